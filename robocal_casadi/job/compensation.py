"""Compensation: the joint commands that put a (calibrated) robot's tool on Cartesian targets.

The controller's own model is nominal; a calibration knows better. For each target the
joints are solved with the calibrated model (inverse kinematics, ``ik``), so that the
real robot, commanded with them, lands on the target. By default only the geometry is
used; given the calibration's effects (``effect_model.EffectModel``: compliance under the
payload, periodic joint errors, gear-ratio errors, thermal drift), the geometric solution is refined
until the geometry *with* the effects reaches the target (Gauss-Newton on the tool pose
with the effects, ``_with_effects``), to ``EFFECT_TOLERANCE``.

A target is a tool position ``x, y, z`` [m] (world frame), optionally with the tool
orientation ``qw, qx, qy, qz``. Every answer keeps the configuration (shoulder, elbow,
wrist branch) of its seed: the joints that reached the target before (a taught program),
or else the nominal model's inverse kinematics of the target, solved along the targets
from the previous solution (smooth motion along a path). The answer is solved from the
seed and accepted when no singularity lies between them
(``configuration.same_configuration``); otherwise the target is approached from the
seed's own pose in small steps, each on the branch of the last (``_walk``); a target
that only another branch reaches is reported (``STATUS_BRANCH``), never switched to.
Position-only targets keep the tool turned as at the seed (a soft preference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..common.checks import count, path_argument
from ..effects.motion import is_derived_column
from ..errors import ArgumentError, InputError
from ..model.configuration import same_configuration
from ..model.ik import IKBatchResult, inverse_kinematics
from ..model.kinematics import Kinematics
from ..model.robot import Robot, load_robot
from ..model.transforms import matrix_from_quaternion

STATUS_OK = "ok"
EFFECT_TOLERANCE = 1e-11  # [m], [rad]: what the refinement may leave of the target
EFFECT_ROUNDS = 20
STATUS_UNREACHABLE = "unreachable"
STATUS_BRANCH = "branch"  # reachable, but only on another branch than the seed's
WALK_LENGTH = 0.01  # [m] largest tool move per step of a walk from the seed's pose
WALK_ANGLE = math.radians(5.0)  # [rad] largest tool turn per step of that walk
WALK_STEPS = 200  # a seed further than this many steps from its target is not walked


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


def compensate(robot: Robot | str | Path, targets, *, start=None, seeds=None,
               nominal: Robot | None = None, restarts: int = 10, seed: int = 0, effects=None,
               extras: dict | None = None) -> Compensation:
    """Joints that put ``robot``'s tool (a ``Robot`` or a robot file) on each target, each
    on the branch of its seed (see the module docstring).

    ``targets`` (N, 3) positions or (N, 7) poses, SI, world frame. ``seeds`` (N, dof)
    [rad or m]: the joints that reached each target before (a taught program), NaN rows
    where none is known; a row without one is seeded with the inverse kinematics of
    ``nominal`` (the robot the controller knows; default ``robot``), solved in order from
    ``start`` (default the middle of the limits) and then from the previous solution, with
    ``restarts`` random starts (within the limits, from ``seed``) per target. A row whose
    seed's branch cannot reach the target gets status ``branch`` and no joints.
    ``effects`` (an ``EffectModel`` of ``robot``) and ``extras`` (its per-row values,
    ``EffectModel.columns``) make the joints land with the effects applied; the errors
    reported are then those of the tool with the effects.
    """
    restarts = count(restarts, "restarts", minimum=0)
    if not isinstance(robot, Robot):
        robot = load_robot(path_argument(robot, "robot", what="a Robot or a robot file"))
    targets = _targets(targets)
    kinematics = Kinematics(robot)
    rng = np.random.default_rng(seed)
    mode = "pose" if targets.shape[1] == 7 else "point"
    goals = target_poses(targets) if mode == "pose" else targets[:, :3]
    solver = inverse_kinematics(kinematics, mode)
    offset: dict[str, Any] = {} if mode == "pose" else {"offset": np.asarray(robot.tool.xyz)}
    seeds = _seeds(seeds, len(targets), robot.dof)
    p_nominal = None if nominal is None else kinematics.registry.vector_of(nominal)
    unseeded = np.flatnonzero(np.isnan(seeds).any(axis=1))
    if unseeded.size:
        first = solver.solve_batch(goals[unseeded], seeds=start, restarts=restarts, rng=rng,
                                   p=p_nominal, **offset)
        seeds[unseeded[first.success]] = first.q[first.success]
    solved = [_on_branch(solver, goals[i], seeds[i], offset, restarts, rng)
              if np.isfinite(seeds[i]).all()
              else _any_branch(solver, goals[i], start, offset, restarts, rng)
              for i in range(len(targets))]
    batch = IKBatchResult(np.array([s[0].q for s in solved]),
                          np.array([s[1] == STATUS_OK for s in solved]),
                          np.array([s[0].position_error for s in solved]),
                          np.array([s[0].orientation_error for s in solved]),
                          np.array([s[0].iterations for s in solved]))
    if effects is not None and effects.effects:
        batch = _with_effects(kinematics, effects, extras or {}, targets, batch)
    statuses = tuple(status if ok or status != STATUS_OK else STATUS_UNREACHABLE
                     for (_, status), ok in zip(solved, batch.success))
    joints = np.where(batch.success[:, None], batch.q, np.nan)
    return Compensation(joints, statuses, batch.position_error, batch.orientation_error)


def _seeds(seeds, rows: int, dof: int) -> np.ndarray:
    """Per-row seeds (rows, dof) [rad or m], NaN rows where none is given."""
    if seeds is None:
        return np.full((rows, dof), np.nan)
    seeds = np.array(seeds, dtype=float)
    if seeds.shape != (rows, dof):
        raise InputError(f"seeds need one row of {dof} joints per target, got shape "
                         f"{seeds.shape} for {rows} targets")
    partial = np.isnan(seeds).any(axis=1) & ~np.isnan(seeds).all(axis=1)
    if partial.any() or np.isinf(seeds).any():
        row = int(np.flatnonzero(partial | np.isinf(seeds).any(axis=1))[0])
        raise InputError(f"seed row {row} is incomplete or infinite: give every joint or none")
    return seeds


def _any_branch(solver, goal, start, offset: dict, restarts: int, rng):
    """A row with no seed at all (the nominal model could not reach it either)."""
    result = solver.solve(goal, seed=start, restarts=restarts, rng=rng, **offset)
    return result, STATUS_OK if result.success else STATUS_UNREACHABLE


def _on_branch(solver, goal, seed: np.ndarray, offset: dict, restarts: int, rng):
    """``(IKResult, status)`` for one target on the branch of ``seed``: a solve from the
    seed, else a walk from the seed's own pose to the goal in small steps, each on the
    branch of the last (``configuration.same_configuration``); ``branch`` when only
    another branch reaches the goal, ``unreachable`` when none does."""
    kinematics = solver.kinematics
    options = dict(offset)
    if solver.mode == "point":  # keep the tool turned as the seed had it
        options["orientation"] = kinematics.flange_poses(seed[None])[0][:3, :3]
    direct = _near(solver.solve(goal, seed=seed, **options), seed, kinematics.robot)
    if direct.success and same_configuration(kinematics, seed, direct.q):
        return direct, STATUS_OK
    walked = _walk(solver, goal, seed, options)
    if walked is not None:
        return walked, STATUS_OK
    anywhere = solver.solve(goal, seed=seed, restarts=restarts, rng=rng, **options)
    return anywhere, STATUS_BRANCH if anywhere.success else STATUS_UNREACHABLE


def _walk(solver, goal, seed: np.ndarray, options: dict):
    """The goal reached from the seed's own tool pose (or point) in steps of at most
    ``WALK_LENGTH`` / ``WALK_ANGLE``, each solved from the last and on its branch; None
    when a step fails or changes branch."""
    kinematics = solver.kinematics
    here = kinematics.tool_poses(seed[None])[0]
    if solver.mode == "point":
        here = here[:3, 3]
        steps = int(np.ceil(np.linalg.norm(goal - here) / WALK_LENGTH))
    else:
        turn = _rotation_vector(here[:3, :3].T @ goal[:3, :3])
        steps = int(np.ceil(max(np.linalg.norm(goal[:3, 3] - here[:3, 3]) / WALK_LENGTH,
                                np.linalg.norm(turn) / WALK_ANGLE)))
    if steps > WALK_STEPS:
        return None
    q, result = seed, None
    for k in range(1, max(steps, 1) + 1):
        s = k / max(steps, 1)
        if solver.mode == "point":
            step_goal = here + s * (goal - here)
        else:
            step_goal = np.eye(4)
            step_goal[:3, :3] = here[:3, :3] @ _rotation_matrix(s * turn)
            step_goal[:3, 3] = here[:3, 3] + s * (goal[:3, 3] - here[:3, 3])
        result = _near(solver.solve(step_goal, seed=q, **options), q, kinematics.robot)
        if not (result.success and same_configuration(kinematics, q, result.q)):
            return None
        q = result.q
    return result


def _near(result, seed: np.ndarray, robot: Robot):
    """``result`` with each revolute joint turned by whole turns to lie nearest ``seed``
    within the limits (the solver may wrap a joint a turn away: the same pose, but a
    program would unwind the joint)."""
    q = np.array(result.q, dtype=float)
    for i, joint in enumerate(robot.joints):
        if not joint.revolute or not np.isfinite(q[i]):
            continue
        turns = q[i] + 2 * math.pi * np.arange(-3, 4)
        inside = turns[(turns >= robot.lower_limits[i]) & (turns <= robot.upper_limits[i])]
        if inside.size:
            q[i] = inside[np.argmin(np.abs(inside - seed[i]))]
    return replace(result, q=q)


def _rotation_matrix(vector: np.ndarray) -> np.ndarray:
    """Rotation [rad] about ``vector``'s direction by its length (Rodrigues)."""
    angle = float(np.linalg.norm(vector))
    if angle < 1e-15:
        return np.eye(3)
    k = vector / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _targets(value) -> np.ndarray:
    """``value`` as finite (N, 3) or (N, 7) float targets, else an ``ArgumentError``."""
    try:
        targets = np.atleast_2d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise ArgumentError(f"expected numbers (N x 3 or N x 7), got a {type(value).__name__}",
                            argument="targets") from None
    if targets.ndim != 2 or targets.shape[1] not in (3, 7) or not targets.size:
        raise ArgumentError(f"targets need 3 (x, y, z) or 7 (x, y, z, qw, qx, qy, qz) columns, "
                            f"got shape {targets.shape}", argument="targets")
    bad = np.flatnonzero(~np.all(np.isfinite(targets), axis=1))
    if bad.size:
        raise ArgumentError(f"row {int(bad[0])} is not finite (NaN or infinity); "
                            f"{bad.size} such row(s)", argument="targets")
    if targets.shape[1] == 7:
        zero = np.flatnonzero(np.linalg.norm(targets[:, 3:], axis=1) == 0)
        if zero.size:
            raise ArgumentError(f"row {int(zero[0])}: the quaternion (qw, qx, qy, qz) is zero",
                                argument="targets")
    return targets


def _rows_of(extras: dict, rows: np.ndarray, count: int) -> dict:
    return {k: (np.asarray(v)[rows] if np.ndim(v) and len(v) == count else v)
            for k, v in extras.items()}


def _with_effects(kinematics: Kinematics, effects, extras: dict, targets: np.ndarray, batch):
    """Refine the solved joints until the tool *with* the effects is on the targets:
    Gauss-Newton steps ``dq = J^+ e`` with the geometric Jacobian ``J`` (the effects
    change it by a negligible fraction) and ``e`` the remaining error of the tool with the
    effects (position, and rotation vector for pose targets; world frame), the minimum-norm
    step, so a position-only target keeps the orientation it was solved with."""

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
        if any(is_derived_column(c) for c in effects.columns()):
            # backlash: the directions of motion along the whole path of solutions
            from ..effects.motion import with_directions

            T = effects.tool_poses(Q[rows], _rows_of(with_directions(Q, extras, effects.robot),
                                                     rows, count))
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
