"""Tracking a moving target: solve time, success, accuracy and smoothness per cycle.

For a 6R arm (``industrial_6r``) and a 7-DOF arm (``panda_7dof``) the target moves for
several thousand cycles; the goals are reachable by construction (the end poses of a
smooth Lissajous path in joint space, each seen by the camera from the previous cycle's
joints). Every method starts from the same level pose (one IPOPT solve of the first
cycle), so all solve the same sequence of NLPs; ``max_difference_to_ipopt_rad`` compares
their answers with IPOPT's over the cycles IPOPT ran. Side by side on the same observations:

* ``gauss_newton``: the tracker's real-time solver, compiled step function (default);
* ``gauss_newton_interpreted``: the same with the interpreted CasADi function;
* ``sqpmethod_qrqp``, ``sqpmethod_qpoases``: CasADi's SQP on the same NLP;
* ``ipopt``: IPOPT on the same NLP (fewer cycles: it is slow; ``--ipopt-cycles``);
* ``damped_least_squares``: a plain damped least-squares IK on position and z axis only
  (it ignores the level condition; its ``max_level_tilt_deg`` shows what that costs).

Per method: median and 99th-percentile time per cycle (wall clock, and CPU time of the
thread, which leaves out preemption by other processes), success rate, largest
constraint error of the successful cycles, largest joint step between cycles. Prints JSON.

    python benchmarks/tracking.py [--cycles 5000] [--ipopt-cycles 1000]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import time

import casadi as ca
import numpy as np

from robocal_casadi.common import codegen
from robocal_casadi.common.progress import Progress
from robocal_casadi.model.examples import industrial_6r, panda_7dof
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.tracking import Tracker, TrackingProblem, observation_for
from robocal_casadi.tracking.problem import error_expressions

CAMERA = np.array([0.04, -0.03, 0.06])  # [m] camera origin in the end frame
STANDOFF = 0.25  # [m]
ROBOTS = {
    "industrial_6r": (industrial_6r, np.array([0.2, -0.4, 0.5, 0.3, 0.9, 0.2])),
    "panda_7dof": (panda_7dof, np.array([0.1, -0.3, 0.05, -2.0, 0.1, 2.7, 0.6])),
}


def lissajous_path(start: np.ndarray, cycles: int, amplitude: float = 0.3) -> np.ndarray:
    """Joints (cycles x n) [rad] on a Lissajous figure around ``start``, 3 laps."""
    t = np.linspace(0.0, 3.0, cycles)[:, None]
    n = len(start)
    return start + amplitude * np.sin(2 * np.pi * np.arange(1, n + 1) * t / 3 + np.arange(n))


def observations(robot, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Capture joints (the previous cycle's path point) and the observations that ask for
    the end pose of each path point."""
    captures = np.vstack([path[:1], path[:-1]])
    seen = np.array([observation_for(nominal_pose(robot, c), nominal_pose(robot, q), CAMERA,
                                     STANDOFF) for c, q in zip(captures, path)])
    return captures, seen


class DampedLeastSquares:
    """Baseline: damped least-squares IK on the end position and z axis (5 equations),
    no level condition, joints clipped to the limits, warm-started from the last answer."""

    def __init__(self, problem: TrackingProblem, p: np.ndarray, damping: float = 1e-4,
                 tolerance: float = 1e-12, max_iterations: int = 50):
        q = ca.SX.sym("q", problem.dof)
        goal = ca.SX.sym("goal", 12)
        up = ca.SX.sym("up", 3)
        T = problem.kinematics.tool_pose(q, p)
        residual = ca.vertcat(T[:3, 3] - goal[0:3], ca.dot(goal[3:6], T[:3, 2]),
                              ca.dot(goal[6:9], T[:3, 2]))
        J = ca.jacobian(residual, q)
        dq = -J.T @ ca.solve(J @ J.T + damping**2 * ca.SX.eye(5), residual)
        position_error, angle_error = error_expressions(T, goal, up)
        facing = ca.atan2(ca.norm_2(ca.cross(T[:3, 2], goal[9:12])), ca.dot(T[:3, 2], goal[9:12]))
        tilt = ca.fabs(ca.asin(ca.fmin(1, ca.fmax(-1, ca.dot(up, T[:3, 0])))))
        self.function = codegen.compiled(ca.Function(
            "dls_step", [q, goal, up], [dq, position_error, facing, tilt]))
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.lower, self.upper = problem.robot.lower_limits, problem.robot.upper_limits

    def solve(self, previous: np.ndarray, goal: np.ndarray, up: np.ndarray):
        q = previous.copy()
        for iteration in range(1, self.max_iterations + 1):  # noqa: B007 (returned below)
            dq, position_error, facing, tilt = self.function(q, goal, up)
            position_error, facing = float(position_error), float(facing)
            if position_error < self.tolerance and facing < self.tolerance:
                break
            q = np.clip(q + np.asarray(dq).ravel(), self.lower, self.upper)
        return q, position_error, facing, float(tilt), iteration


