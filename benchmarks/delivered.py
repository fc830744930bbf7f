"""What the robot receives, against the simulated truth: the delivered robot's true
tool-position error over the work cell beside the nominal robot's, and beside the error the
calibration predicts for it.

For every kind (tracker, bar, artifact, point laser with joint readings) and several seeds,
a true robot off its drawing by errors drawn at the tolerances the calibration assumes
(1 mm on lengths, 0.5 deg on angles of every joint) is measured, calibrated with held-out
data, and the written ``robot_calibrated.yaml`` is compared with the truth at 400 poses
drawn in the joint ranges the fit data cover, after the best rigid motion (the robot's
registration in the cell) is removed: the same definition ``predicted_accuracy`` uses.
One more case is the point laser on the example 6R arm with four errors, 60 readings and
0.01 mm noise.

Prints one JSON object: per case and seed the exit status, ``recommended``, the true error
of the delivered and of the nominal robot, the predicted error and their ratio (a case whose
data the calibration refuses has exit status 2 and the reason); and per kind how many seeds
were refused, how many are never worse than nominal without exit 3, how many
predictions lie within a factor 1.5 of the truth, how many truths lie in the predicted
band of one robot's RMS (10% to 90%: eight in ten should), and the mean and spread of
log(predicted / true) (a bias shows in the mean; with one dominant direction even a
right prediction has a mean near +0.6, the spread of log |z|).

    python benchmarks/delivered.py [--seeds 10] [--diagnose] [--kinds KIND ...] [--keep DIR]

``--keep DIR`` keeps every case's data, outputs and a pickle of the result and the truth
(``case.pkl``) in DIR, for studying the prediction without calibrating again.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np

# The checkout this script lives in, not an installed copy, is what it measures.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal_casadi.errors import RobocalError  # noqa: E402
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402
from robocal_casadi.instruments.simulate import simulate, true_parameters  # noqa: E402
from robocal_casadi.job.accuracy import SAMPLES, SEED, region_of  # noqa: E402
from robocal_casadi.job.run import JobOptions, run_job  # noqa: E402
from robocal_casadi.model import examples  # noqa: E402
from robocal_casadi.model.kinematics import Kinematics  # noqa: E402
from robocal_casadi.model.robot import load_robot, save_robot  # noqa: E402

ERRORS = (1e-3, np.radians(0.5))  # [m], [rad]: the tolerances the prior assumes
KINDS = {  # kind: (fit units, held-out units, noise [m])
    "tracker_points": (60, 40, 2e-5),
    "cross_bar": (30, 20, 1e-5),
    "artifact_touches": (30, 20, 1e-5),
    "sphere_laser": (200, 100, 1e-5),
}
MOUNTED_ERROR = 5e-3  # [m] the prior's instrument tolerance
README_ERRORS = {"a2": 0.3e-3, "alpha3": np.radians(0.02), "d4": -0.2e-3,
                 "theta5": np.radians(0.03)}


def rigid_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS distance [m] between point sets after the best rigid motion (Kabsch)."""
    a0, b0 = a - a.mean(0), b - b.mean(0)
    U, _, Vt = np.linalg.svd(a0.T @ b0)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    return float(np.sqrt(np.mean(np.sum((a0 @ R.T - b0) ** 2, axis=1))))


def split(dataset: Path, table: Path, share: float) -> tuple[Path, Path]:
    """Two dataset files beside ``dataset``: every unit of data (a row, or all rows of one
    ``pose`` for touches) dealt to the held-out file with probability ``share``."""
    lines = table.read_text().splitlines()
    header, rows = lines[0], lines[1:]
    column = header.split(",")
    unit = column.index("pose") if "pose" in column else None
    keys = [r.split(",")[unit] if unit is not None else str(i) for i, r in enumerate(rows)]
    distinct = sorted(set(keys), key=keys.index)
    held = set(distinct[::max(1, round(1 / share))])
    text = dataset.read_text()
    out = []
    for role, keep in (("fit", lambda k: k not in held), ("held", lambda k: k in held)):
        part = table.with_name(f"{role}.csv")
        part.write_text("\n".join([header] + [r for r, k in zip(rows, keys) if keep(k)]) + "\n")
        path = dataset.with_name(f"{role}.yaml")
        path.write_text(text.replace(f"data: {table.name}", f"data: {part.name}"))
        out.append(path)
    return out[0], out[1]


