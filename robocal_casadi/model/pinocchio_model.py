"""The robot as a pinocchio model: the independent reference for kinematics and gravity.

Every DH link transform splits into a fixed part, the joint motion along or about a z
axis, and another fixed part (docs/conventions.md#standard-dh,
docs/conventions.md#modified-dh)::

    standard DH   T(i-1,i) = Jz(q_i) . [Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)]
    modified DH   T(i-1,i) = [Rx(alpha_{i-1}) Tx(a_{i-1})] . Jz(q_i)
                             . [Rz(theta_i) Tz(d_i) Ry(beta_i)]

with ``Jz`` a rotation about z (revolute, the reading adds to theta) or a translation
along z (prismatic, the reading adds to d; ``Tz`` commutes with ``Rz``). Writing
``T(i-1,i) = A_i Jz(q_i) B_i``, pinocchio joint i is placed at ``B_{i-1} A_i`` in joint
i-1's frame (``base A_1`` in the world for joint 1), and operational frames mark the DH
frames: ``frame_0`` (the base, joint-1 frame), ``frame_i = joint_i B_i``, ``flange``
(= ``frame_n``) and ``tool`` (``flange`` then ``tool``).

A ``urdf`` robot's joint ``T(i-1,i) = origin_i Motion(axis_i, q_i)`` splits the same way
with ``A_i = origin_i R_i`` and ``B_i = R_i^T`` (``flange`` appended for the last joint),
where ``R_i`` is a rotation taking z onto ``axis_i``; ``frame_i`` is then URDF link i and
``frame_n`` the tip link.

Link ``i``'s mass sits at its ``com`` given in ``frame_i`` (point masses: gravity needs
no rotational inertia). ``model.gravity`` is the robot's ``gravity`` in the world frame.
Everything is SI: [m], [rad], [kg], [N m].
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pinocchio as pin

from ..common import exact
from ..common.output import atomic_file
from .robot import Robot
from .transforms import product, rot_x, rot_y, rot_z, rpy_from_matrix, translation

LIMITLESS = 1.0e3  # [rad] or [m]: URDF limits written for a joint the robot file leaves unlimited
# URDF requires a joint's effort [N m or N] and velocity [rad/s or m/s] limits, which a robot
# file does not give: these stand-ins constrain nothing (the file says so in a comment).
UNRATED = 1.0e6
# [kg/m^3] aluminium alloy, the usual material of an arm's castings: the density of the solid
# sphere whose rotational inertia stands in for a link's where the robot file gives only a mass.
LINK_DENSITY = 2700.0


def link_parts(robot: Robot) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(A_i, B_i)`` per joint (4x4, [m]) with ``T(i-1,i) = A_i Jz(q_i) B_i``."""
    parts = []
    if robot.convention == "urdf":
        for i, joint in enumerate(robot.joints, start=1):
            R = np.eye(4)
            R[:3, :3] = z_onto(joint.axis)
            B = product(R.T, robot.flange.matrix() if i == robot.dof else np.eye(4))
            parts.append((product(joint.origin.matrix(), R), B))
        return parts
    for joint in robot.joints:
        if robot.convention == "dh":
            A = np.eye(4)
            B = product(rot_z(joint.theta), translation(0, 0, joint.d),
                        translation(joint.a, 0, 0), rot_x(joint.alpha), rot_y(joint.beta))
        else:
            A = product(rot_x(joint.alpha), translation(joint.a, 0, 0))
            B = product(rot_z(joint.theta), translation(0, 0, joint.d), rot_y(joint.beta))
        parts.append((A, B))
    return parts


def z_onto(axis) -> np.ndarray:
    """A rotation (3x3) that takes the z axis onto the unit vector ``axis``."""
    a = np.asarray(axis, dtype=float) / exact.norm(axis)
    v = exact.cross([0.0, 0.0, 1.0], a)
    c = float(a[2])
    if exact.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + exact.matmul(K, K) / (1 + c)


def _se3(T: np.ndarray) -> pin.SE3:
    return pin.SE3(np.array(T[:3, :3]), np.array(T[:3, 3]))


def _point_mass(mass: float, position) -> pin.Inertia:
    return pin.Inertia(float(mass), np.asarray(position, dtype=float), np.zeros((3, 3)))


