"""Calibration time and accuracy: our engine against what a user would otherwise write
(the residual in plain numpy, scipy least_squares with finite-difference Jacobians) on
the same problem and the same free unknowns, side by side in one process.

Cases: 30 bar placements and 1,000 and 10,000 tracker points of the example 6R arm, and
how the time grows with the number of rows. Times are CPU seconds (``time.process_time``),
which other work on the machine moves less than wall time.

scipy runs twice: with its default tolerances (it stops early, a little off the minimum)
and converged (``ftol = xtol = gtol = 1e-15``, central differences), where it must reach
our answer: ``max_relative_difference`` is the largest relative difference of a free
unknown between the two, ``speedup_converged`` the CPU time ratio. Each case's
``headline`` is the comparison at the same answer (scipy converged, within 1e-9 relative
of ours) with the one at scipy's default tolerances beside it. Prints JSON.

    python benchmarks/calibration.py [--quick] [--rows 1000,5000] [--no-growth] [--no-loop]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from robocal_casadi.calibration import Problem, analyse_identifiability, models_for, solve
from robocal_casadi.instruments.datasets import TrackerPoints
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.transforms import pose_from_xyz_rpy


def numpy_points(robot, Q: np.ndarray, p: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """World positions (N x 3) of a flange point: standard DH in plain numpy, batched."""
    registry = robot.parameters()
    n = len(Q)
    T = np.broadcast_to(pose_from_xyz_rpy([p[registry.index(f"base_{k}")] for k in "xyz"],
                                          [p[registry.index(f"base_r{k}")] for k in "xyz"]),
                        (n, 4, 4)).copy()
    for i in range(1, robot.dof + 1):
        theta, d, a, alpha, beta = (p[registry.index(f"{s}{i}")]
                                    for s in ("theta", "d", "a", "alpha", "beta"))
        t = Q[:, i - 1] + theta
        ct, st, ca, sa, cb, sb = np.cos(t), np.sin(t), np.cos(alpha), np.sin(alpha), \
            np.cos(beta), np.sin(beta)
        # Rz(t) Tz(d) Tx(a) Rx(alpha) Ry(beta)
        R_x = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        R_y = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
        A = np.zeros((n, 4, 4))
        A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = ct, -st, st, ct
        A[:, 2, 2] = A[:, 3, 3] = 1.0
        A[:, :3, 3] = np.column_stack([a * ct, a * st, np.full(n, d)])
        A[:, :3, :3] = A[:, :3, :3] @ (R_x @ R_y)
        T = T @ A
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def numpy_points_loop(robot, Q: np.ndarray, p: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The same, one configuration at a time (how forward kinematics is usually written)."""
    return np.vstack([numpy_points(robot, q[None, :], p, offset) for q in Q])


def numpy_residual(problem: Problem, x_start: np.ndarray, free: np.ndarray, points=None):
    """The problem's residual written the way a user would: plain numpy, one function."""
    model = problem.models[0]
    robot = problem.robot
    dataset = model.dataset
    robot_slice = problem.slices["robot"]
    mounted = problem.mounted_indices(model)
    placement = problem.placement_indices(model)
    index = np.flatnonzero(free)

    def residual(z):
        x = x_start.copy()
        x[index] = z
        world = (points or numpy_points)(robot, dataset.joints, x[robot_slice], x[mounted])
        if dataset.kind == "tracker_points":
            T = model.instrument_transform(x[placement])
            return (dataset.measured - (world @ T[:3, :3].T + T[:3, 3])).ravel()
        out = []
        for pose in np.unique(dataset.pose):
            rows = {dataset.point[i]: world[i] for i in np.flatnonzero(dataset.pose == pose)}
            ac, bd = rows["C"] - rows["A"], rows["D"] - rows["B"]
            length = dataset.distances[0][2]
            out += [np.linalg.norm(ac) - length, np.linalg.norm(bd) - length, ac @ bd / length]
        return np.array(out)

    return residual, index


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


def bar_case(placements: int, seed: int = 0, noise: float = 10e-6):
    """A simulated cross-bar data set (written to a temporary folder) and its truth."""
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="robocal-bench-"))
    sim = simulate(industrial_6r(), "cross_bar", out_dir=folder / "bar", rows=placements,
                   noise=noise, geometric_errors=(0.5e-3, 0.5e-3), seed=seed, progress=False)
    return sim.load(), sim.truth.robot.parameter_vector()


CONVERGED = dict(ftol=1e-15, xtol=1e-15, gtol=1e-15)  # scipy run to the minimum


