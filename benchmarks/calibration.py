"""Calibration time and accuracy: our engine against scipy least_squares with
finite-difference Jacobians on the same residual, side by side in one process.

Cases: tracker points (1,000 and 10,000 rows) of the example 6R arm, and how the time
grows with the number of rows. Prints JSON.

    python benchmarks/calibration.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from robocal_casadi.datasets import TrackerPoints
from robocal_casadi.examples import industrial_6r
from robocal_casadi.identification import Problem, analyse_identifiability, models_for, solve
from robocal_casadi.kinematics import Kinematics
from robocal_casadi.transforms import pose_from_xyz_rpy


def tracker_case(rows: int, seed: int = 0, noise: float = 10e-6):
    """A simulated tracker data set: perturbed robot, random instrument frame, noise [m]."""
    rng = np.random.default_rng(seed)
    robot = industrial_6r()
    kinematics = Kinematics(robot)
    registry = kinematics.registry
    true_p = kinematics.nominal.copy()
    for i, name in enumerate(registry.names):
        if name.startswith(("base_", "tool_")):
            continue
        true_p[i] += rng.normal(0, 0.5e-3 if registry.quantities[i] == "length" else 0.05e-3 * 10)
    lower, upper = robot.lower_limits, robot.upper_limits
    Q = rng.uniform(np.maximum(lower, -2.5), np.minimum(upper, 2.5), size=(rows, robot.dof))
    target = np.array([0.01, -0.02, 0.12])
    world = kinematics.points(Q, target, true_p)
    T = pose_from_xyz_rpy(rng.normal(0, 1.0, 3), rng.uniform(-np.pi, np.pi, 3))
    measured = world @ T[:3, :3].T + T[:3, 3] + rng.normal(0, noise, (rows, 3))
    dataset = TrackerPoints(path=Path(f"simulated_{rows}.yaml"), kind="tracker_points",
                            robot=robot, robot_path=Path("robot.yaml"), units=robot.units,
                            data_path=None, joints=Q, measured=measured,
                            target=np.array([0.0, 0.0, 0.12]))
    return dataset, true_p


def run_case(rows: int, baseline: bool) -> dict:
    dataset, true_p = tracker_case(rows)
    start = time.perf_counter()
    problem = Problem(dataset.robot, models_for([dataset]))
    x0 = problem.initial()
    nominal = solve(problem, x0, problem.mask("placement"))
    identifiability = analyse_identifiability(problem, nominal.x)
    free = problem.mask("placement")
    free[problem.unknowns.indices(identifiability.identifiable)] = True
    ours = solve(problem, nominal.x, free)
    ours_seconds = time.perf_counter() - start
    out = {"rows": rows, "free_unknowns": int(free.sum()),
           "ours": {"seconds_total": ours_seconds, "seconds_solve": ours.seconds,
                    "iterations": ours.iterations,
                    "rms_mm": 1e3 * problem.rms(ours.x)}}
    if baseline:
        from scipy.optimize import least_squares

        index = np.flatnonzero(free)

        def residual(z):
            x = nominal.x.copy()
            x[index] = z
            return problem.residual(x)

        start = time.perf_counter()
        fitted = least_squares(residual, nominal.x[index], jac="2-point", method="trf",
                               x_scale="jac")
        seconds = time.perf_counter() - start
        x = nominal.x.copy()
        x[index] = fitted.x
        out["scipy_least_squares_fd"] = {"seconds": seconds, "evaluations": int(fitted.nfev),
                                         "rms_mm": 1e3 * problem.rms(x)}
        out["speedup"] = seconds / ours.seconds
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="smaller cases")
    args = parser.parse_args()
    sizes = (300, 1000) if args.quick else (1000, 10000)
    results = [run_case(n, baseline=True) for n in sizes]
    growth = [run_case(n, baseline=False) for n in ((250, 500, 1000) if args.quick
                                                    else (1000, 2000, 5000, 10000, 20000))]
    print(json.dumps({"benchmark": "calibration", "tracker": results,
                      "growth": [{"rows": g["rows"], "seconds_solve": g["ours"]["seconds_solve"],
                                  "seconds_total": g["ours"]["seconds_total"]} for g in growth]},
                     indent=2))


if __name__ == "__main__":
    main()
