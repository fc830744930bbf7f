"""The robot a calibration folder delivers (and the nominal one it started from), and tool
poses written in a robot file's units.

``robocal fk``, ``track`` and ``compensate`` and the Python front door
(``robocal_casadi.fk`` ...) read a calibration the same way: ``DIR/robot_calibrated.yaml``,
checked to have the nominal robot's joints and expressed in the nominal robot file's
units, so that the caller's joint readings and poses keep the units they were written in.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..common.fields import read_text
from ..errors import InputError
from .kinematics import Kinematics
from .robot import Robot, load_robot
from .transforms import quaternion_from_matrix

CALIBRATED_ROBOT = "robot_calibrated.yaml"
RESULT = "result.json"
POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")


def calibrated_robot(folder: str | Path, nominal: Robot,
                     nominal_path: str | Path | None = None) -> Robot:
    """The calibrated robot of result folder ``folder``, in ``nominal``'s units.

    Its joint types must match ``nominal``'s (the robot file ``nominal_path``, named in
    the message); a missing folder or file is an ``InputError`` naming ``--calibrated``.
    """
    folder = Path(folder)
    path = folder / CALIBRATED_ROBOT
    if not folder.is_dir():
        raise InputError("calibration folder not found", file=folder, where="--calibrated")
    if not path.is_file():
        raise InputError(f"no {CALIBRATED_ROBOT} in the calibration folder", file=folder,
                         where="--calibrated")
    robot = load_robot(path)
    if [j.type for j in robot.joints] != [j.type for j in nominal.joints]:
        named = f"{Path(nominal_path).name}'s" if nominal_path is not None else "the robot's"
        raise InputError(
            f"joints {[j.type for j in robot.joints]} do not match {named} "
            f"{[j.type for j in nominal.joints]}", file=path, where="joints")
    return robot.with_units(nominal.units)


def nominal_of(calibrated: Robot, folder: str | Path) -> Robot:
    """The robot the calibration started from: ``calibrated`` with every parameter at the
    ``nominal`` value result.json lists (robot file units)."""
    path = Path(folder) / RESULT
    try:
        content = json.loads(read_text(path, what="result file"))
        rows = {row["name"]: float(row["nominal"]) for row in content["parameters"]}
    except (ValueError, KeyError, TypeError):
        raise InputError("not a result.json of robocal calibrate (no parameters with "
                         "nominal values)", file=path, where="parameters") from None
    registry = calibrated.parameters()
    values = calibrated.parameter_vector()
    for i, name in enumerate(registry.names):
        if name in rows:
            values[i] = rows[name] * calibrated.units.scale(registry.quantity(name))
    return calibrated.with_parameters(values)


def pose_rows(poses: np.ndarray, robot: Robot) -> np.ndarray:
    """Rows ``x, y, z, qw, qx, qy, qz`` (N x 7) of world poses ``poses`` (N x 4 x 4) [m]:
    positions in ``robot``'s file length unit, unit quaternions with ``qw >= 0``."""
    rows = np.empty((len(poses), 7))
    rows[:, :3] = poses[:, :3, 3] / robot.units.length_scale
    rows[:, 3:] = [quaternion_from_matrix(T[:3, :3]) for T in poses]
    return rows


def tool_pose_rows(robot: Robot, Q: np.ndarray) -> np.ndarray:
    """Rows ``x, y, z, qw, qx, qy, qz`` (N x 7), robot file units, world frame, of the tool
    at joint readings ``Q`` (N x dof) [rad or m]."""
    return pose_rows(Kinematics(robot).tool_poses(Q), robot)
