"""Laser scans planned as an optimal control problem, judged on a simulated truth.

For the 6R example arm and a 25 mm sphere: scans of 200 and 500 readings at 50 Hz, sensor
only (the 8 laser and sphere unknowns, pendant poses) and robot plus laser. Reported per
scan: solve time and status, the index of the scan against its start path, the predicted
errors; then a simulated truth (laser origin off by ~2 mm, beam by ~5 mrad, sphere centre
by ~2 mm; robot plus laser also the robot's identifiable parameters, 0.5 mm / 1 mrad),
readings by the true robot with 0.01 mm noise, identified by ``sphere_fit.fit_sensor``
(sensor only) or the engine (``calibration.calibrate``, geometric, robot plus laser): the
laser origin error against its predicted standard error ("within the noise floor": below
3 predicted standard errors). Prints JSON.

    python benchmarks/scan.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from planning.trajectory import design_scan  # noqa: E402
from robocal_casadi.calibration import calibrate  # noqa: E402
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402
from robocal_casadi.instruments.laser.sphere_fit import fit_sensor  # noqa: E402
from robocal_casadi.instruments.simulate import true_parameters  # noqa: E402
from robocal_casadi.model.examples import industrial_6r  # noqa: E402
from robocal_casadi.model.kinematics import Kinematics  # noqa: E402
from robocal_casadi.model.robot import save_robot  # noqa: E402

NOISE = 10e-6  # [m]


def readings_of(poses, origin, beam, centre, radius, rng):
    """Laser readings [m] of flange ``poses`` for a true laser and sphere, with noise."""
    o = poses[:, :3, :3] @ origin + poses[:, :3, 3]
    d = poses[:, :3, :3] @ beam
    v = o - centre
    b = np.einsum("ni,ni->n", d, v)
    disc = b**2 - (np.einsum("ni,ni->n", v, v) - radius**2)
    if np.any(disc <= 0):
        raise RuntimeError("a true beam misses the sphere")
    return -b - np.sqrt(disc) + rng.normal(0, NOISE, len(b))


def case(path: Path, count: int, sensor_only: bool, seed: int = 0) -> dict:
    dataset = load_dataset(path, require_data=False)
    started = time.perf_counter()
    scan = design_scan(dataset, count, seed=seed, sensor_only=sensor_only, quiet=True)
    total = time.perf_counter() - started
    setup = scan.setup
    rng = np.random.default_rng(seed + 7)
    origin = setup.offset + rng.normal(0, 2e-3, 3)
    beam = setup.axis + rng.normal(0, 5e-3, 3)
    beam /= np.linalg.norm(beam)
    centre = setup.centre + rng.normal(0, 2e-3, 3)
    entry = {"samples": count, "sensor_only": sensor_only, "duration_s": float(scan.times[-1]),
             "solve_seconds": scan.seconds, "total_seconds": total, "status": scan.solver_status,
             "index": scan.index, "index_value": scan.value, "start_index_value": scan.start_value,
             "identifiable": len(scan.identifiable),
             "predicted_tool_error_mm": 1e3 * scan.tool_error,
             "predicted_origin_std_mm": (1e3 * scan.laser_errors[:3]).tolist()}
    if sensor_only:
        readings = readings_of(scan.flange_poses, origin, beam, centre, setup.radius, rng)
        fit = fit_sensor(scan.flange_poses, readings, setup.radius, origin_guess=setup.offset,
                         direction_guess=setup.axis, centre_guess=setup.centre)
        found = fit.origin
        entry["residual_rms_mm"] = 1e3 * fit.residual_rms
    else:
        kin = Kinematics(dataset.robot)
        registry = kin.registry
        errors = {}
        for name in scan.identifiable:
            if name in registry:
                std = 0.5e-3 if registry.quantity(name) == "length" else 1e-3
                errors[name] = float(rng.normal(0, std))
        p_true, _ = true_parameters(dataset.robot, errors, rng)
        poses = kin.flange_poses(scan.joints, p_true)
        readings = readings_of(poses, origin, beam, centre, setup.radius, rng)
        data = replace(dataset, joints=scan.joints, distance=readings, flange_poses=None,
                       extras={})
        result = calibrate([data], diagnose=False)
        found = np.array([result.mounted[f"laser_{k}"][0] for k in "xyz"])
        entry["residual_rms_mm"] = 1e3 * result.fit.rms_geometric
    error = np.abs(found - origin)
    entry["origin_error_mm"] = (1e3 * error).tolist()
    entry["origin_error_in_predicted_std"] = (error / scan.laser_errors[:3]).tolist()
    entry["within_noise_floor"] = bool(np.all(error < 3 * scan.laser_errors[:3]))
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 readings only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        save_robot(industrial_6r(), folder / "r6.yaml")
        path = folder / "sphere.yaml"
        path.write_text(yaml.safe_dump(dict(
            kind="sphere_laser", robot="r6.yaml", units=dict(length="mm", angle="deg"),
            sphere=dict(radius=25, centre_guess=[900, 100, 300]),
            laser=dict(origin_guess=[60, -15, 140], direction_guess=[0, 0, 1]),
            data="none.csv")))
        counts = [200] if args.quick else [200, 500]
        results = [case(path, n, sensor_only) for sensor_only in (True, False) for n in counts]
    print(json.dumps({"benchmark": "scan", "noise_mm": 1e3 * NOISE, "cases": results},
                     indent=2))


if __name__ == "__main__":
    main()