def one_case(robot_file: Path, kind: str, seed: int, errors, rows: tuple[int, int],
             noise: float, diagnose: bool, folder: Path, mounted_error: float | None,
             keep: bool = False) -> dict:
    if isinstance(errors, tuple):  # drawn once, so fit and held-out data share the truth
        _, errors = true_parameters(load_robot(robot_file), errors,
                                    np.random.default_rng(1000 + seed))
    # One simulated set, split into fit and held-out files, so that both share the truth,
    # the instrument included (drawn at the prior's tolerance).
    fit = simulate(robot_file, kind, out_dir=folder / "all", rows=rows[0] + rows[1],
                   noise=noise, geometric_errors=errors, seed=seed, progress=False, force=True,
                   mounted_error=mounted_error)
    fit_path, held_path = split(fit.dataset_path, fit.table_path, rows[1] / sum(rows))
    truth = fit.truth.robot
    try:
        outcome = run_job([load_dataset(fit_path)], [load_dataset(held_path)],
                          JobOptions(diagnose=diagnose), folder / "out")
    except RobocalError as error:  # refused data: what a user would get (exit status 2)
        return {"seed": seed, "exit_status": 2, "refused": str(error).split(": ", 1)[-1]}
    result = outcome.result
    delivered = load_robot(folder / "out" / "robot_calibrated.yaml")
    low, high = np.array(region_of(result)).T
    Q = np.random.default_rng(SEED).uniform(low, high, size=(SAMPLES, len(low)))
    # The instrument's point on the flange: true, as delivered, and as the file declares.
    true_point = next(np.asarray(v, float) for k, v in fit.truth.mounted.items()
                      if k in ("probe", "target", "laser_origin"))
    mounted = result.delivered.mounted
    delivered_point = np.array([mounted[n] for n in list(mounted)[:3]])
    nominal_point = np.array(list(result.delivery.candidate("nominal").mounted.values())[:3])
    true_points = Kinematics(truth).points(Q, true_point)
    delivered_error = rigid_rms(Kinematics(delivered).points(Q, delivered_point), true_points)
    nominal_error = rigid_rms(Kinematics(result.robot_nominal).points(Q, nominal_point),
                              true_points)
    if keep:
        with open(folder / "case.pkl", "wb") as handle:
            pickle.dump({"result": result, "truth": fit.truth, "fit": fit_path,
                         "held": held_path}, handle)
    predicted = result.predicted_accuracy
    # the truth is taken over the box of joint ranges: the statement's box figure
    predicted = predicted if predicted is None or predicted.box is None else predicted.box
    out = {"seed": seed, "exit_status": outcome.exit_status, "recommended": result.recommended,
           "delivered_model": result.delivered.model,
           "true_error_delivered_mm": 1e3 * delivered_error,
           "true_error_nominal_mm": 1e3 * nominal_error,
           "predicted_mm": None if predicted is None else 1e3 * predicted.rms}
    if predicted is not None:
        out["predicted_over_true"] = predicted.rms / delivered_error
        band = getattr(predicted, "band", None)
        if band is not None:
            out["band_mm"] = [1e3 * band[0], 1e3 * band[1]]
            out["true_in_band"] = bool(band[0] <= delivered_error <= band[1])
    return out


def summarise(rows: list[dict]) -> dict:
    refused = sum(1 for r in rows if "refused" in r)
    honest = sum(1 for r in rows if "refused" not in r and (
        r["true_error_delivered_mm"] <= r["true_error_nominal_mm"] or r["exit_status"] == 3))
    ratios = [r["predicted_over_true"] for r in rows if "predicted_over_true" in r]
    within = sum(1 for x in ratios if 1 / 1.5 <= x <= 1.5)
    banded = [r["true_in_band"] for r in rows if "true_in_band" in r]
    return {"seeds": len(rows), "refused": refused, "never_worse_without_exit_3": honest,
            "predicted_within_1.5x": within, "predictions": len(ratios),
            "median_predicted_over_true": float(np.median(ratios)) if ratios else None,
            # mean and spread of log(predicted / true): a bias shows in the mean
            "mean_log_predicted_over_true": float(np.mean(np.log(ratios))) if ratios else None,
            "std_log_predicted_over_true": float(np.std(np.log(ratios))) if ratios else None,
            "true_in_band": sum(banded), "bands": len(banded),
            "mean_true_error_delivered_mm": float(np.mean(
                [r["true_error_delivered_mm"] for r in rows if "refused" not in r] or [np.nan]))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--diagnose", action="store_true")
    parser.add_argument("--kinds", nargs="*", default=list(KINDS) + ["laser_readme"])
    parser.add_argument("--keep", type=Path, default=None)
    args = parser.parse_args()
    report: dict = {"cases": {}, "summary": {}}
    with tempfile.TemporaryDirectory() as scratch:
        tmp = scratch if args.keep is None else str(args.keep)
        Path(tmp).mkdir(parents=True, exist_ok=True)
        robot_file = Path(tmp) / "robot.yaml"
        save_robot(examples.ROBOTS["industrial_6r"](), robot_file)
        for kind in args.kinds:
            rows = []
            for seed in range(1, args.seeds + 1):
                folder = Path(tmp) / f"{kind}-{seed}"
                if kind == "laser_readme":
                    row = one_case(robot_file, "sphere_laser", seed, README_ERRORS, (60, 60),
                                   1e-5, args.diagnose, folder, None, args.keep is not None)
                else:
                    units, held, noise = KINDS[kind]
                    row = one_case(robot_file, kind, seed, ERRORS, (units, held), noise,
                                   args.diagnose, folder, MOUNTED_ERROR, args.keep is not None)
                rows.append(row)
                print(f"{kind} seed {seed}: {row}", file=sys.stderr)
            report["cases"][kind] = rows
            report["summary"][kind] = summarise(rows)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
