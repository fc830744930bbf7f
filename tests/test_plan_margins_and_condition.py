"""Plans keep away from the joint limits, and the condition index is judged on the
measure the summary reports: the condition number over every parameter that is not
exactly unidentifiable, which must not lose to random plans of the same size."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from planning.design import design_plan
from planning.information import exact_condition
from planning.rows import RowModel
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.robot import save_robot

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"


def _tracker(folder: Path, robot_file: str) -> Path:
    (folder / "t.yaml").write_text(yaml.safe_dump(dict(
        kind="tracker_points", robot=robot_file, units=dict(length="mm", angle="deg"),
        target=dict(xyz=[0, 0, 100]), instrument=dict(xyz=[2500, 0, 800]), data="t.csv")))
    return folder / "t.yaml"


def test_planned_poses_keep_a_margin_from_every_limit(tmp_path):
    """Refined poses stay 5% of the range (at most 5 deg) inside the file's limits."""
    robot = industrial_6r()
    save_robot(robot, tmp_path / "r6.yaml")
    dataset = load_dataset(_tracker(tmp_path, "r6.yaml"), require_data=False)
    plan = design_plan(dataset, 16, seed=4, pool=60, refine=True, refine_rounds=1, quiet=True)
    lower, upper = dataset.robot.lower_limits, dataset.robot.upper_limits
    margin = np.minimum(0.05 * (upper - lower), math.radians(5.0))
    Q = plan.joints
    assert np.all(Q >= lower + margin - 1e-9) and np.all(Q <= upper - margin + 1e-9)


def test_condition_index_does_not_lose_to_random_plans_on_the_reported_measure(tmp_path):
    """A UR10 whose wrist barely moves (joint 5 within 85..95 deg, joint 6 within +-5 deg)
    leaves some parameters weak but not exactly unidentifiable: the plan chosen for the
    condition number must be judged, and win, with them."""
    content = yaml.safe_load(UR10.read_text())
    content["joints"][4]["limits"] = [85, 95]
    content["joints"][5]["limits"] = [-5, 5]
    (tmp_path / "ur.yaml").write_text(yaml.safe_dump(content))
    dataset = load_dataset(_tracker(tmp_path, "ur.yaml"), require_data=False)
    plan = design_plan(dataset, 24, "cond", seed=1, pool=100, refine=False, quiet=True)
    # the reported condition number, recomputed from the plan's own rows
    rows = RowModel(plan.setup, Kinematics(plan.setup.robot))
    reported = exact_condition(rows.blocks(list(plan.candidates)), rows.parameters, rows.shared)
    assert plan.condition_all == pytest.approx(reported, rel=1e-9)
    assert plan.value == pytest.approx(reported, rel=1e-6)  # its own measure is that one
    assert len(plan.random_conditions_all) == len(plan.random_values)
    assert plan.condition_all < np.median(plan.random_conditions_all)
    assert "random median" in plan.summary().splitlines()[3]