def pinocchio_model(robot: Robot, *, with_links: bool = True) -> pin.Model:
    """A pinocchio ``Model`` of ``robot`` (see the module docstring for its frames).

    ``with_links=False`` leaves every link massless (used for payload-only models).
    """
    model = pin.Model()
    model.name = robot.name
    model.gravity = pin.Motion(np.asarray(robot.gravity, dtype=float), np.zeros(3))
    base = robot.base.matrix()
    model.addFrame(pin.Frame("frame_0", 0, 0, _se3(base), pin.FrameType.OP_FRAME))
    parts = link_parts(robot)
    parent = 0
    previous_B = base
    for i, (joint, (A, B)) in enumerate(zip(robot.joints, parts), start=1):
        motion = pin.JointModelRZ() if joint.revolute else pin.JointModelPZ()
        lower = joint.limits[0] if joint.limits else -LIMITLESS
        upper = joint.limits[1] if joint.limits else LIMITLESS
        joint_id = model.addJoint(
            parent, motion, _se3(product(previous_B, A)), f"joint_{i}",
            np.array([1e6]), np.array([1e6]), np.array([lower]), np.array([upper]),
        )
        inertia = pin.Inertia.Zero()
        if with_links and joint.mass is not None:
            com = np.zeros(3) if joint.com is None else np.asarray(joint.com, dtype=float)
            inertia = _point_mass(joint.mass, exact.matmul(B[:3, :3], com) + B[:3, 3])
        model.appendBodyToJoint(joint_id, inertia, pin.SE3.Identity())
        model.addFrame(pin.Frame(f"frame_{i}", joint_id, 0, _se3(B), pin.FrameType.OP_FRAME))
        parent = joint_id
        previous_B = B
    model.addFrame(pin.Frame("flange", parent, 0, _se3(previous_B), pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("tool", parent, 0, _se3(product(previous_B, robot.tool.matrix())),
                             pin.FrameType.OP_FRAME))
    return model


def frame_placements(model: pin.Model, q, names) -> np.ndarray:
    """World poses (len(names) x 4 x 4) [m] of the named frames of ``model`` at ``q``."""
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(q, dtype=float))
    out = []
    for name in names:
        frame_id = model.getFrameId(name)
        out.append(pin.updateFramePlacement(model, data, frame_id).homogeneous)
    return np.array(out)


def pinocchio_tool_pose(robot: Robot, q) -> np.ndarray:
    """``T_world_tool`` (4x4, [m]) of ``robot`` at joint readings ``q`` [rad or m], by pinocchio."""
    return frame_placements(pinocchio_model(robot), q, ["tool"])[0]


def pinocchio_joint_frames(robot: Robot, q) -> np.ndarray:
    """``T_world_0 ... T_world_n`` ((n+1) x 4 x 4, [m]) at ``q``, by pinocchio."""
    names = [f"frame_{i}" for i in range(robot.dof + 1)]
    return frame_placements(pinocchio_model(robot), q, names)


def pinocchio_tool_jacobian(robot: Robot, q) -> np.ndarray:
    """Geometric tool Jacobian (6 x dof), world-aligned axes, by pinocchio.

    Rows 0-2: tool-origin velocity [m/s per unit reading]; rows 3-5: angular velocity
    [rad/s per unit reading] (pinocchio ``LOCAL_WORLD_ALIGNED``).
    """
    model = pinocchio_model(robot)
    data = model.createData()
    return pin.computeFrameJacobian(model, data, np.asarray(q, dtype=float),
                                    model.getFrameId("tool"), pin.LOCAL_WORLD_ALIGNED)


def gravity_torques(robot: Robot, Q, payload_mass=0.0, payload_com=None) -> np.ndarray:
    """Joint torques [N m] (forces [N] at prismatic joints) that hold the arm against gravity.

    ``Q`` (N x dof) joint readings [rad or m]. Pinocchio's generalized gravity
    ``g(q) = dV/dq``: the torque the motors apply to hold the arm still. The links carry
    their ``mass`` [kg] at ``com`` (link frame); a joint without inertial data adds
    nothing. ``payload_mass`` [kg] (scalar or one per row) is a point mass at the flange
    origin, or at ``payload_com`` [m] in the flange frame. Gravity is ``robot.gravity``
    [m/s^2], world frame. Returns N x dof.
    """
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    if Q.shape[1] != robot.dof:
        raise ValueError(f"Q has {Q.shape[1]} columns, robot {robot.name!r} has {robot.dof} joints")
    masses = np.broadcast_to(np.asarray(payload_mass, dtype=float), (len(Q),))
    links = pinocchio_model(robot)
    data = links.createData()
    torques = np.array([pin.computeGeneralizedGravity(links, data, q).copy() for q in Q])
    if np.any(masses != 0.0):
        # Gravity torques are linear in the masses: add the unit payload's torques, scaled.
        unit = pinocchio_model(robot, with_links=False)
        B = link_parts(robot)[-1][1]
        offset = np.zeros(3) if payload_com is None else np.asarray(payload_com, dtype=float)
        unit.inertias[robot.dof] = _point_mass(1.0, exact.matmul(B[:3, :3], offset) + B[:3, 3])
        unit_data = unit.createData()
        for k, q in enumerate(Q):
            if masses[k] != 0.0:
                torques[k] += masses[k] * pin.computeGeneralizedGravity(unit, unit_data, q)
    return torques


