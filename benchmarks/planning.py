"""Designed against random feasible plans of the same size, on a simulated truth.

For each set-up (tracker points and cross bar, on the 6R example arm and the 7-DOF
one): a true robot (``robocal_casadi.instruments.simulate.true_parameters``: random errors on the
parameters the data identify, 0.5 mm and 1 mrad), measurements of each plan simulated
by a forward pass of the true robot with the same noise (tracker 0.01 mm per axis in a
random instrument frame; bar: the true robot seated on the planned sockets, 0.01 mm
seating noise), calibrated by the engine (``identification.calibrate``, geometric only)
and validated on a separate random feasible set (placements fitted again). Reported per
plan size: condition number, model error (the calibrated measured point against the true
one over 500 random configurations, after the best rigid motion: the parameter error
where it matters), per-parameter errors when the engine kept the planned parameter set,
validation RMS; designed plan against the median of random ones; the ratio of
condition numbers (goal <= 0.3); and the fewest poses that reach the target model
error. Beside the simulated margin over random plans (goal >= 30%) it prints the
planner's predicted margin and the attainable one: the margin of the optimal approximate
design over the candidate pool (``planning.approximate``), which no choice of poses from
the pool can exceed. Prints JSON.

    python benchmarks/planning.py [--quick] [--set-up industrial_6r/cross_bar ...]
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

# This script's own name is ``planning``: keep its folder off the import path so that
# ``import planning`` finds the package.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from planning.candidates import generate  # noqa: E402
from planning.design import design_plan  # noqa: E402
from planning.planned import engine_identifiability, planned_dataset  # noqa: E402
from planning.reach import Workspace  # noqa: E402
from planning.runnable import runnable_setup  # noqa: E402
from planning.setup import setup_from_dataset  # noqa: E402
from robocal_casadi.calibration import calibrate  # noqa: E402
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402
from robocal_casadi.instruments.simulate import true_parameters  # noqa: E402
from robocal_casadi.instruments.tracker.model import rigid_registration  # noqa: E402
from robocal_casadi.model.examples import industrial_6r, panda_7dof  # noqa: E402
from robocal_casadi.model.kinematics import Kinematics  # noqa: E402
from robocal_casadi.model.robot import save_robot  # noqa: E402
from robocal_casadi.model.transforms import pose_from_xyz_rpy  # noqa: E402

NOISE = 10e-6  # [m]
LENGTH_ERROR, ANGLE_ERROR = 0.5e-3, 1e-3  # [m], [rad] standard deviations of the truth
INDICES = ("tool", "cond", "O1")  # designs compared: tool error (default), cond, O1
TARGET = {"tracker_points": 0.010e-3, "cross_bar": 0.010e-3}  # [m] model error goal


def setups(folder: Path) -> dict[str, Path]:
    save_robot(industrial_6r(), folder / "r6.yaml")
    save_robot(panda_7dof(), folder / "p7.yaml")
    files = {
        "industrial_6r/tracker_points": dict(
            kind="tracker_points", robot="r6.yaml", units=dict(length="mm", angle="deg"),
            target=dict(xyz=[0, 0, 100]), instrument=dict(xyz=[2500, 0, 800])),
        "industrial_6r/cross_bar": dict(
            kind="cross_bar", robot="r6.yaml", units=dict(length="mm", angle="deg"),
            bar=dict(length=400), probe=dict(xyz=[0, 0, 150])),
        "panda_7dof/tracker_points": dict(
            kind="tracker_points", robot="p7.yaml", units=dict(length="m", angle="rad"),
            target=dict(xyz=[0, 0, 0.1]), instrument=dict(xyz=[2.0, 0.5, 0.6])),
        "panda_7dof/cross_bar": dict(
            kind="cross_bar", robot="p7.yaml", units=dict(length="m", angle="rad"),
            bar=dict(length=0.3), probe=dict(xyz=[0, 0, 0.1])),
    }
    paths = {}
    for name, content in files.items():
        content["data"] = "none.csv"
        paths[name] = folder / (name.replace("/", "_") + ".yaml")
        paths[name].write_text(yaml.safe_dump(content))
    return paths


class Simulator:
    """Measurements of planned candidates by the true robot, with noise."""

    def __init__(self, dataset, p_true: np.ndarray, rng: np.random.Generator):
        self.dataset = dataset
        self.kinematics = Kinematics(dataset.robot)
        self.p_true = p_true
        self.rng = rng
        self.instrument = pose_from_xyz_rpy(rng.normal(0, 1.0, 3), rng.uniform(-np.pi, np.pi, 3))
        # the true robot, limits widened by 2 deg: a plan at a limit stays reachable
        widened = replace(dataset.robot, joints=tuple(
            replace(j, limits=None if j.limits is None
                    else (j.limits[0] - 0.035, j.limits[1] + 0.035))
            for j in dataset.robot.joints))
        self.true_workspace = Workspace(Kinematics(widened), p_true, table_height=-np.inf,
                                        tolerance=1e-8)

    def dataset_of(self, candidates):
        planned = planned_dataset(self.dataset, candidates, self.kinematics)
        if planned.kind == "tracker_points":
            world = self.kinematics.points(planned.joints, planned.target, self.p_true)
            T = self.instrument
            measured = world @ T[:3, :3].T + T[:3, 3] + self.rng.normal(0, NOISE, world.shape)
            return replace(planned, measured=measured)
        # touches: the true robot seated on the planned sockets (with seating noise)
        sockets = np.array([c.sockets[p] for c in candidates for p in c.points])
        sockets = sockets + self.rng.normal(0, NOISE, sockets.shape)
        solved = self.true_workspace.solve_points(sockets, planned.probe, planned.joints)
        joints = solved.joints
        for _ in range(5):
            missing = np.flatnonzero(~solved.ok)
            if not missing.size:
                break
            seeds = planned.joints[missing] + self.rng.normal(0, 0.05, joints[missing].shape)
            again = self.true_workspace.solve_points(sockets[missing], planned.probe, seeds)
            joints[missing[again.ok]] = again.joints[again.ok]
            ok = solved.ok.copy()
            ok[missing[again.ok]] = True
            solved = replace(solved, ok=ok)
        if not solved.ok.all():
            raise RuntimeError("the true robot could not reach a planned socket")
        return replace(planned, joints=joints)


def model_error(data, result, p_true, Q_test) -> float:
    """RMS [m] over ``Q_test`` of the calibrated measured point against the true one, after
    the best rigid motion (what neither kind can see): the parameter error expressed where
    it matters, free of the choice among dependent parameters."""
    kinematics = Kinematics(data.robot)
    offset_name = "target" if data.kind == "tracker_points" else "probe"
    nominal_offset = data.target if data.kind == "tracker_points" else data.probe
    offset = np.array([result.mounted.get(f"{offset_name}_{k}", (v, None))[0]
                       for k, v in zip("xyz", nominal_offset)])
    p_cal = kinematics.registry.vector_of(result.robot_calibrated)
    calibrated = kinematics.points(Q_test, offset, p_cal)
    true = kinematics.points(Q_test, nominal_offset, p_true)
    R, t = rigid_registration(calibrated, true)
    return float(np.sqrt(np.mean(np.sum((calibrated @ R.T + t - true) ** 2, axis=1))))


def evaluate(simulator, candidates, validation, identifiable, p_true, Q_test):
    data = simulator.dataset_of(candidates)
    result = calibrate([data], [validation], diagnose=False)
    registry = Kinematics(data.robot).registry
    entry = {}
    judged = engine_identifiability(simulator.dataset, candidates, identifiable)
    entry["condition_number"] = judged.condition_number
    entry["model_error_mm"] = 1e3 * model_error(data, result, p_true, Q_test)
    entry["validation_rms_mm"] = 1e3 * result.validation.rms_geometric
    # per-parameter errors mean something only when the engine kept the same parameters
    if tuple(result.identifiability.identifiable) == tuple(identifiable):
        lengths, angles = [], []
        for name in identifiable:
            if name in registry:
                error = result.parameter(name).estimate - p_true[registry.index(name)]
                (lengths if registry.quantity(name) == "length" else angles).append(error)
        entry["parameter_error_mm"] = 1e3 * float(np.sqrt(np.mean(np.square(lengths))))
        entry["parameter_error_mrad"] = 1e3 * float(np.sqrt(np.mean(np.square(angles))))
    return entry


def median_of(entries):
    keys = set.intersection(*(set(e) for e in entries))
    return {k: float(np.median([e[k] for e in entries])) for k in sorted(keys)}


def case(path: Path, counts, repeats: int, seed: int = 0) -> dict:
    dataset = load_dataset(path, require_data=False)
    kind = dataset.kind
    rng = np.random.default_rng(seed)
    # random plans are drawn from what the planner may use: its joint ranges, clear of
    # the table, of the arm itself and of the line of sight
    setup, kinematics, workspace = runnable_setup(setup_from_dataset(dataset))
    big = 60 if kind == "cross_bar" else 400
    pool = generate(setup, workspace, big + 40 * repeats, rng)
    first = design_plan(dataset, counts[-1], seed=seed, refine=False, quiet=True)
    identifiable = first.identifiable
    robot_errors = {}
    registry = Kinematics(dataset.robot).registry
    for name in identifiable:
        if name in registry:
            std = LENGTH_ERROR if registry.quantity(name) == "length" else ANGLE_ERROR
            robot_errors[name] = float(rng.normal(0, std))
    p_true, _ = true_parameters(dataset.robot, robot_errors, rng)
    simulator = Simulator(dataset, p_true, rng)
    validation_size = 25 if kind == "cross_bar" else 100
    validation = simulator.dataset_of(pool[:validation_size])
    Q_test = workspace.random_joints(rng, 500)
    rest = pool[validation_size:]
    rows = []
    for count in counts:
        row = {"count": count}
        for index in INDICES:
            started = time.perf_counter()
            plan = design_plan(dataset, count, index, seed=seed + count, quiet=True)
            seconds = time.perf_counter() - started
            # the same plan measured several times: the median over noise realisations
            designed = median_of([evaluate(simulator, plan.candidates, validation, identifiable,
                                           p_true, Q_test) for _ in range(repeats)])
            designed.update(index_value=plan.value, random_median_index_value=plan.random_median,
                            refined=plan.refined, design_seconds=seconds,
                            # the planner's own prediction at the benchmark's noise: the
                            # plan, random plans from its pool, and the least any choice
                            # from that pool could reach (planning.approximate)
                            predicted_tool_error_mm=1e3 * plan.tool_error / plan.setup.noise
                            * NOISE,
                            predicted_random_median_mm=1e3 * plan.random_tool_median
                            / plan.setup.noise * NOISE,
                            predicted_bound_mm=1e3 * plan.tool_error_bound / plan.setup.noise
                            * NOISE)
            row[f"designed_{index}"] = designed
        random = []
        for _ in range(repeats):
            chosen = rng.choice(len(rest), size=count, replace=False)
            random.append(evaluate(simulator, [rest[i] for i in chosen], validation,
                                   identifiable, p_true, Q_test))
        row["random_median"] = median_of(random)
        row["condition_ratio"] = (row["designed_cond"]["condition_number"]
                                  / row["random_median"]["condition_number"])
        # the accuracy margin over random plans: 1 - designed / random model error
        row["model_error_margin"] = {
            index: 1.0 - row[f"designed_{index}"]["model_error_mm"]
            / row["random_median"]["model_error_mm"] for index in INDICES}
        # the same margin predicted, and the largest any choice from the pool could have
        tool = row["designed_tool"]
        row["predicted_margin"] = 1.0 - (tool["predicted_tool_error_mm"]
                                         / tool["predicted_random_median_mm"])
        row["attainable_margin"] = 1.0 - (tool["predicted_bound_mm"]
                                          / tool["predicted_random_median_mm"])
        rows.append(row)
    target = TARGET[kind]

    def fewest(key):
        for row in rows:
            if row[key]["model_error_mm"] <= 1e3 * target:
                return row["count"]
        return None

    return {"kind": kind, "robot": dataset.robot.name, "identifiable": len(identifiable),
            "noise_mm": 1e3 * NOISE, "target_model_error_mm": 1e3 * target,
            **{f"poses_needed_designed_{i}": fewest(f"designed_{i}") for i in INDICES},
            "poses_needed_random_median": fewest("random_median"),
            "random_plans_per_size": repeats, "noise_realisations_per_design": repeats,
            "sizes": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="6R only, fewer sizes")
    parser.add_argument("--set-up", action="append", dest="set_ups", metavar="NAME",
                        help="only this set-up, e.g. industrial_6r/cross_bar (repeatable)")
    args = parser.parse_args()
    counts = {"tracker_points": [12, 16, 24, 36], "cross_bar": [10, 14, 20, 28]}
    repeats = 5
    with tempfile.TemporaryDirectory() as folder:
        paths = setups(Path(folder))
        results = []
        for name, path in paths.items():
            if args.quick and not name.startswith("industrial_6r"):
                continue
            if args.set_ups and name not in args.set_ups:
                continue
            kind = name.split("/")[1]
            sizes = counts[kind][1:3] if args.quick else counts[kind]
            started = time.perf_counter()
            results.append(case(path, sizes, 3 if args.quick else repeats))
            results[-1]["seconds"] = time.perf_counter() - started
            # progress on stderr: a long run shows each set-up as it ends
            print(json.dumps({name: {r["count"]: r["model_error_margin"] | {
                "condition_ratio": r["condition_ratio"], "predicted": r["predicted_margin"],
                "attainable": r["attainable_margin"]} for r in results[-1]["sizes"]}}),
                file=sys.stderr, flush=True)
    print(json.dumps({"benchmark": "planning", "cases": results}, indent=2))


if __name__ == "__main__":
    main()
