"""Gravity torques from pinocchio against a direct static computation on our FK frames.

Holding torque at joint j: ``tau_j = -z_j . sum_k (p_com_k - o_j) x (m_k g)`` over the links
k >= j (revolute, axis z_j through o_j), ``tau_j = -z_j . sum_k m_k g`` (prismatic), where
the sum includes the payload. ``z_j``/``o_j`` come from ``Kinematics.joint_frames``: the
frame before joint j (standard DH), or that frame moved by ``Rx(alpha_j) Tx(a_j)``
(modified DH).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from robocal_casadi.model import examples
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import gravity_torques
from robocal_casadi.model.robot import Frame, Joint, Robot


def axis_frame(robot, joint_index: int, frame_before: np.ndarray) -> np.ndarray:
    """The frame whose z axis is joint ``joint_index``'s axis (0-based), world coordinates."""
    if robot.convention == "dh":
        return frame_before
    joint = robot.joints[joint_index]
    c, s = np.cos(joint.alpha), np.sin(joint.alpha)
    A = np.array([[1, 0, 0, joint.a], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])
    return frame_before @ A


def static_torques(robot, q, payload_mass=0.0, payload_com=(0.0, 0.0, 0.0)) -> np.ndarray:
    kinematics = Kinematics(robot)
    frames = [np.asarray(T) for T in kinematics.joint_frames(q, kinematics.nominal)]
    g = np.asarray(robot.gravity)
    masses = []  # (mass [kg], world position [m], index of the last joint that moves it)
    for k, joint in enumerate(robot.joints):
        if joint.mass is not None:
            com = np.zeros(3) if joint.com is None else np.asarray(joint.com)
            masses.append((joint.mass, frames[k + 1][:3, :3] @ com + frames[k + 1][:3, 3], k))
    flange = frames[-1]
    masses.append((payload_mass, flange[:3, :3] @ np.asarray(payload_com) + flange[:3, 3],
                   robot.dof - 1))
    torques = np.zeros(robot.dof)
    for j, joint in enumerate(robot.joints):
        A = axis_frame(robot, j, frames[j])
        z, origin = A[:3, 2], A[:3, 3]
        for mass, position, last in masses:
            if last < j:
                continue
            force = mass * g
            if joint.revolute:
                torques[j] -= z @ np.cross(position - origin, force)
            else:
                torques[j] -= z @ force
    return torques


def with_beta_and_tilted_gravity(robot):
    """Beta on every joint and gravity of a wall-mounted arm, to exercise both paths."""
    joints = tuple(replace(j, beta=0.01 * (i + 1)) for i, j in enumerate(robot.joints))
    return replace(robot, joints=joints, gravity=(1.2, 9.6, -1.5))


ROBOTS = [examples.industrial_6r(), examples.ur_type(), examples.panda_7dof(),
          examples.prismatic_rrp(), with_beta_and_tilted_gravity(examples.panda_7dof()),
          with_beta_and_tilted_gravity(examples.prismatic_rrp())]
IDS = ["industrial_6r", "ur_type", "panda_7dof", "prismatic_rrp", "panda_beta_wall",
       "rrp_beta_wall"]


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_gravity_torques_match_static_computation(robot, samples):
    Q = samples(robot, count=10, seed=7)
    torques = gravity_torques(robot, Q)
    assert torques.shape == Q.shape
    expected = np.array([static_torques(robot, q) for q in Q])
    assert np.abs(expected).max() > 1.0  # the check is not trivially zero
    np.testing.assert_allclose(torques, expected, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_gravity_torques_with_payload(robot, samples):
    Q = samples(robot, count=6, seed=8)
    masses = np.linspace(0.5, 12.0, len(Q))
    com = (0.03, -0.02, 0.11)
    torques = gravity_torques(robot, Q, payload_mass=masses, payload_com=com)
    expected = np.array([static_torques(robot, q, m, com) for q, m in zip(Q, masses)])
    np.testing.assert_allclose(torques, expected, rtol=1e-12, atol=1e-10)
    at_flange = gravity_torques(robot, Q, payload_mass=3.0)
    expected = np.array([static_torques(robot, q, 3.0) for q in Q])
    np.testing.assert_allclose(at_flange, expected, rtol=1e-12, atol=1e-10)


def test_payload_alone_on_a_massless_arm():
    """Without link masses only the payload counts: a 2 kg mass 1 m out on a flat arm."""
    robot = examples.panda_7dof()
    robot = replace(robot, joints=tuple(replace(j, mass=None, com=None) for j in robot.joints))
    Q = np.array([[0.2, -0.4, 0.1, -1.9, 0.3, 1.4, -0.6]])
    np.testing.assert_array_equal(gravity_torques(robot, Q), 0.0)
    np.testing.assert_allclose(gravity_torques(robot, Q, 2.0, (0.0, 0.0, 0.05)),
                               [static_torques(robot, Q[0], 2.0, (0.0, 0.0, 0.05))],
                               rtol=1e-12, atol=1e-12)


def test_horizontal_lever_closed_form():
    """A single revolute link lying along world x: tau = m g L (closed form)."""
    robot = Robot("lever", "dh", (Joint("revolute", 0.0, 0.0, 0.8, -np.pi / 2, mass=3.0,
                                        com=(-0.3, 0.0, 0.0)),),
                  base=Frame((0, 0, 0), (np.pi / 2, 0, 0)))
    # Base rotated so joint 1's axis is world -y; the link points along world x, so
    # holding it up takes a positive torque about -y.
    torque = gravity_torques(robot, [[0.0]], payload_mass=1.5)[0, 0]
    lever_com, lever_payload = 0.8 - 0.3, 0.8
    assert torque == pytest.approx(9.81 * (3.0 * lever_com + 1.5 * lever_payload), abs=1e-12)
    assert torque == pytest.approx(static_torques(robot, [0.0], 1.5)[0], abs=1e-12)