# ----------------------------------------------------------------------------- URDF export


def _origin(T: np.ndarray) -> str:
    xyz = " ".join(repr(float(v)) for v in T[:3, 3])
    rpy = " ".join(repr(float(v)) for v in rpy_from_matrix(T[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def sphere_moment(mass: float) -> float:
    """[kg m^2] The moment of inertia ``2/5 m r^2`` about any axis through the centre of a
    solid sphere of ``mass`` [kg] and density ``LINK_DENSITY``: a positive-definite tensor
    that satisfies the triangle inequalities, where the robot file gives no inertia."""
    radius = (3.0 * mass / (4.0 * np.pi * LINK_DENSITY)) ** (1.0 / 3.0)
    return 0.4 * mass * radius**2


def urdf_text(robot: Robot) -> str:
    """URDF of ``robot``: DH frames as links, ``A_i`` as joint origins, ``B_i`` as fixed joints.

    Links ``world``, ``frame_0`` (base), ``link_i`` (joint i's moving frame), ``frame_i``
    (DH frame i, carrying the link's ``mass`` at ``com`` as the robot file gives them, with
    the rotational inertia of a solid aluminium sphere of that mass, ``sphere_moment``,
    since the robot file gives none), ``tool``. Lengths [m], angles [rad], masses [kg],
    inertias [kg m^2]. Effort and velocity limits, which URDF requires and the robot file
    does not give, are ``UNRATED`` stand-ins. URDF has no gravity: ``robot.gravity`` is not
    exported.
    """
    lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(robot.name)}>",
             "  <!-- Written by robocal from a robot file. Each link's mass [kg] and centre of "
             "mass are the robot file's; its rotational inertia is that of a solid aluminium "
             f"sphere of the same mass ({LINK_DENSITY:g} kg/m^3), as the robot file gives none. "
             f"Joint effort and velocity limits ({UNRATED:g}) are stand-ins that constrain "
             "nothing: the robot file gives no ratings. -->",
             '  <link name="world"/>', '  <link name="frame_0"/>',
             '  <joint name="base_joint" type="fixed"><parent link="world"/><child link="frame_0"/>'
             f"{_origin(robot.base.matrix())}</joint>"]
    for i, (joint, (A, B)) in enumerate(zip(robot.joints, link_parts(robot)), start=1):
        lower = joint.limits[0] if joint.limits else -LIMITLESS
        upper = joint.limits[1] if joint.limits else LIMITLESS
        lines.append(f'  <link name="link_{i}"/>')
        lines.append(
            f'  <joint name="joint_{i}" type="{joint.type}"><parent link="frame_{i - 1}"/>'
            f'<child link="link_{i}"/>{_origin(A)}<axis xyz="0 0 1"/>'
            f'<limit lower="{lower!r}" upper="{upper!r}" effort="{UNRATED!r}" '
            f'velocity="{UNRATED!r}"/></joint>')
        if joint.mass is not None and joint.mass > 0:
            com = (0.0, 0.0, 0.0) if joint.com is None else joint.com
            xyz = " ".join(repr(float(v)) for v in com)
            moment = repr(sphere_moment(float(joint.mass)))
            lines.append(
                f'  <link name="frame_{i}"><inertial><origin xyz="{xyz}" rpy="0 0 0"/>'
                f'<mass value="{float(joint.mass)!r}"/>'
                f'<inertia ixx="{moment}" ixy="0" ixz="0" iyy="{moment}" iyz="0" '
                f'izz="{moment}"/></inertial></link>')
        else:
            lines.append(f'  <link name="frame_{i}"/>')
        lines.append(f'  <joint name="dh_{i}" type="fixed"><parent link="link_{i}"/>'
                     f'<child link="frame_{i}"/>{_origin(B)}</joint>')
    lines.append('  <link name="tool"/>')
    lines.append(f'  <joint name="tool_joint" type="fixed"><parent link="frame_{robot.dof}"/>'
                 f'<child link="tool"/>{_origin(robot.tool.matrix())}</joint>')
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def export_urdf(robot: Robot, path: str | Path) -> None:
    """Write ``robot`` as a URDF file (see ``urdf_text``), readable by pinocchio."""
    with atomic_file(path) as staging:
        staging.write_text(urdf_text(robot))

