"""Shared fixtures: the example robots, the real robot files, and joint samples."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.model import examples
from robocal_casadi.model.robot import Robot, load_robot

REPOSITORY = Path(__file__).resolve().parents[1]


def real_data_folder() -> Path:
    """The real data sets: ``$ROBOCAL_DATA`` if set, else the copies shipped in the
    package (``robocal_casadi/data``)."""
    if os.environ.get("ROBOCAL_DATA"):
        return Path(os.environ["ROBOCAL_DATA"])
    return REPOSITORY / "robocal_casadi" / "data"


DATA = real_data_folder()
REAL_ROBOT_FILES = sorted(DATA.glob("*/robot.yaml")) if DATA.is_dir() else []
ROBOT_IDS = list(examples.ROBOTS) + [f"file:{p.parent.name}" for p in REAL_ROBOT_FILES]


def robot_by_id(robot_id: str) -> Robot:
    """An example robot by name, or a real robot file as ``file:<folder>``."""
    if robot_id.startswith("file:"):
        return load_robot(DATA / robot_id[5:] / "robot.yaml")
    return examples.ROBOTS[robot_id]()


@pytest.fixture(params=ROBOT_IDS)
def any_robot(request) -> Robot:
    """Each example robot and each real robot file in turn."""
    return robot_by_id(request.param)


def joint_samples(robot: Robot, rng: np.random.Generator, count: int = 20) -> np.ndarray:
    """Joint readings (rows) [rad or m]: uniform within the limits (+-pi or +-0.3 m where
    a joint has none), then near-singular rows: all zero, the wrist aligned (q5 = 0),
    tiny readings (1e-9), and the joint limits themselves."""
    default = np.array([np.pi if j.revolute else 0.3 for j in robot.joints])
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -default)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, default)
    random_rows = rng.uniform(lower, upper, size=(count, robot.dof))
    wrist = random_rows[:3].copy()
    if robot.dof >= 5:
        wrist[:, 4] = 0.0
    tiny = rng.choice([-1.0, 1.0], size=(2, robot.dof)) * 1e-9
    return np.vstack([random_rows, np.zeros((1, robot.dof)), wrist, tiny, lower, upper])


@pytest.fixture
def samples():
    """``samples(robot, count=20, seed=0)`` -> joint readings, see ``joint_samples``."""

    def make(robot: Robot, count: int = 20, seed: int = 0) -> np.ndarray:
        return joint_samples(robot, np.random.default_rng(seed), count)

    return make
