"""Inverse kinematics: Levenberg-Marquardt against IPOPT on the same targets, one process.

For each example robot and mode, targets are made by forward kinematics of random joints
within the limits (so they are reachable); each solver starts from the same seed with
the same random restarts. Reported per solver: share of targets solved to 1e-10 m /
1e-10 rad, the worst error of the solved ones, mean and median wall time per target
(restarts included), and the speed ratio. Prints JSON.

    python benchmarks/ik.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.ik import inverse_kinematics, random_joints
from robocal_casadi.model.kinematics import Kinematics

OFFSET = np.array([0.0, 0.0, 0.15])  # [m] probe in the flange frame (point mode)


def case(name: str, mode: str, count: int, restarts: int) -> dict:
    robot = ROBOTS[name]()
    kinematics = Kinematics(robot)
    joints = random_joints(robot, count, np.random.default_rng(0), margin=0.02)
    if mode == "pose":
        targets = kinematics.tool_poses(joints)
    else:
        targets = kinematics.points(joints, OFFSET)
    seeds = random_joints(robot, count, np.random.default_rng(1))
    out: dict = {"robot": name, "mode": mode, "targets": count, "restarts": restarts}
    for method in ("lm", "ipopt"):
        solver = inverse_kinematics(kinematics, mode, method)
        solver.solve(targets[0], seed=seeds[0], offset=OFFSET)  # build and warm up
        times, solved, worst = [], 0, 0.0
        for target, seed in zip(targets, seeds):
            start = time.perf_counter()
            result = solver.solve(target, seed=seed, offset=OFFSET, restarts=restarts, rng=2)
            times.append(time.perf_counter() - start)
            if result.success:
                solved += 1
                worst = max(worst, result.position_error)
        out[method] = {"solved": solved / count, "worst_position_error_m": worst,
                       "mean_ms": 1e3 * float(np.mean(times)),
                       "median_ms": 1e3 * float(np.median(times))}
    out["ipopt_over_lm_mean_time"] = out["ipopt"]["mean_ms"] / out["lm"]["mean_ms"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer targets")
    args = parser.parse_args()
    count = 10 if args.quick else 50
    results = [case(name, mode, count, restarts=10)
               for name in ("industrial_6r", "panda_7dof", "prismatic_rrp")
               for mode in ("pose", "point")]
    print(json.dumps({"benchmark": "ik", "cases": results}, indent=2))


if __name__ == "__main__":
    main()
