"""Compensation: the joint commands that put a (calibrated) robot's tool on Cartesian targets.

The controller's own model is nominal; a calibration knows better. For each target the
joints are solved with the calibrated model (inverse kinematics, ``ik``), so that the
real robot, commanded with them, lands on the target. Only the geometry is used: joint
effects a calibration may have added (compliance, cyclic errors, thermal drift) are not
inverted here.

A target is a tool position ``x, y, z`` [m] (world frame), optionally with the tool
orientation ``qw, qx, qy, qz``. Position-only targets leave the orientation free and
each solve starts from the previous solution (smooth motion along a path).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import count
from .errors import InputError
from .ik import inverse_kinematics
from .kinematics import Kinematics
from .robot import Robot
from .transforms import matrix_from_quaternion

STATUS_OK = "ok"
STATUS_UNREACHABLE = "unreachable"


@dataclass(frozen=True)
class Compensation:
    """Joint commands per target.

    ``joints`` (N, dof) [rad or m], NaN where the status is ``unreachable``; ``status``
    ``ok`` or ``unreachable``; ``position_error`` [m] of the tool at the solution (the best
    found where unreachable); ``orientation_error`` [rad] (NaN for position-only targets).
    """

    joints: np.ndarray
    status: tuple[str, ...]
    position_error: np.ndarray
    orientation_error: np.ndarray

    def __len__(self) -> int:
        return len(self.status)

    def __repr__(self) -> str:
        ok = sum(s == STATUS_OK for s in self.status)
        return f"Compensation({len(self)} targets, {ok} ok, {len(self) - ok} unreachable)"


def target_poses(targets: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses [m] from rows ``x, y, z, qw, qx, qy, qz`` (unit quaternions)."""
    targets = np.asarray(targets, dtype=float)
    poses = np.tile(np.eye(4), (len(targets), 1, 1))
    poses[:, :3, 3] = targets[:, :3]
    for i, quaternion in enumerate(targets[:, 3:7]):
        poses[i, :3, :3] = matrix_from_quaternion(quaternion / np.linalg.norm(quaternion))
    return poses


def compensate(robot: Robot, targets, *, start=None, restarts: int = 10,
               seed: int = 0) -> Compensation:
    """Joints that put ``robot``'s tool on each target (see the module docstring).

    ``targets`` (N, 3) positions or (N, 7) poses, SI, world frame. ``start`` (dof,) the
    first solve's seed [rad or m] (default: the middle of the limits). ``restarts``
    random seeds (within the limits, from ``seed``) per target before it counts as
    unreachable.
    """
    restarts = count(restarts, "restarts", minimum=0)
    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    if targets.ndim != 2 or targets.shape[1] not in (3, 7):
        raise InputError(f"targets need 3 (x, y, z) or 7 (x, y, z, qw, qx, qy, qz) columns, "
                         f"got {targets.shape[1]}")
    kinematics = Kinematics(robot)
    rng = np.random.default_rng(seed)
    if targets.shape[1] == 7:
        batch = inverse_kinematics(kinematics, "pose").solve_batch(
            target_poses(targets), seeds=start, restarts=restarts, rng=rng)
    else:
        batch = inverse_kinematics(kinematics, "point").solve_batch(
            targets, seeds=start, offset=np.asarray(robot.tool.xyz), restarts=restarts, rng=rng)
    joints = np.where(batch.success[:, None], batch.q, np.nan)
    status = tuple(STATUS_OK if s else STATUS_UNREACHABLE for s in batch.success)
    return Compensation(joints, status, batch.position_error, batch.orientation_error)
