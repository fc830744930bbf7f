"""Point laser and sphere: time and accuracy, side by side in one process. Prints JSON.

1. Sensor only, the published example (820 readings, tilting scan, 25 mm sphere, 0.01 mm
   distance noise): our Levenberg-Marquardt (closed-form start, no guesses; and with the
   file's direction guess), our IPOPT (CasADi, exact derivatives), against
   ``scipy.optimize.least_squares`` with a finite-difference Jacobian on the published
   method's parametrisation ``[x0, y0, z0, nx, ny, xc, yc, zc]`` (``nz = sqrt(1 - nx^2 - ny^2)``),
   started from the guesses a user would write.
2. Robot plus sensor: 300 joint readings of the example 6R arm, identified jointly through
   ``calibrate``, against scipy ``least_squares`` (finite differences) on the same
   ``Problem`` and free unknowns.

Small dense problems run fastest on one BLAS thread; the benchmark pins it.

    python benchmarks/sphere_laser.py [--repeats 50]
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_sphere_laser import NOISE, RADIUS, joint_scan, noise_floor, patent_truth, tilting_scan  # noqa: E402

from robocal_casadi.calibration import (  # noqa: E402
    Problem,
    analyse_identifiability,
    calibrate,
    models_for,
    solve,
)
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402
from robocal_casadi.instruments.laser.sphere_fit import (  # noqa: E402
    Scan,
    _ipopt,
    _ipopt_solver,
    _levenberg_marquardt,
    algebraic_start,
    fit_sensor,
)

PATENT_NAMES = ("x0", "y0", "z0", "nx", "ny", "xc", "yc", "zc")
MM = np.array([1e3, 1e3, 1e3, 1.0, 1.0, 1e3, 1e3, 1e3])  # SI -> the published example's units


def _median_seconds(call, repeats: int):
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = call()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), value


def _patent_std(fit) -> np.ndarray:
    return np.concatenate([fit.origin_std, fit.direction_std[:2], fit.centre_std])


def sensor_case(repeats: int) -> dict:
    rng = np.random.default_rng(0)
    p0, n, c = patent_truth()
    poses, distance, incidence = tilting_scan(rng, 820, p0, n, c, radius=RADIUS, noise=NOISE)
    truth = np.concatenate([p0, n[:2], c])
    out: dict = {"readings": 820, "radius_mm": RADIUS * 1e3, "noise_mm": NOISE * 1e3,
                 "noise_floor_rms_mm": noise_floor(incidence) * 1e3,
                 "truth": dict(zip(PATENT_NAMES, (truth * MM).tolist()))}

    def report(fit, seconds: float) -> dict:
        estimate = fit.patent_vector()
        std = _patent_std(fit)
        return {"seconds": seconds, "iterations": fit.iterations, "status": fit.status,
                "estimate": dict(zip(PATENT_NAMES, (estimate * MM).tolist())),
                "std": dict(zip(PATENT_NAMES, (std * MM).tolist())),
                "max_abs_error_in_std": float(np.max(np.abs(estimate - truth) / std)),
                "residual_rms_mm": fit.residual_rms * 1e3}

    seconds, lm = _median_seconds(lambda: fit_sensor(poses, distance, RADIUS), repeats)
    out["ours_lm_no_guess"] = report(lm, seconds)
    seconds, fit = _median_seconds(
        lambda: fit_sensor(poses, distance, RADIUS, direction_guess=[0, 0, 1]), repeats)
    out["ours_lm_direction_guess"] = report(fit, seconds)
    start = time.perf_counter()
    _ipopt_solver(len(distance))
    build = time.perf_counter() - start
    seconds, ipopt = _median_seconds(lambda: fit_sensor(poses, distance, RADIUS,
                                                        method="ipopt"), max(repeats // 5, 3))
    out["ours_ipopt"] = dict(report(ipopt, seconds), build_seconds=build,
                             max_difference_from_lm_mm=float(np.max(np.abs(
                                 (ipopt.patent_vector() - lm.patent_vector()) * MM))))
    scan = Scan.from_poses(poses, distance, RADIUS)
    start_point = algebraic_start(scan)  # both solvers from the same closed-form start
    seconds, solved = _median_seconds(lambda: _ipopt(scan, *start_point), max(repeats // 5, 3))
    out["solver_only_from_closed_form_start"] = {
        "ipopt": {"seconds": seconds, "iterations": solved[3], "status": solved[4]}}
    seconds, solved = _median_seconds(
        lambda: _levenberg_marquardt(scan, *start_point, max_iterations=100), repeats)
    out["solver_only_from_closed_form_start"]["lm"] = {
        "seconds": seconds, "iterations": solved[3], "status": solved[4]}

    from scipy.optimize import least_squares

    R, t = poses[:, :3, :3], poses[:, :3, 3]

    def residual(z):  # what a user would write: the published method's 8 unknowns
        nz = np.sqrt(max(1.0 - z[3] ** 2 - z[4] ** 2, 0.0))
        offsets = z[0:3] + distance[:, None] * np.array([z[3], z[4], nz])
        points = np.einsum("nij,nj->ni", R, offsets) + t
        return np.linalg.norm(points - z[5:8], axis=1) - RADIUS

    std = _patent_std(lm)
    starts = {  # a user's guesses (within a few mm), and none (flange origin, +z, centroid)
        "scipy_2point_from_guesses": np.array([0.060, -0.015, 0.140, 0.0, 0.0, -0.120, -0.305,
                                               0.105]),
        "scipy_2point_without_guesses": np.concatenate([np.zeros(5), t.mean(axis=0)])}
    for key, guess in starts.items():
        seconds, fitted = _median_seconds(lambda guess=guess: least_squares(
            residual, guess, jac="2-point", method="trf", x_scale="jac"), max(repeats // 5, 3))
        out[key] = {
            "seconds": seconds, "evaluations": int(fitted.nfev), "status": int(fitted.status),
            "max_abs_error_in_std": float(np.max(np.abs(fitted.x - truth) / std)),
            "residual_rms_mm": float(np.sqrt(np.mean(fitted.fun ** 2))) * 1e3,
            "max_difference_from_lm_mm": float(np.max(np.abs((fitted.x - lm.patent_vector())
                                                             * MM)))}
    out["speedup_lm_over_scipy_from_guesses"] = (
        out["scipy_2point_from_guesses"]["seconds"] / out["ours_lm_no_guess"]["seconds"])
    return out


def robot_case() -> dict:
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        path, truth, p0, n, centre, incidence = joint_scan(Path(folder) / "scan",
                                                           np.random.default_rng(4))
        simulate_seconds = time.perf_counter() - start
        dataset = load_dataset(path)
    start = time.perf_counter()
    result = calibrate([dataset], diagnose=False)
    seconds = time.perf_counter() - start
    identified = [p for p in result.parameters if p.identifiable]
    z_robot = [abs(p.estimate - truth.get(p.name, p.nominal)) / p.std for p in identified]
    laser = np.concatenate([p0, n])
    z_laser = [abs(result.mounted[name][0] - laser[k]) / result.mounted[name][1]
               for k, name in enumerate(("laser_x", "laser_y", "laser_z", "laser_nx",
                                         "laser_ny", "laser_nz"))]
    out = {"robot": "industrial_6r", "readings": dataset.distance.size,
           "simulate_seconds": simulate_seconds,
           "ours_calibrate": {"seconds": seconds, "solver": result.solver,
                              "identified_robot_parameters": len(identified),
                              "max_abs_error_in_std_robot": float(max(z_robot)),
                              "max_abs_error_in_std_laser": float(max(z_laser)),
                              "rms_nominal_mm": result.fit.rms_nominal * 1e3,
                              "rms_geometric_mm": result.fit.rms_geometric * 1e3,
                              "noise_floor_rms_mm": 1e3 * noise_floor(
                                  incidence, unknowns=result.solver["free_unknowns"])}}

    # the same geometric solve by scipy with finite differences, same problem and unknowns
    from scipy.optimize import least_squares

    problem = Problem(dataset.robot, models_for([dataset]))
    nominal = solve(problem, problem.initial(), problem.mask("placement"))
    identifiability = analyse_identifiability(problem, nominal.x)
    free = problem.mask("placement")
    free[problem.unknowns.indices(identifiability.identifiable)] = True
    start = time.perf_counter()
    ours = solve(problem, nominal.x, free)
    ours_seconds = time.perf_counter() - start
    index = np.flatnonzero(free)

    def residual(z):
        x = nominal.x.copy()
        x[index] = z
        return problem.residual(x)

    start = time.perf_counter()
    fitted = least_squares(residual, nominal.x[index], jac="2-point", method="trf", x_scale="jac")
    scipy_seconds = time.perf_counter() - start
    x = nominal.x.copy()
    x[index] = fitted.x
    out["geometric_solve_only"] = {
        "free_unknowns": int(free.sum()),
        "ours_lm_seconds": ours_seconds, "ours_rms_mm": 1e3 * problem.rms(ours.x),
        "scipy_2point_seconds": scipy_seconds, "scipy_evaluations": int(fitted.nfev),
        "scipy_rms_mm": 1e3 * problem.rms(x),
        "max_difference_in_std": float(np.max(np.abs(x[index] - ours.x[index])
                                              / ours.std[index]))}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=50, help="timed repeats per solver")
    args = parser.parse_args()
    print(json.dumps({"benchmark": "sphere_laser", "sensor_only": sensor_case(args.repeats),
                      "robot_plus_sensor": robot_case()}, indent=2))


if __name__ == "__main__":
    main()
