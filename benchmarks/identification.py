"""Identification at the noise floor: the 1% rule against the maximum a posteriori rule.

For each case the same data are calibrated twice in this process, once with
``rule="fraction"`` (parameters with less than 1% of their effect their own held at
nominal, least squares for the rest) and once with ``rule="prior"`` (every parameter that
is not exactly undeterminable, weighed against its tolerance). Printed side by side:

* simulated cases of every kind (``simulate``: cross bar, artifact, tracker, sphere with
  joint readings, sphere with pendant poses), three quarters of the units fitted and the
  rest held out, for several seeds; the held-out RMS is compared with the noise floor,
  the held-out RMS of the TRUE model (true robot and instrument from the simulation,
  placements fitted again), which the estimator never sees. Per seed and the median,
  beside what an efficient estimator reaches on average (``expected_over_floor``); a
  single held-out laser reading far from every fitted one (another branch of the inverse
  kinematics) can dominate one seed's RMS;
* the UR10 series D target offset along the flange axis (every fourth pose held out);
* the Panda placements held out (three pairs), as in ``real_data.py``.

    python benchmarks/identification.py [--shared DIR] [--quick]

Real data come from ``robocal_casadi/data`` unless ``--shared DIR`` names a folder of the
full data sets (``ur10-ipa/series_D.yaml``, ``panda-mukca/``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_data import PANDA, split_every_fourth  # noqa: E402

from robocal_casadi.calibration import calibrate, evaluate  # noqa: E402
from robocal_casadi.instruments.datasets import (
    dataset_rows,  # noqa: E402
    load_dataset,  # noqa: E402
)
from robocal_casadi.instruments.simulate import simulate  # noqa: E402
from robocal_casadi.model import examples  # noqa: E402

RULES = ("fraction", "prior")
MM = 1e3

# kind, readings, units of data (placements or readings), noise [m], errors (length [m],
# angle [rad]); every fourth unit is held out.
CASES = (
    ("cross_bar", "joints", 200, 10e-6, (0.5e-3, math.radians(0.05))),
    ("artifact_touches", "joints", 40, 10e-6, (0.5e-3, math.radians(0.05))),
    ("tracker_points", "joints", 400, 10e-6, (0.5e-3, math.radians(0.05))),
    ("sphere_laser", "joints", 400, 8e-6, (0.5e-3, math.radians(0.05))),
    # The same with twice the readings: the held-out excess of any estimator shrinks as
    # the unknowns per reading do (see ``expected_over_floor``).
    ("sphere_laser", "joints", 800, 8e-6, (0.5e-3, math.radians(0.05))),
    # Pendant poses are the controller's: with robot errors they carry those errors, which
    # the true laser does not explain, so the true model would be no floor; none here.
    ("sphere_laser", "pendant", 400, 8e-6, None),
)


def split_units(dataset, held_every: int = 4):
    """(fit, held out): every ``held_every``-th unit (placement or reading) held out."""
    pose = getattr(dataset, "pose", None)
    distance = getattr(dataset, "distance", None)
    count = len(distance) if distance is not None else dataset.rows  # pendant: no joints
    unit = np.unique(pose, return_inverse=True)[1] if pose is not None else np.arange(count)
    held = unit % held_every == held_every - 1

    def take(mask, suffix):
        part = dataset_rows(dataset, mask)
        return replace(part, path=dataset.path.with_name(dataset.path.stem + suffix +
                                                         dataset.path.suffix))

    return take(~held, "_fit"), take(held, "_validation")


def true_values(truth) -> dict[str, float]:
    """True robot and instrument parameters by name [SI]."""
    registry = truth.robot.parameters()
    values = dict(zip(registry.names, registry.vector_of(truth.robot)))
    mounted = truth.mounted
    for key, prefix in (("probe", "probe_"), ("target", "target_"), ("laser_origin", "laser_")):
        if key in mounted:
            values.update({prefix + axis: float(v) for axis, v in zip("xyz", mounted[key])})
    if "laser_direction" in mounted:
        values.update({f"laser_n{axis}": float(v)
                       for axis, v in zip("xyz", mounted["laser_direction"])})
    return values


def held_out_floor(truth, held) -> float:
    """Held-out RMS [m] of the true model, placements fitted again."""
    problem, x = evaluate(truth.nominal, [held], (), true_values(truth),
                          label_prefix="validation:")
    errors = np.concatenate(problem.errors(x))
    return float(np.sqrt(np.mean(errors**2)))


def outcome(result, seconds: float) -> dict:
    prior = result.prior
    return {"fit_mm": result.fit.rms_final * MM,
            "held_out_mm": result.validation.rms_final * MM,
            "identifiable": len(result.identifiability.identifiable),
            "prior_dominated": list(prior.dominated) if prior else [],
            "seconds": seconds}


def expected_over_floor(result) -> float:
    """Held-out RMS over the floor that an efficient estimator reaches on average with
    this many unknowns ``p`` (placements included) and residual entries ``m`` of the
    same kind of data: ``sqrt(1 + p / m)`` (Akaike's final prediction error; the
    estimate's own error adds ``p / m`` of the noise variance to held-out data)."""
    solver = result.solver
    return math.sqrt(1.0 + solver["free_unknowns"] / solver["residuals"])


def run_simulated(folder: Path, kind: str, readings: str, units: int, noise: float,
                  errors, seed: int) -> dict:
    robot = examples.industrial_6r()
    sim = simulate(robot, kind, out_dir=folder / f"{kind}_{readings}", rows=units, noise=noise,
                   geometric_errors=errors, seed=seed, readings=readings, progress=False)
    fit, held = split_units(sim.load())
    floor = held_out_floor(sim.truth, held)
    out = {"case": f"{kind} ({readings})" if kind == "sphere_laser" else kind,
           "units_fit_held_out": [int(units - units // 4), int(units // 4)],
           "noise_mm": noise * MM, "held_out_floor_mm": floor * MM}
    for rule in RULES:
        start = time.perf_counter()
        result = calibrate([fit], [held], diagnose=False, rule=rule)
        entry = outcome(result, time.perf_counter() - start)
        entry["held_out_over_floor"] = result.validation.rms_final / floor
        entry["expected_over_floor"] = expected_over_floor(result)
        out[rule] = entry
    return out


def run_tracker(path: Path) -> dict:
    out = {"case": f"UR10 {path.stem}, target offset along the flange axis"}
    if path.is_file():
        fit, held = split_every_fourth(load_dataset(path))
    else:  # the package's copy of the series, already split the same way
        fit = load_dataset(path.with_name(path.stem + "_fit.yaml"))
        held = load_dataset(path.with_name(path.stem + "_validation.yaml"))
    for rule in RULES:
        start = time.perf_counter()
        result = calibrate([fit], [held], diagnose=True, rule=rule)
        entry = outcome(result, time.perf_counter() - start)
        value, std = result.mounted["target_z"]
        nominal = fit.target[2]
        entry.update({"target_z_mm": value * MM, "target_z_std_mm": None if std is None
                      else std * MM, "target_z_nominal_mm": nominal * MM,
                      "target_z_identified": "target_z" in result.identifiability.identifiable})
        out[rule] = entry
    return out


def run_panda(folder: Path, held_out: tuple[str, str]) -> dict:
    fit = [load_dataset(folder / f"{n}.yaml") for n in PANDA if n not in held_out]
    validation = [load_dataset(folder / f"{n}.yaml") for n in held_out]
    out = {"case": f"Panda, hold out {held_out[0]} + {held_out[1]}"}
    for rule in RULES:
        start = time.perf_counter()
        result = calibrate(fit, validation, diagnose=True, rule=rule)
        out[rule] = outcome(result, time.perf_counter() - start)
    out["held_out_change"] = out["prior"]["held_out_mm"] / out["fraction"]["held_out_mm"] - 1
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--shared", type=Path, default=None, metavar="DIR",
                        help="folder of the full data sets (default: the package's copies)")
    parser.add_argument("--quick", action="store_true", help="simulated cases only")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = parser.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, readings, units, noise, errors in CASES:
            runs = [run_simulated(Path(tmp) / str(seed), kind, readings, units, noise, errors,
                                  seed) for seed in args.seeds]
            entry = {"case": runs[0]["case"], "units": units, "seeds": args.seeds}
            for rule in RULES:
                ratios = [r[rule]["held_out_over_floor"] for r in runs]
                entry[rule] = {"held_out_over_floor": ratios,
                               "median_held_out_over_floor": float(np.median(ratios)),
                               "median_expected_over_floor": float(np.median(
                                   [r[rule]["expected_over_floor"] for r in runs])),
                               "prior_dominated": [r[rule]["prior_dominated"] for r in runs]}
            entry["runs"] = runs
            results.append(entry)
            print(json.dumps({k: v for k, v in entry.items() if k != "runs"}), flush=True)
    if args.shared is None:
        args.shared = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data"
    if not args.quick:
        results.append(run_tracker(args.shared / "ur10-ipa" / "series_D.yaml"))
        print(json.dumps(results[-1]), flush=True)
        for pair in (("mid-high", "mid_right"), ("back_left", "front_right"),
                     ("high", "front_center")):
            results.append(run_panda(args.shared / "panda-mukca", pair))
            print(json.dumps(results[-1]), flush=True)
    print(json.dumps({"benchmark": "identification", "results": results}, indent=2))


if __name__ == "__main__":
    main()
