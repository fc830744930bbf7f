"""The goal pose of one tracking cycle: the method's chain of frames (docs/methods.md#tracking).

A camera fixed on the end frame (the robot's tool frame, the flange when the robot file
has no tool) at ``camera_xyz = (a, b, c)`` [m], axes parallel to the end frame, sees the
target at ``(x, y, z)`` [m] with its own ``roll, pitch, yaw`` [rad]. Then

* ``B = Trans(a+x, b+y, c+z) R_B`` is the target frame in the end frame, with the fixed
  rotation ``R_B = Rx(90 deg) Rz(90 deg)`` (the end frame turned 90 deg about x, then
  90 deg about the new z);
* ``C = rpy(roll, pitch, yaw) = Rz(yaw) Ry(pitch) Rx(roll)`` is the target's own
  orientation;
* ``T_world_target = A B C`` with ``A = T_world_end`` at the capture joints;
* the goal end pose ``A'`` satisfies ``T_world_target = A' B' C'`` with
  ``B' = Tz(Z) R_B`` (the target at the standoff ``Z`` [m] on the end frame's z axis) and
  ``C' = I``, so ``A' = T_world_target (B' C')^-1``;
* ``A''`` is ``A'`` turned about its own z axis so that its x axis is perpendicular to
  ``up`` (the worktable normal, world frame). Of the two such turns the smaller one is
  taken (``|angle| <= 90 deg``); when the z axis is parallel to ``up`` every turn is level
  and ``A''`` is ``A'``.

The functions work on numpy arrays and on CasADi symbols alike, so the chain is written
once: ``tracking.problem`` builds it into a CasADi function for the real-time loop.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..model.transforms import pose_from_xyz_rpy, rot_x, rot_z, rpy_from_matrix, translation

#: Fixed rotation of the target frame in the end frame: ``Rx(90 deg) Rz(90 deg)`` (4x4).
R_B = rot_x(math.pi / 2) @ rot_z(math.pi / 2)

#: Below this ``|up x z|`` the end frame's z axis counts as parallel to ``up``: no turn.
PARALLEL_TOLERANCE = 1e-12


def _is_symbolic(*values) -> bool:
    return any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in values)


def target_in_end(camera_xyz, observation):
    """``B C``: the target frame in the end frame (4x4) [m].

    ``camera_xyz`` (3,) [m] is the camera origin in the end frame; ``observation`` is
    ``(x, y, z, roll, pitch, yaw)``, the target position in the camera [m] and its
    orientation [rad].
    """
    a, b, c = camera_xyz[0], camera_xyz[1], camera_xyz[2]
    x, y, z = observation[0], observation[1], observation[2]
    B = translation(a + x, b + y, c + z) @ R_B
    C = pose_from_xyz_rpy([0.0, 0.0, 0.0], [observation[3], observation[4], observation[5]])
    return B @ C


def target_in_world(T_world_end, camera_xyz, observation):
    """``T = A B C``: the target frame in the world (4x4) [m] from the capture end pose ``A``."""
    return T_world_end @ target_in_end(camera_xyz, observation)


def facing_pose(T_world_target, standoff):
    """``A' = T (B' C')^-1`` with ``B' = Tz(Z) R_B``, ``C' = I``: the end pose that faces the
    target from the standoff ``Z`` [m] (target at ``(0, 0, Z)`` in it), before levelling."""
    # (Tz(Z) R_B)^-1 = R_B^T Tz(-Z); R_B is a pure rotation.
    return T_world_target @ R_B.T @ translation(0.0, 0.0, -standoff)


def level_turn(T_world_end, up):
    """``T_world_end Rz(phi)``: the smallest turn about the frame's own z axis after which
    its x axis is perpendicular to ``up`` (unit vector, world frame).

    With ``u_x = up . x`` and ``u_y = up . y``, the new x axis ``cos(phi) x + sin(phi) y``
    is level when ``(cos(phi), sin(phi)) = +-(u_y, -u_x) / hypot(u_x, u_y)``; the sign
    with ``cos(phi) >= 0`` is the smaller turn.
    """
    x_axis, y_axis = T_world_end[:3, 0], T_world_end[:3, 1]
    if _is_symbolic(T_world_end, up):
        u_x = ca.dot(up, x_axis)
        u_y = ca.dot(up, y_axis)
        h = ca.sqrt(u_x**2 + u_y**2)
        sign = ca.if_else(u_y >= 0, 1.0, -1.0)
        safe = ca.if_else(h > PARALLEL_TOLERANCE, h, 1.0)
        cosine = ca.if_else(h > PARALLEL_TOLERANCE, sign * u_y / safe, 1.0)
        sine = ca.if_else(h > PARALLEL_TOLERANCE, -sign * u_x / safe, 0.0)
        turn = ca.vertcat(ca.horzcat(cosine, -sine, 0, 0), ca.horzcat(sine, cosine, 0, 0),
                          ca.horzcat(0, 0, 1, 0), ca.horzcat(0, 0, 0, 1))
        return T_world_end @ turn
    up = np.asarray(up, dtype=float)
    u_x, u_y = float(up @ x_axis), float(up @ y_axis)
    h = math.hypot(u_x, u_y)
    if h <= PARALLEL_TOLERANCE:
        return np.array(T_world_end, dtype=float)
    sign = 1.0 if u_y >= 0 else -1.0
    return T_world_end @ rot_z(math.atan2(-sign * u_x, sign * u_y))


def goal_pose(T_world_end, camera_xyz, observation, standoff, up):
    """``A''``: the levelled goal end pose (4x4, world frame) [m] for one observation.

    ``T_world_end`` is the end pose at the capture joints, ``camera_xyz`` [m],
    ``observation = (x, y, z [m], roll, pitch, yaw [rad])``, ``standoff`` Z [m], ``up`` the
    unit worktable normal in the world frame.
    """
    target = target_in_world(T_world_end, camera_xyz, observation)
    return level_turn(facing_pose(target, standoff), up)


def observation_for(T_world_end, T_world_end_goal, camera_xyz, standoff) -> np.ndarray:
    """The inverse of the chain: the observation ``(x, y, z [m], roll, pitch, yaw [rad])``
    seen from the end pose ``T_world_end`` whose facing pose ``A'`` is ``T_world_end_goal``
    (the target at ``T = A' Tz(Z) R_B``). For simulations and benchmarks (numpy only)."""
    T_world_target = T_world_end_goal @ translation(0.0, 0.0, standoff) @ R_B
    B_C = np.linalg.solve(T_world_end, T_world_target)
    xyz = B_C[:3, 3] - np.asarray(camera_xyz, dtype=float)
    return np.concatenate([xyz, rpy_from_matrix(R_B[:3, :3].T @ B_C[:3, :3])])
