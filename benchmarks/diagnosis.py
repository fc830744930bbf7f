"""Diagnosis time against one geometric calibration, side by side in one process.

Real data first: the shipped UR10 tracker series, fitted in one region of joint 1 and
held out in another, and split pose by pose; for each, the held-out RMS of the geometric
model beside that of the model diagnosis built, which must not be worse.

Then tracker data of the example 6R arm (simulated by ``robocal_casadi.simulate``: geometric
errors, 0.01 mm noise per coordinate, a payload column) at 1,000 and 10,000 rows, once
with compliance on joints 2 and 3 (which diagnosis should find) and once clean (where it
should add nothing). For each: the wall-clock seconds of the geometric calibration
(``calibrate(diagnose=False)``), of the whole job with diagnosis, of ``diagnosis.run``
alone on a geometric solution, the ratio of the last to the first, and what diagnosis
found. Prints JSON.

    python benchmarks/diagnosis.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from robocal_casadi.calibration import (
    Problem,
    analyse_identifiability,
    calibrate,
    diagnosis,
    models_for,
    solve,
)
from robocal_casadi.instruments.datasets import dataset_rows, load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.results import Decision

NOISE = 1e-5  # [m]
COMPLIANCE = {2: 1.5e-6, 3: 2.5e-6}  # [rad/Nm]


def geometric_errors(robot, seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {f"{stem}{i}": float(rng.normal(0.0, 5e-4))
            for i in range(1, robot.dof + 1) for stem in ("theta", "d", "a", "alpha")}


def _geometric(data):
    """The geometric fit through the public API, as ``calibrate`` does it."""
    problem = Problem(data.robot, models_for([data]))
    nominal = solve(problem, problem.initial(), problem.mask("placement"))
    identifiability = analyse_identifiability(problem, nominal.x)
    free = problem.mask("placement")
    free[problem.unknowns.indices(identifiability.identifiable)] = True
    return problem, solve(problem, nominal.x, free), identifiability


def run_case(rows: int, effects: dict | None, folder: Path) -> dict:
    robot = industrial_6r()
    data = simulate(robot, "tracker_points", out_dir=folder, rows=rows, noise=NOISE,
                    geometric_errors=geometric_errors(robot), effects=effects,
                    payload=(0.0, 10.0), seed=1, progress=False).load()
    start = time.perf_counter()
    geometric = calibrate([data], diagnose=False)
    calibration_seconds = time.perf_counter() - start
    start = time.perf_counter()
    full = calibrate([data], diagnose=True)
    full_seconds = time.perf_counter() - start
    problem, solution, identifiability = _geometric(data)
    start = time.perf_counter()
    outcome = diagnosis.run(problem, solution, identifiability, progress=False)
    run_seconds = time.perf_counter() - start
    return {
        "rows": rows,
        "truth": {"joint_compliance": {str(j): c for j, c in (effects or {}).get(
            "joint_compliance", {}).items()}},
        "seconds_calibration": calibration_seconds,
        "seconds_calibration_with_diagnosis": full_seconds,
        "seconds_diagnosis_run": run_seconds,
        "ratio_diagnosis_to_calibration": run_seconds / calibration_seconds,
        "rounds": outcome.rounds,
        "candidates_tested": len(full.diagnosis),
        "found": [{"name": e.name, "joints": list(e.joints), "parameters": e.parameters}
                  for e in full.effects],
        "rms_mm": {"geometric": full.fit.rms_geometric * 1e3,
                   "final": full.fit.rms_final * 1e3,
                   "noise_floor": NOISE * np.sqrt(3) * 1e3},
        "geometric_only_rms_mm": geometric.fit.rms_final * 1e3,
    }


def real_split(name: str, fit, validation) -> dict:
    """Geometric model against diagnosis on one real fit/held-out split, side by side."""
    start = time.perf_counter()
    result = calibrate([fit], [validation])
    seconds = time.perf_counter() - start
    mm = 1e3
    return {
        "case": name, "fit_rows": fit.rows, "held_out_rows": validation.rows,
        "fit_mm": {"geometric": result.fit.rms_geometric * mm,
                   "final": result.fit.rms_final * mm},
        "held_out_mm": {"geometric": result.validation.rms_geometric * mm,
                        "final": result.validation.rms_final * mm},
        "final_not_worse": result.validation.rms_final <= result.validation.rms_geometric,
        "recommended": result.recommended,
        "effects": [e.summary for e in result.effects],
        "unexplained": None if result.unexplained is None else
        result.unexplained.to_json(1e-3, "mm"),
        "rejected_as_implausible": sorted({f"{t.effect}{list(t.joints)}"
                                           for t in result.diagnosis
                                           if t.outcome is Decision.IMPLAUSIBLE}),
        "seconds": seconds,
    }


def real_cases(shared: Path | None) -> list[dict]:
    """UR10 tracker data: series A split at q1 = -2.3 rad (fit below, held out above: the
    held-out poses lie outside the fit region), series A and D every fourth pose held out.
    Without the full data sets (``shared``) only series D as the package ships it, split
    the same way."""
    folder = None if shared is None else shared / "ur10-ipa"
    if folder is None or not (folder / "series_A.yaml").is_file():
        shipped = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa"
        return [real_split("ur10 series_D, every fourth pose held out",
                           load_dataset(shipped / "series_D_fit.yaml"),
                           load_dataset(shipped / "series_D_validation.yaml"))]
    series_a = load_dataset(folder / "series_A.yaml")
    below = series_a.joints[:, 0] < -2.3
    cases = [real_split("ur10 series A, fit q1 < -2.3 rad, held out the rest",
                        dataset_rows(series_a, below), dataset_rows(series_a, ~below))]
    for series in ("series_A", "series_D"):
        data = load_dataset(folder / f"{series}.yaml")
        held = np.arange(data.rows) % 4 == 3
        cases.append(real_split(f"ur10 {series}, every fourth pose held out",
                                dataset_rows(data, ~held), dataset_rows(data, held)))
    return cases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 rows only")
    parser.add_argument("--real-only", action="store_true", help="the real data splits only")
    parser.add_argument("--shared", type=Path, default=None, metavar="DIR",
                        help="folder of the full real data sets (ur10-ipa/series_A.yaml, "
                             "series_D.yaml); default: the package's copy of series D")
    args = parser.parse_args()
    sizes = (1000,) if args.quick else (1000, 10000)
    cases = real_cases(args.shared)
    if args.real_only:
        sizes = ()
    with tempfile.TemporaryDirectory() as folder:
        for rows in sizes:
            for label, effects in (("compliance", {"joint_compliance": COMPLIANCE}),
                                   ("clean", None)):
                case = run_case(rows, effects, Path(folder) / f"{label}_{rows}")
                case["case"] = label
                cases.append(case)
    print(json.dumps({"benchmark": "diagnosis", "cases": cases}, indent=2))


if __name__ == "__main__":
    main()