def _scipy(problem: Problem, x_start: np.ndarray, free: np.ndarray, ours: np.ndarray, *,
           jac: str = "2-point", points=None, **tolerances) -> dict:
    """scipy least_squares on the numpy residual from ``x_start``: CPU seconds, counts,
    and how far its answer is from ``ours`` (largest relative difference, free unknowns)."""
    from scipy.optimize import least_squares

    residual, index = numpy_residual(problem, x_start, free, points=points)
    start = time.process_time()
    fitted = least_squares(residual, x_start[index], jac=jac, method="trf", x_scale="jac",
                           **tolerances)
    seconds = time.process_time() - start
    x = x_start.copy()
    x[index] = fitted.x
    difference = np.abs(fitted.x - ours[index]) / np.maximum(np.abs(ours[index]), 1e-300)
    return {"cpu_seconds": seconds, "evaluations": int(fitted.nfev),
            "jacobians": int(fitted.njev or 0), "rms_mm": 1e3 * problem.rms(x),
            "max_relative_difference": float(difference.max())}


def _label(dataset) -> str:
    """The case in words: bar placements or tracker points."""
    if dataset.kind == "cross_bar":
        return f"{len(np.unique(dataset.pose)):,} bar placements"
    return f"{dataset.rows:,} tracker points"


SAME_ANSWER = 1e-9  # largest relative difference of a free unknown that counts as the same


def headline(default: dict, converged: dict, seconds: float) -> dict:
    """The comparison the benchmark stands for: our solve against scipy run to the same
    answer (converged; ``same_answer`` says whether it is within ``SAME_ANSWER``), and,
    beside it, against scipy with its default tolerances (which stops early; whether that
    answer is the same too)."""
    return {"speedup_same_answer": converged["cpu_seconds"] / seconds,
            "same_answer": converged["max_relative_difference"] <= SAME_ANSWER,
            "speedup_default_tolerances": default["cpu_seconds"] / seconds,
            "default_tolerances_same_answer":
                default["max_relative_difference"] <= SAME_ANSWER,
            "same_answer_tolerance": SAME_ANSWER}


def run_case(dataset, baseline: bool, loop: bool = True) -> dict:
    start = time.process_time()
    problem = Problem(dataset.robot, models_for([dataset]))
    x0 = problem.initial()
    nominal = solve(problem, x0, problem.mask("placement"))
    identifiability = analyse_identifiability(problem, nominal.x)
    free = problem.mask("placement")
    free[problem.unknowns.indices(identifiability.identifiable)] = True
    solve_start = time.process_time()
    ours = solve(problem, nominal.x, free)
    end = time.process_time()
    out = {"case": _label(dataset), "kind": dataset.kind, "rows": dataset.rows,
           "free_unknowns": int(free.sum()),
           "ours": {"cpu_seconds_total": end - start, "cpu_seconds_solve": end - solve_start,
                    "iterations": ours.iterations,
                    "rms_mm": 1e3 * problem.rms(ours.x)}}
    if baseline:
        residual, index = numpy_residual(problem, nominal.x, free)
        assert np.allclose(residual(nominal.x[index]), problem.residual(nominal.x), atol=1e-12)
        seconds = end - solve_start
        default = _scipy(problem, nominal.x, free, ours.x)
        out["numpy_scipy_least_squares_fd"] = default
        out["speedup_solve"] = default["cpu_seconds"] / seconds
        converged = _scipy(problem, nominal.x, free, ours.x, jac="3-point", **CONVERGED)
        out["numpy_scipy_least_squares_fd_converged"] = converged
        out["speedup_converged"] = converged["cpu_seconds"] / seconds
        out["headline"] = headline(default, converged, seconds)
        if loop:  # the same with forward kinematics written per configuration
            looped = _scipy(problem, nominal.x, free, ours.x, points=numpy_points_loop)
            out["loop_numpy_scipy_least_squares_fd"] = looped
            out["speedup_solve_loop"] = looped["cpu_seconds"] / seconds
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="smaller cases")
    parser.add_argument("--rows", type=lambda text: [int(v) for v in text.split(",")],
                        metavar="N,N", help="tracker sizes compared with scipy (default "
                        "1000,10000; --quick 300,1000)")
    parser.add_argument("--no-growth", action="store_true", help="skip the growth series")
    parser.add_argument("--no-loop", action="store_true",
                        help="skip scipy with forward kinematics per configuration (slow)")
    args = parser.parse_args()
    sizes = args.rows or ((300, 1000) if args.quick else (1000, 10000))
    loop = not args.no_loop
    results = [run_case(bar_case(30)[0], baseline=True, loop=loop)]
    results += [run_case(tracker_case(n)[0], baseline=True, loop=loop) for n in sizes]
    growth = [] if args.no_growth else [
        run_case(tracker_case(n)[0], baseline=False)
        for n in ((250, 500, 1000) if args.quick else (1000, 2000, 5000, 10000, 20000))]
    print(json.dumps({"benchmark": "calibration", "cases": results,
                      "growth": [{"rows": g["rows"],
                                  "cpu_seconds_solve": g["ours"]["cpu_seconds_solve"],
                                  "cpu_seconds_total": g["ours"]["cpu_seconds_total"]}
                                 for g in growth]},
                     indent=2))


if __name__ == "__main__":
    main()
