"""Compensation: the joint commands that put a (calibrated) robot's tool on Cartesian targets.

The controller's own model is nominal; a calibration knows better. For each target the
joints are solved with the calibrated model (inverse kinematics, ``ik``), so that the
real robot, commanded with them, lands on the target. By default only the geometry is
used; given the calibration's effects (``effect_model.EffectModel``: compliance under the
payload, periodic joint errors, gear-ratio errors, thermal drift), the geometric solution is refined
until the geometry *with* the effects reaches the target (Gauss-Newton on the tool pose
with the effects, ``_with_effects``), to ``EFFECT_TOLERANCE``.

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
EFFECT_TOLERANCE = 1e-11  # [m], [rad]: what the refinement may leave of the target
EFFECT_ROUNDS = 20
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
               seed: int = 0, effects=None, extras: dict | None = None) -> Compensation:
    """Joints that put ``robot``'s tool on each target (see the module docstring).

    ``targets`` (N, 3) positions or (N, 7) poses, SI, world frame. ``start`` (dof,) the
    first solve's seed [rad or m] (default: the middle of the limits). ``restarts``
    random seeds (within the limits, from ``seed``) per target before it counts as
    unreachable. ``effects`` (an ``EffectModel`` of ``robot``) and ``extras`` (its per-row
    values, ``EffectModel.columns``) make the joints land with the effects applied; the
    errors reported are then those of the tool with the effects.
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
    if effects is not None and effects.effects:
        batch = _with_effects(kinematics, effects, extras or {}, targets, batch)
    joints = np.where(batch.success[:, None], batch.q, np.nan)
    status = tuple(STATUS_OK if s else STATUS_UNREACHABLE for s in batch.success)
    return Compensation(joints, status, batch.position_error, batch.orientation_error)


def _rows_of(extras: dict, rows: np.ndarray, count: int) -> dict:
    return {k: (np.asarray(v)[rows] if np.ndim(v) and len(v) == count else v)
            for k, v in extras.items()}


def _with_effects(kinematics: Kinematics, effects, extras: dict, targets: np.ndarray, batch):
    """Refine the solved joints until the tool *with* the effects is on the targets:
    Gauss-Newton steps ``dq = J^+ e`` with the geometric Jacobian ``J`` (the effects
    change it by a negligible fraction) and ``e`` the remaining error of the tool with the
    effects (position, and rotation vector for pose targets; world frame), the minimum-norm
    step, so a position-only target keeps the orientation it was solved with."""
    from dataclasses import replace

    count = len(targets)
    poses = target_poses(targets) if targets.shape[1] == 7 else None
    Q = batch.q.copy()
    success = batch.success.copy()
    position_error = np.asarray(batch.position_error, dtype=float).copy()
    orientation_error = np.asarray(batch.orientation_error, dtype=float).copy()
    lower, upper = kinematics.robot.lower_limits, kinematics.robot.upper_limits
    rows = np.flatnonzero(success)
    for _ in range(EFFECT_ROUNDS):
        if rows.size == 0:
            break
        if any(c.startswith(("direction_q", "travel_q")) for c in effects.columns()):
            # backlash: the directions of motion along the whole path of solutions
            from .effects.motion import with_directions

            T = effects.tool_poses(Q[rows], _rows_of(with_directions(Q, extras), rows, count))
        else:
            T = effects.tool_poses(Q[rows], _rows_of(extras, rows, count))
        if poses is None:
            error = targets[rows, :3] - T[:, :3, 3]
        else:
            goal = poses[rows]
            error = np.column_stack([goal[:, :3, 3] - T[:, :3, 3],
                                     [_rotation_vector(G[:3, :3] @ E[:3, :3].T)
                                      for G, E in zip(goal, T)]])
            orientation_error[rows] = np.linalg.norm(error[:, 3:], axis=1)
        position_error[rows] = np.linalg.norm(error[:, :3], axis=1)
        miss = np.max(np.abs(error), axis=1)
        active = miss > EFFECT_TOLERANCE
        rows, error = rows[active], error[active]
        for row, e in zip(rows, error):
            J = np.asarray(kinematics.tool_jacobian(Q[row], kinematics.nominal))
            J = J[:3] if poses is None else J
            Q[row] = np.clip(Q[row] + np.linalg.pinv(J) @ e, lower, upper)
    # what is still off by more than the solver's own tolerances did not converge
    bad = position_error > 1e-6
    if poses is not None:
        bad |= orientation_error > 1e-6
    success &= ~bad
    return replace(batch, q=Q, success=success, position_error=position_error,
                   orientation_error=orientation_error)


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """Axis times angle [rad] of the rotation ``R`` (small angles exact to first order)."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    sine = np.linalg.norm(skew)
    if sine < 1e-12:
        return skew
    return skew / sine * np.arctan2(sine, (np.trace(R) - 1) / 2)


def _angle(R: np.ndarray) -> float:
    """Rotation angle [rad] of ``R``, accurate near zero (from its skew part)."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.arctan2(np.linalg.norm(skew) / 2, (np.trace(R) - 1) / 2))


def _pose_error(T: np.ndarray, G: np.ndarray) -> float:
    return max(float(np.linalg.norm(T[:3, 3] - G[:3, 3])), _angle(T[:3, :3].T @ G[:3, :3]))
