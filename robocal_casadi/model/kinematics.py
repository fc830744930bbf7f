"""Forward kinematics of a DH or URDF robot, built once as CasADi functions.

All functions take the joint readings ``q`` [rad or m] and the full geometric
parameter vector ``p`` (``ParameterRegistry`` order, SI) as inputs, so the same
function serves the nominal robot, a calibrated one, and symbolic identification.
Derivatives with respect to ``p`` and ``q`` are exact (CasADi automatic
differentiation).

Frames: ``T_world_joint[0]`` is the joint-1 frame (``base``), ``T_world_joint[i]`` the
frame after joint i's transform, ``T_world_joint[n]`` the flange; ``T_world_tool`` adds
``tool``. A point "in the flange frame" (probe tip, reflector, laser origin) is
``offset`` [m].
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from ..common.codegen import BatchFunction, compiled
from .parameters import ParameterRegistry
from .robot import Robot
from .transforms import pose_from_xyz_rpy, product, rot_x, rot_y, rot_z, translation

SERIAL_ROWS = 1000  # from this many rows on, a mapped function runs in series


def dh_transform(convention: str, revolute: bool, reading, theta, d, a, alpha, beta):
    """One link transform ``T(i-1,i)`` (docs/conventions.md#standard-dh,
    docs/conventions.md#modified-dh); works on floats and CasADi symbols.

    ``reading`` is the joint reading, added to ``theta`` (revolute) or ``d`` (prismatic).
    """
    if revolute:
        theta = theta + reading
    else:
        d = d + reading
    if convention == "dh":
        return product(rot_z(theta), translation(0, 0, d), translation(a, 0, 0), rot_x(alpha),
                       rot_y(beta))
    return product(rot_x(alpha), translation(a, 0, 0), rot_z(theta), translation(0, 0, d),
                   rot_y(beta))


def axis_motion(revolute: bool, axis, reading):
    """The joint's motion: rotation by ``reading`` [rad] about the unit ``axis``
    (Rodrigues), or translation by ``reading`` [m] along it; 4x4, floats or CasADi."""
    ax, ay, az = (float(v) for v in axis)
    if not revolute:
        return translation(ax * reading, ay * reading, az * reading)
    lib = ca if isinstance(reading, (ca.SX, ca.MX, ca.DM)) else np
    c, s = lib.cos(reading), lib.sin(reading)
    v = 1 - c
    rows = [[c + ax * ax * v, ax * ay * v - az * s, ax * az * v + ay * s, 0],
            [ay * ax * v + az * s, c + ay * ay * v, ay * az * v - ax * s, 0],
            [az * ax * v - ay * s, az * ay * v + ax * s, c + az * az * v, 0],
            [0, 0, 0, 1]]
    if lib is np:
        return np.array(rows, dtype=float)
    return ca.vertcat(*[ca.horzcat(*row) for row in rows])


def urdf_transform(revolute: bool, axis, reading, xyz, rpy):
    """One URDF link transform ``T(i-1,i) = Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)
    Motion(axis, reading)`` (lengths [m], angles [rad]); floats or CasADi symbols."""
    return product(pose_from_xyz_rpy(xyz, rpy), axis_motion(revolute, axis, reading))


def _fixed(registry: ParameterRegistry, p, frame: str):
    return pose_from_xyz_rpy([p[registry.index(f"{frame}_{k}")] for k in "xyz"],
                             [p[registry.index(f"{frame}_r{k}")] for k in "xyz"])


def symbolic_frames(robot: Robot, registry: ParameterRegistry, q, p) -> list:
    """World frames ``[T_world_0, ..., T_world_n, T_world_tool]`` as CasADi expressions.

    For a ``urdf`` robot frame i is the link joint i moves and frame n the tip link
    (the last moving link then ``flange``).
    """
    base = _fixed(registry, p, "base")
    frames = [base]
    T = base
    for i, joint in enumerate(robot.joints, start=1):
        if robot.convention == "urdf":
            link = urdf_transform(
                joint.revolute, joint.axis, q[i - 1],
                [p[registry.index(f"{stem}{i}")] for stem in ("x", "y", "z")],
                [p[registry.index(f"{stem}{i}")] for stem in ("roll", "pitch", "yaw")])
        else:
            link = dh_transform(
                robot.convention, joint.revolute, q[i - 1],
                *(p[registry.index(f"{stem}{i}")] for stem in ("theta", "d", "a", "alpha", "beta")),
            )
        T = T @ link
        frames.append(T)
    if robot.convention == "urdf":
        T = T @ _fixed(registry, p, "flange")
        frames[-1] = T
    tool = pose_from_xyz_rpy([p[registry.index(f"tool_{k}")] for k in "xyz"],
                             [p[registry.index(f"tool_r{k}")] for k in "xyz"])
    frames.append(T @ tool)
    return frames


def mapped(function: ca.Function, count: int) -> ca.Function:
    """``function`` evaluated over ``count`` columns at once: on two threads below
    ``SERIAL_ROWS``, in series from there on (a threaded map holds work memory that grows
    with ``count``; the numbers are the same); ``function`` itself for one column."""
    if count <= 1:
        return function
    if count >= SERIAL_ROWS:
        return function.map(count, "serial")
    return function.map(count, "thread", 2)

class Kinematics:
    """Cached CasADi kinematics of one robot structure.

    The functions depend on the structure (convention, joint types, dof) only; the
    geometry enters through ``p``. Build one ``Kinematics`` per robot and reuse it.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.registry = robot.parameters()
        self.nominal = self.registry.vector_of(robot)
        self._maps: dict[tuple[str, int], ca.Function] = {}

    def __repr__(self) -> str:
        return (f"Kinematics({self.robot.name!r}, {self.robot.convention}, dof={self.dof}, "
                f"parameters={len(self.registry)})")

    @property
    def dof(self) -> int:
        return self.robot.dof

    # ------------------------------------------------------------------ symbolic core

    @cached_property
    def _symbols(self):
        q = ca.SX.sym("q", self.dof)
        p = ca.SX.sym("p", len(self.registry))
        offset = ca.SX.sym("offset", 3)
        frames = symbolic_frames(self.robot, self.registry, q, p)
        return q, p, offset, frames

    @cached_property
    def joint_frames(self) -> ca.Function:
        """``(q, p) -> (T_world_0, ..., T_world_n)``: joint frames, world coordinates [m]."""
        q, p, _, frames = self._symbols
        return ca.Function("joint_frames", [q, p], frames[:-1], ["q", "p"],
                           [f"T_world_{i}" for i in range(self.dof + 1)])

    @cached_property
    def flange_pose(self) -> ca.Function:
        """``(q, p) -> T_world_flange`` (4x4, [m])."""
        q, p, _, frames = self._symbols
        return ca.Function("flange_pose", [q, p], [frames[-2]], ["q", "p"], ["T_world_flange"])

    @cached_property
    def tool_pose(self) -> ca.Function:
        """``(q, p) -> T_world_tool`` (4x4, [m])."""
        q, p, _, frames = self._symbols
        return ca.Function("tool_pose", [q, p], [frames[-1]], ["q", "p"], ["T_world_tool"])

    @cached_property
    def point(self) -> ca.Function:
        """``(q, p, offset) -> p_world`` [m]: a point fixed in the flange frame, in world."""
        q, p, offset, frames = self._symbols
        T = frames[-2]
        position = T[:3, :3] @ offset + T[:3, 3]
        return ca.Function("point", [q, p, offset], [position], ["q", "p", "offset"], ["p_world"])

    @cached_property
    def point_jacobians(self) -> ca.Function:
        """``(q, p, offset) -> (p_world, d p_world/d p, d p_world/d q, d p_world/d offset)``."""
        q, p, offset, _ = self._symbols
        position = self.point(q, p, offset)
        return ca.Function(
            "point_jacobians", [q, p, offset],
            [position, ca.jacobian(position, p), ca.jacobian(position, q),
             ca.jacobian(position, offset)],
            ["q", "p", "offset"], ["p_world", "J_p", "J_q", "J_offset"],
        )

    @cached_property
    def tool_jacobian(self) -> ca.Function:
        """``(q, p) -> J`` (6 x dof): geometric Jacobian of the tool, world frame.

        Rows 0-2: linear velocity of the tool origin [m/s per unit reading]; rows 3-5:
        angular velocity [rad/s per unit reading], both in the world frame.
        """
        q, p, _, frames = self._symbols
        T = frames[-1]
        linear = ca.jacobian(T[:3, 3], q)
        R = T[:3, :3]
        # omega_hat = dR/dq_i R^T; read its skew part column by column.
        columns = []
        for i in range(self.dof):
            dR = ca.jacobian(ca.vec(R), q[i]).reshape((3, 3))
            W = dR @ R.T
            columns.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
        angular = ca.horzcat(*columns)
        return ca.Function("tool_jacobian", [q, p], [ca.vertcat(linear, angular)], ["q", "p"],
                           ["J"])

    def compiled(self, name: str) -> ca.Function:
        """The function ``name`` (e.g. ``"tool_pose"``) as compiled C, built once and cached.

        Same inputs and outputs as the interpreted one, named ``<name>_compiled`` so that
        ``mapped`` keeps both apart. Falls back to the interpreted function with a warning
        where no C compiler works (see ``codegen.compiled``).
        """
        cache = self.__dict__.setdefault("_compiled", {})
        if name not in cache:
            function = getattr(self, name)
            symbols = function.sx_in()
            renamed = ca.Function(f"{name}_compiled", symbols, function.call(symbols),
                                  function.name_in(), function.name_out())
            cache[name] = compiled(renamed)
        return cache[name]

    def batch(self, name: str, chunk: int = 256):
        """The function ``name`` over many joint readings, compiled: a ``codegen.BatchFunction``.

        ``kinematics.batch("point_jacobians")(Q, p, offset)`` with ``Q`` (N x dof) returns
        numpy arrays with one row per reading (here ``p_world`` N x 3, ``J_p`` N x 3 x
        n_p, ...); ``p`` and the other inputs are shared by all rows, and what depends on
        them alone is computed once per chunk. Built once per (name, chunk) and cached.
        """
        cache = self.__dict__.setdefault("_batches", {})
        if (name, chunk) not in cache:
            cache[name, chunk] = BatchFunction(getattr(self, name), ("q",), chunk)
        return cache[name, chunk]

    # ------------------------------------------------------------------ numeric helpers

    def mapped(self, function: ca.Function, count: int) -> ca.Function:
        """``function.map(count)``, built once per (function, count) and cached: on two
        threads below ``SERIAL_ROWS``, in series from there on (a threaded map holds work
        memory that grows with ``count``; the numbers are the same)."""
        key = (function.name(), count)
        if key not in self._maps:
            self._maps[key] = mapped(function, count)
        return self._maps[key]

    def _parameters(self, p) -> np.ndarray:
        return self.nominal if p is None else np.asarray(p, dtype=float)

    def flange_poses(self, Q: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """World flange poses (N x 4 x 4) [m] for joint readings ``Q`` (N x dof)."""
        return self._poses(self.flange_pose, Q, p)

    def tool_poses(self, Q: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """World tool poses (N x 4 x 4) [m] for joint readings ``Q`` (N x dof)."""
        return self._poses(self.tool_pose, Q, p)

    def _poses(self, function, Q, p) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        out = np.asarray(self.mapped(function, len(Q))(Q.T, self._parameters(p)))
        return out.reshape(4, len(Q), 4).transpose(1, 0, 2)

    def points(self, Q: np.ndarray, offset, p: np.ndarray | None = None) -> np.ndarray:
        """World positions (N x 3) [m] of a flange-frame point ``offset`` [m]."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        out = self.mapped(self.point, len(Q))(Q.T, self._parameters(p), np.asarray(offset, float))
        return np.asarray(out).T


def nominal_pose(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Tool pose of ``robot`` at ``q`` from plain numpy (for quick checks and tests)."""
    T = robot.base.matrix()
    for joint, reading in zip(robot.joints, q):
        if robot.convention == "urdf":
            T = product(T, urdf_transform(joint.revolute, joint.axis, float(reading),
                                          joint.origin.xyz, joint.origin.rpy))
        else:
            T = product(T, dh_transform(robot.convention, joint.revolute, float(reading),
                                        joint.theta, joint.d, joint.a, joint.alpha, joint.beta))
    if robot.convention == "urdf":
        T = product(T, robot.flange.matrix())
    return product(T, robot.tool.matrix())