@contextlib.contextmanager
def quiet_stdout():
    """Send what C libraries print to standard output (qpOASES's banner) to /dev/null."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)


def summary(times_ms, cpu_ms, ok, errors, answers, extra=None) -> dict:
    """Figures of one method."""
    times_ms, cpu_ms = np.asarray(times_ms), np.asarray(cpu_ms)
    ok = np.asarray(ok)
    answers = np.asarray(answers)
    steps = np.abs(np.diff(answers, axis=0)).max() if len(answers) > 1 else 0.0
    result = {
        "cycles": int(len(times_ms)),
        "median_ms": float(np.median(times_ms)),
        "p99_ms": float(np.percentile(times_ms, 99)),
        "max_ms": float(times_ms.max()),
        "cpu_median_ms": float(np.median(cpu_ms)),
        "cpu_p99_ms": float(np.percentile(cpu_ms, 99)),
        "success_rate": float(ok.mean()),
        "max_constraint_error": float(np.max(np.asarray(errors)[ok])) if ok.any() else None,
        "largest_joint_step_rad": float(steps),
    }
    result.update(extra or {})
    return result


def run_tracker(tracker: Tracker, start, captures, seen, bar: Progress, done: int):
    tracker.reset(start)
    times, cpu, ok, errors, answers, iterations = [], [], [], [], [], []
    for k, (capture, observation) in enumerate(zip(captures, seen)):
        cpu_start = time.thread_time()
        step = tracker.step(capture, observation)
        cpu.append((time.thread_time() - cpu_start) * 1e3)
        times.append(step.solve_ms)
        ok.append(step.ok)
        errors.append(step.constraint_error)
        answers.append(step.q)
        iterations.append(step.iterations)
        bar.update(done + k + 1)
    return summary(times, cpu, ok, errors, answers,
                   {"mean_iterations": float(np.mean(iterations)),
                    "max_iterations": int(np.max(iterations))}), np.array(answers)


def run_dls(problem, p, start, captures, seen, bar: Progress, done: int) -> dict:
    baseline = DampedLeastSquares(problem, p)
    goal_function = problem.compiled_goal
    up = np.array([0.0, 0.0, 1.0])
    previous = start.copy()
    times, cpu, ok, errors, answers, tilts = [], [], [], [], [], []
    for k, (capture, observation) in enumerate(zip(captures, seen)):
        start, cpu_start = time.perf_counter(), time.thread_time()
        goal = np.asarray(goal_function(capture, observation, p, CAMERA, STANDOFF, up)).ravel()
        q, position_error, facing, tilt, _ = baseline.solve(previous, goal, up)
        good = position_error < 1e-6 and facing < 1e-6
        if good:
            previous = q
        cpu.append((time.thread_time() - cpu_start) * 1e3)
        times.append((time.perf_counter() - start) * 1e3)
        ok.append(good)
        errors.append(max(position_error, facing))
        answers.append(previous)
        tilts.append(tilt)
        bar.update(done + k + 1)
    return summary(times, cpu, ok, errors, answers,
                   {"max_level_tilt_deg": float(np.degrees(np.max(tilts))),
                    "note": "position and z axis only; the level condition is ignored"})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=5000)
    parser.add_argument("--ipopt-cycles", type=int, default=1000)
    args = parser.parse_args()
    report: dict = {"machine": {"python": platform.python_version(), "casadi": ca.__version__,
                                "processor": platform.processor() or platform.machine()},
                    "cycles": args.cycles, "camera_xyz_m": CAMERA.tolist(),
                    "standoff_m": STANDOFF, "robots": {}}
    methods = [("gauss_newton", {}), ("gauss_newton_interpreted", {"compiled": False}),
               ("sqpmethod_qrqp", {"method": "sqpmethod"}),
               ("sqpmethod_qpoases", {"method": "sqpmethod", "qpsol": "qpoases"}),
               ("ipopt", {"method": "ipopt"})]
    for name, (make, start) in ROBOTS.items():
        robot = make()
        problem = TrackingProblem(robot)
        path = lissajous_path(start, args.cycles)
        captures, seen = observations(robot, path)
        results = {}
        total = args.cycles * (len(methods) + 1)
        done = 0
        with Progress(f"tracking {name}", total=total) as bar, quiet_stdout():
            reference = Tracker(robot, CAMERA, STANDOFF, problem=problem, method="ipopt")
            level_start = reference.step(captures[0], seen[0]).q
            answers = {}
            for method, options in [methods[-1], *methods[:-1]]:
                count = args.ipopt_cycles if method == "ipopt" else args.cycles
                tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem, **options)
                results[method], answers[method] = run_tracker(
                    tracker, level_start, captures[:count], seen[:count], bar, done)
                count = min(count, args.ipopt_cycles)
                results[method]["max_difference_to_ipopt_rad"] = float(
                    np.abs(answers[method][:count] - answers["ipopt"][:count]).max())
                done += args.cycles
            results["damped_least_squares"] = run_dls(problem, robot.parameter_vector(),
                                                      level_start, captures, seen, bar, done)
        report["robots"][name] = {"dof": robot.dof,
                                  "true_largest_joint_step_rad":
                                      float(np.abs(np.diff(path, axis=0)).max()),
                                  "methods": results}
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
