"""Gross errors: does the default (robust) calibration set them aside, and only them?

Simulated cases of every kind (tracker points, cross bar, artifact touches, laser with
joint readings, laser with pendant poses), each with a gear-ratio error on joint 2 where
the data see joints, and a clean held-out set from the same robot. Per case and seed:

* today's calibration (``loss="linear"``) and the robust one on the clean data: held-out
  RMS, readings set aside (should be none), effects named;
* the robust one on the same data with a share of the rows corrupted by 2-10 mm
  (``simulate.inject_gross_errors``): held-out RMS against the clean case, share of the
  corrupted rows set aside, clean rows set aside, effects named.

Then the real data: UR10 series A and D (every fourth pose held out) and the Panda plate
(two placements held out), linear against robust: held-out RMS and what was set aside.

Prints JSON (lengths in mm).

    python benchmarks/robust.py [--seeds 2] [--quick] [--shared DIR] [--no-real]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from robocal_casadi.calibration import calibrate
from robocal_casadi.instruments.datasets import dataset_rows, load_dataset
from robocal_casadi.instruments.simulate import inject_gross_errors, simulate, true_parameters
from robocal_casadi.model.examples import industrial_6r

MM = 1e3
NOISE = 5e-5  # [m]
EFFECT = {"joint_scale": {2: 1e-3}}
CASES = {  # name: (kind, rows, options)
    "tracker_points": ("tracker_points", 150, {}),
    "cross_bar": ("cross_bar", 60, {}),
    "artifact_touches": ("artifact_touches", 12, {}),
    "sphere_laser_joints": ("sphere_laser", 300, {}),
    "sphere_laser_pendant": ("sphere_laser", 200, {"readings": "pendant"}),
}
SHARES = (0.01, 0.03, 0.05)  # share of rows corrupted, by seed in turn
PANDA = ("back_left", "back_right", "front_center", "front_left", "front_right", "high",
         "mid-high", "mid_left", "mid_right")


def held_out_rms(result) -> float:
    """Held-out RMS of the final model over every reading [mm]."""
    return (result.validation_all or result.validation).rms_final * MM


def recommended_rms(result) -> float:
    """Held-out RMS over every reading [mm] of the model the calibration recommends (the
    geometric one when the held-out data show the model with effects worse)."""
    validation = result.validation_all or result.validation
    chosen = validation.rms_geometric if result.recommended == "geometric" else \
        validation.rms_final
    return chosen * MM


def effects(result) -> list[str]:
    return [f"{e.name}{list(e.joints)}" for e in result.effects]


def one_case(name: str, seed: int, share: float, folder: Path, diagnose: bool) -> dict:
    kind, rows, options = CASES[name]
    robot = industrial_6r()
    _, errors = true_parameters(robot, (5e-4, 5e-4), np.random.default_rng(seed))
    if options:  # pendant poses: the controller's own, exact only for an accurate robot
        errors = None
    common = dict(rows=rows, noise=NOISE, geometric_errors=errors, mounted_error=0.0,
                  progress=False, effects=None if options else EFFECT, **options)
    fit = simulate(robot, kind, out_dir=folder / "fit", seed=seed, **common)
    val = simulate(robot, kind, out_dir=folder / "val", seed=seed + 1000, **common)
    bad = simulate(robot, kind, out_dir=folder / "bad", seed=seed, **common)
    injected = set(inject_gross_errors(bad, share, seed=seed))
    out: dict = {"case": name, "seed": seed, "share_injected": share,
                 "readings": len(fit.joints) if fit.joints is not None else rows}
    runs = (("clean_linear", fit, "linear"), ("clean_robust", fit, "robust"),
            ("bad_robust", bad, "robust"))
    for label, data, loss in runs:
        start = time.perf_counter()
        result = calibrate([data.load()], [val.load()], loss=loss, diagnose=diagnose)
        lines = [set(e.lines) for e in result.rejected if e.role == "fit"]
        flagged = {line for group in lines for line in group}
        entry = {"held_out_rms": held_out_rms(result), "effects": effects(result),
                 "units_set_aside": len(lines), "seconds": time.perf_counter() - start}
        if label == "bad_robust":
            entry["injected"] = len(injected)
            entry["injected_flagged"] = len(injected & flagged) / len(injected)
            entry["clean_units_set_aside"] = sum(not (g & injected) for g in lines)
        out[label] = entry
    out["held_out_ratio_bad_to_clean"] = (out["bad_robust"]["held_out_rms"]
                                          / out["clean_linear"]["held_out_rms"])
    out["held_out_ratio_robust_to_linear_clean"] = (out["clean_robust"]["held_out_rms"]
                                                    / out["clean_linear"]["held_out_rms"])
    return out


def split_every_fourth(dataset):
    """(fit, held out): rows 4, 8, 12, ... held out (1-based), the rest fit (lines kept)."""
    held = np.arange(dataset.rows) % 4 == 3
    return dataset_rows(dataset, ~held), dataset_rows(dataset, held)


def compare(fit: list, validation: list, diagnose: bool) -> dict:
    out: dict = {}
    for loss in ("linear", "robust"):
        start = time.perf_counter()
        result = calibrate(fit, validation, loss=loss, diagnose=diagnose)
        out[loss] = {"held_out_rms_kept": result.validation.rms_final * MM,
                     "held_out_rms_all": held_out_rms(result), "effects": effects(result),
                     "recommended": result.recommended,
                     "held_out_rms_recommended": recommended_rms(result),
                     "rejected": [e.to_json(result.units) for e in result.rejected],
                     "seconds": time.perf_counter() - start}
        out[loss]["rejected_count"] = len(result.rejected)
        for entry in out[loss]["rejected"]:
            entry.pop("position", None)
    out["ratio_all"] = out["robust"]["held_out_rms_all"] / out["linear"]["held_out_rms_all"]
    out["ratio_kept"] = out["robust"]["held_out_rms_kept"] / out["linear"]["held_out_rms_kept"]
    out["ratio_recommended"] = (out["robust"]["held_out_rms_recommended"]
                                / out["linear"]["held_out_rms_recommended"])
    return out


def real_data(shared: Path, quick: bool, diagnose: bool) -> list[dict]:
    results = []
    for series in ("series_D",) if quick else ("series_D", "series_A"):
        path = shared / "ur10-ipa" / f"{series}.yaml"
        if path.is_file():
            fit, held = split_every_fourth(load_dataset(path))
        else:
            fit = load_dataset(path.with_name(f"{series}_fit.yaml"))
            held = load_dataset(path.with_name(f"{series}_validation.yaml"))
        results.append({"set": f"ur10 {series}", **compare([fit], [held], diagnose)})
        print(json.dumps(results[-1]), flush=True)
    pairs = [("mid-high", "mid_right")] if quick else \
        [("mid-high", "mid_right"), ("back_left", "front_right")]
    folder = shared / "panda-mukca"
    for pair in pairs:
        fit = [load_dataset(folder / f"{n}.yaml") for n in PANDA if n not in pair]
        held = [load_dataset(folder / f"{n}.yaml") for n in pair]
        results.append({"set": f"panda held out {'+'.join(pair)}",
                        **compare(fit, held, diagnose)})
        print(json.dumps(results[-1]), flush=True)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per simulated case")
    parser.add_argument("--quick", action="store_true",
                        help="one seed, UR10 series D and one Panda split")
    parser.add_argument("--no-diagnose", action="store_true")
    parser.add_argument("--shared", type=Path, default=None, metavar="DIR",
                        help="folder of the real data sets, e.g. with UR10 series A "
                        "(default: the package's copies)")
    parser.add_argument("--no-real", action="store_true", help="simulated cases only")
    args = parser.parse_args()
    diagnose = not args.no_diagnose
    seeds = 1 if args.quick else args.seeds
    simulated = []
    with tempfile.TemporaryDirectory() as scratch:
        for name in CASES:
            for seed in range(seeds):
                folder = Path(scratch) / f"{name}-{seed}"
                simulated.append(one_case(name, seed, SHARES[seed % len(SHARES)], folder,
                                          diagnose))
                print(json.dumps(simulated[-1]), flush=True)
    real = []
    if not args.no_real:
        shared = args.shared
        if shared is None or not shared.is_dir():
            from robocal_casadi.commands.demo import data_folder

            shared = data_folder()
        real = real_data(shared, args.quick, diagnose)
    print(json.dumps({"benchmark": "robust", "simulated": simulated, "real": real}, indent=2))


if __name__ == "__main__":
    main()
