"""The learned map on an effect no library names: does it pay, and only where it should?

Tracker data of the example 6R arm are computed here (pinocchio forward kinematics of a
true robot off its drawing by random DH errors; tracker frame = world frame; noise
``NOISE`` per coordinate), with an invented error of the tool position no effect of the
library describes: a smooth world-frame shift that depends on joints 2 and 3 as a sum
of sines,

    e(q) = A (sin(2 q2 + 0.4) cos(q3), cos(3 q3 - 0.2) sin(q2), 0.7 sin(q2 + 2 q3))  [m]

Scenarios (fit rows / held-out rows):

* ``invented``: the error above, fit and held-out rows over the same joint ranges;
* ``clean``: no such error (the map must be absent, the held-out error unchanged);
* ``region_q1``: the error above, fit on the lower half of joint 1's range, held out on
  the upper half (the map's variables stay inside its region);
* ``region_q2``: the error above, fit on the lower half of joint 2's range, held out on
  the upper half (the map must fade out, never make it worse).

For each scenario and seed: held-out RMS [m] over every held-out reading of the
geometric model, of the final one (with what diagnosis and the map added) and of the
final one with the map never offered (physical effects only), their ratios (and over
the readings validation keeps), whether the map was kept, and the
shares of the fit's mean square. Prints JSON.

    python benchmarks/learned_map.py [--seeds 3] [--rows 300] [--only invented,clean]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from robocal_casadi import load_dataset
from robocal_casadi.calibration import calibrate, identification
from robocal_casadi.instruments.datasets import dataset_rows
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import frame_placements, pinocchio_model
from robocal_casadi.model.robot import save_robot
from robocal_casadi.results import mean_square_shares

NOISE = 1e-5  # [m] per tracker coordinate
AMPLITUDE = 3e-4  # [m] of the invented error
TARGET = np.array([0.0, 0.0, 0.1])  # [m] reflector in the flange frame
HELD_OUT = 150


def invented_error(Q: np.ndarray) -> np.ndarray:
    """The invented world-frame error (N x 3) [m] at joints ``Q`` (N x dof)."""
    q2, q3 = Q[:, 1], Q[:, 2]
    return AMPLITUDE * np.column_stack([np.sin(2 * q2 + 0.4) * np.cos(q3),
                                        np.cos(3 * q3 - 0.2) * np.sin(q2),
                                        0.7 * np.sin(q2 + 2 * q3)])


def tracker_table(folder: Path, robot, Q: np.ndarray, seed: int, error: bool):
    """Tracker data at joints ``Q`` of the true robot (random DH errors of 0.5 mm and
    0.5 mrad, fixed per benchmark), with the invented error when ``error``."""
    folder.mkdir(parents=True, exist_ok=True)
    kinematics = Kinematics(robot)
    p = kinematics.nominal.copy()
    truth = np.random.default_rng(700)
    for i in range(1, robot.dof + 1):
        for stem in ("theta", "d", "a", "alpha"):
            p[kinematics.registry.index(f"{stem}{i}")] += truth.normal(0.0, 5e-4)
    model = pinocchio_model(robot.with_parameters(p), with_links=False)
    points = []
    for q in Q:
        T = frame_placements(model, q, ["flange"])[0]
        points.append(T[:3, :3] @ TARGET + T[:3, 3])
    points = np.array(points) + np.random.default_rng(seed).normal(0.0, NOISE, (len(Q), 3))
    if error:
        points += invented_error(Q)
    save_robot(robot, folder / "robot.yaml")
    (folder / "dataset.yaml").write_text(
        "kind: tracker_points\nrobot: robot.yaml\nunits: {length: m, angle: rad}\n"
        f"target: {{xyz: [{TARGET[0]}, {TARGET[1]}, {TARGET[2]}]}}\ndata: points.csv\n")
    header = ",".join([f"q{j + 1}" for j in range(robot.dof)] + ["x", "y", "z"])
    lines = [header] + [",".join(repr(float(v)) for v in row)
                        for row in np.column_stack([Q, points])]
    (folder / "points.csv").write_text("\n".join(lines) + "\n")
    return load_dataset(folder / "dataset.yaml")


def datasets(name: str, folder: Path, robot, rows: int, seed: int):
    rng = np.random.default_rng(seed)
    lower = np.maximum(robot.lower_limits, -math.pi) * 0.9
    upper = np.minimum(robot.upper_limits, math.pi) * 0.9
    error = name != "clean"
    if name in ("invented", "clean"):
        fit = tracker_table(folder / "fit", robot, rng.uniform(lower, upper, (rows, robot.dof)),
                            seed, error)
        held = tracker_table(folder / "held", robot,
                             rng.uniform(lower, upper, (HELD_OUT, robot.dof)), seed + 1, error)
        return fit, held
    joint = {"region_q1": 0, "region_q2": 1}[name]
    whole = tracker_table(folder / "all", robot,
                          rng.uniform(lower, upper, (rows * 2, robot.dof)), seed, error)
    low = whole.joints[:, joint] < np.median(whole.joints[:, joint])
    return dataset_rows(whole, low), dataset_rows(whole, ~low)


def run(name: str, rows: int, seed: int, folder: Path) -> dict:
    robot = ROBOTS["industrial_6r"]()
    fit, held = datasets(name, folder / f"{name}-{seed}", robot, rows, seed)
    start = time.perf_counter()
    result = calibrate([fit], [held])
    seconds = time.perf_counter() - start
    without = _without_map(fit, held)
    v, f = result.validation_all or result.validation, result.fit
    kept = result.validation
    mapped = [e for e in result.effects if e.name == "residual_map"]
    return {"scenario": name, "seed": seed, "rows": rows,
            "held_out_rms_m": {"geometric": v.rms_geometric, "final": v.rms_final},
            "final_over_geometric": v.rms_final / v.rms_geometric,
            "held_out_rms_without_map_m": without,
            "final_over_without_map": v.rms_final / without,
            "kept_readings_final_over_geometric": kept.rms_final / kept.rms_geometric,
            "map_kept": bool(mapped), "map_joints": list(mapped[0].joints) if mapped else [],
            "effects": [e.name for e in result.effects], "recommended": result.recommended,
            "unexplained": None if result.unexplained is None else
            list(result.unexplained.variables),
            "shares": mean_square_shares(f.rms_nominal, f.rms_geometric, f.rms_final,
                                         result.effects),
            "seconds": seconds}


def _without_map(fit, held) -> float:
    """Held-out RMS [m] over every reading of the same calibration with the learned map
    never offered (physical effects only): what the map is judged against."""
    offer = identification._learned
    identification._learned = lambda final, structure, **options: final
    try:
        result = calibrate([fit], [held])
    finally:
        identification._learned = offer
    return (result.validation_all or result.validation).rms_final


SCENARIOS = ("invented", "clean", "region_q1", "region_q2")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=300, help="fit rows per scenario")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per scenario")
    parser.add_argument("--only", default=",".join(SCENARIOS), help="scenarios, comma-separated")
    args = parser.parse_args()
    out = []
    with tempfile.TemporaryDirectory() as folder:
        for name in args.only.split(","):
            for seed in range(1, args.seeds + 1):
                out.append(run(name, args.rows, seed, Path(folder)))
    summary = {}
    for name in args.only.split(","):
        ratios = [r["final_over_geometric"] for r in out if r["scenario"] == name]
        against = [r["final_over_without_map"] for r in out if r["scenario"] == name]
        summary[name] = {"final_over_geometric_max": max(ratios),
                         "final_over_geometric_min": min(ratios),
                         "final_over_without_map_max": max(against),
                         "map_kept": [r["map_kept"] for r in out if r["scenario"] == name]}
    print(json.dumps({"runs": out, "summary": summary}, indent=2))


if __name__ == "__main__":
    main()
