"""Symbolic gravity torques of a DH robot, from its potential energy.

The generalized gravity torque is the gradient of the potential energy,

    V(q) = - g . ( sum_k m_k c_k(q) + m_payload c_payload(q) )          [J]
    tau_j(q) = dV/dq_j                                                   [Nm] or [N]

with ``g`` the robot's gravity vector [m/s^2] in the world frame, ``c_k`` the world
position [m] of link k's centre of mass (``com`` given in link k's own frame, the frame
after joint k's transform) and the payload a point mass [kg] at ``payload_com`` [m] in
the flange frame. ``tau`` is the torque (force, for a prismatic joint) the motors apply
to hold the arm still; it equals pinocchio's ``computeGeneralizedGravity``.

Where the robot file carries no masses, ``first_moment_basis`` gives the same torque as a
linear combination of known functions of ``q``: per link k, the unknown first moment
``h_k = m_k com_k`` [kg m] (3 numbers, link frame) and mass ``m_k`` [kg] enter
``V = -g . sum_k (R_k h_k + m_k o_k)`` linearly, with ``R_k, o_k`` link k's world frame.

Everything is CasADi (SX or MX) so derivatives are exact; ``GravityModel`` builds the
numeric function once per robot and caches it.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from ..errors import InputError
from ..model.kinematics import symbolic_frames
from ..model.parameters import ParameterRegistry
from ..model.robot import Robot

FIRST_MOMENT_COMPONENTS = ("x", "y", "z", "m")  # h_x, h_y, h_z [kg m] and m [kg] per link


def _require_inertia(robot: Robot) -> list[tuple[float, tuple[float, float, float]]]:
    """Each joint's link ``(mass [kg], com [m])``; an ``InputError`` where one is missing."""
    inertia = [(j.mass, j.com) for j in robot.joints]
    missing = [i for i, (mass, com) in enumerate(inertia, start=1) if mass is None or com is None]
    if missing:
        raise InputError(
            f"robot {robot.name!r} has no mass/com for joint(s) {missing}; the gravity torque "
            "needs both (joint_compliance falls back to lumped first moments without them)",
            where="joints",
        )
    return [(mass, com) for mass, com in inertia if mass is not None and com is not None]


def potential_energy(robot: Robot, registry: ParameterRegistry, q, p, payload=0.0,
                     payload_com=(0.0, 0.0, 0.0)):
    """Potential energy ``V`` [J] of the links and a payload at joint readings ``q``.

    ``p`` geometric parameters (registry order, SI); ``payload`` [kg]; ``payload_com``
    (3,) [m] in the flange frame. Requires ``mass`` and ``com`` on every joint.
    """
    inertia = _require_inertia(robot)
    frames = symbolic_frames(robot, registry, q, p)
    g = ca.DM(robot.gravity)
    weight = 0
    for k, (mass, com) in enumerate(inertia, start=1):
        T = frames[k]
        c = T[:3, :3] @ ca.DM(com) + T[:3, 3]
        weight = weight + mass * c
    flange = frames[robot.dof]
    c_payload = flange[:3, :3] @ ca.vertcat(*[payload_com[i] for i in range(3)]) + flange[:3, 3]
    weight = weight + payload * c_payload
    return -ca.dot(g, weight)


def gravity_torque(robot: Robot, registry: ParameterRegistry, q, p, payload=0.0,
                   payload_com=(0.0, 0.0, 0.0)):
    """Generalized gravity torque ``tau(q)`` (dof,) [Nm, or N for prismatic joints].

    ``q`` must be a CasADi symbol (the gradient is taken with respect to it); see
    ``potential_energy`` for the other arguments.
    """
    V = potential_energy(robot, registry, q, p, payload, payload_com)
    return ca.gradient(V, q)


def payload_torque_per_kg(robot: Robot, registry: ParameterRegistry, q, p,
                          payload_com=(0.0, 0.0, 0.0)):
    """Gravity torque (dof,) of a 1 kg point mass at ``payload_com`` [m] (flange frame).

    Needs no link masses: ``tau_payload = payload * payload_torque_per_kg``.
    """
    frames = symbolic_frames(robot, registry, q, p)
    flange = frames[robot.dof]
    c = flange[:3, :3] @ ca.vertcat(*[payload_com[i] for i in range(3)]) + flange[:3, 3]
    return ca.gradient(-ca.dot(ca.DM(robot.gravity), c), q)


def first_moment_basis(robot: Robot, registry: ParameterRegistry, q, p):
    """Gravity-torque basis (dof x 4 dof) for unknown link masses and centres of mass.

    Column ``4 (k-1) + i`` is ``d/dq`` of ``-g . R_k e_i`` (i = x, y, z) or of
    ``-g . o_k`` (i = m), so that ``tau = basis @ [h_1x, h_1y, h_1z, m_1, h_2x, ...]``
    with ``h_k = m_k com_k`` [kg m] in link k's frame and ``m_k`` [kg].
    """
    frames = symbolic_frames(robot, registry, q, p)
    g = ca.DM(robot.gravity)
    columns = []
    for k in range(1, robot.dof + 1):
        T = frames[k]
        for i in range(3):
            columns.append(ca.gradient(-ca.dot(g, T[:3, i]), q))
        columns.append(ca.gradient(-ca.dot(g, T[:3, 3]), q))
    return ca.horzcat(*columns)


class GravityModel:
    """Numeric gravity torques of one robot, CasADi functions built once.

    ``torques(Q, p=None, payload=None, payload_com=None)`` -> (N x dof) [Nm or N] for
    joint readings ``Q`` (N x dof), geometry ``p`` (default nominal), ``payload`` (N,)
    [kg] and ``payload_com`` (3,) [m] in the flange frame.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.registry = robot.parameters()
        self.nominal = self.registry.vector_of(robot)
        self._maps: dict[int, ca.Function] = {}

    def __repr__(self) -> str:
        return f"GravityModel({self.robot.name!r}, dof={self.robot.dof})"

    @cached_property
    def function(self) -> ca.Function:
        """``(q, p, payload, payload_com) -> tau`` [Nm or N]."""
        q = ca.SX.sym("q", self.robot.dof)
        p = ca.SX.sym("p", len(self.registry))
        payload = ca.SX.sym("payload")
        payload_com = ca.SX.sym("payload_com", 3)
        tau = gravity_torque(self.robot, self.registry, q, p, payload, payload_com)
        return ca.Function("gravity_torque", [q, p, payload, payload_com], [tau],
                           ["q", "p", "payload", "payload_com"], ["tau"])

    def torques(self, Q, p=None, payload=None, payload_com=None) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        n = len(Q)
        if n not in self._maps:
            self._maps[n] = self.function.map(n, "serial") if n > 1 else self.function
        p = self.nominal if p is None else np.asarray(p, dtype=float)
        payload = np.zeros(n) if payload is None else np.broadcast_to(
            np.asarray(payload, dtype=float), (n,))
        com = np.zeros(3) if payload_com is None else np.asarray(payload_com, dtype=float)
        out = self._maps[n](Q.T, p, payload[None, :], com)
        return np.asarray(out).T.reshape(n, self.robot.dof)
