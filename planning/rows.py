"""Rows of the identification Jacobian contributed by each candidate.

For a candidate with residual ``r`` (the residuals of its kind, [m]) the
planner needs ``G = dr/d(robot geometry, mounted)``, ``L = dr/d(local placement)`` (the
sockets of one artifact placement touched more than once, projected out per candidate)
and ``S = dr/d(shared placement)`` (the tracker frame, the sphere centre, projected out
of the whole design). A ``Block`` holds ``X = P [G S]`` with ``P`` the projection
orthogonal to ``L``; the design's Jacobian stacks the blocks' ``X``.

Residuals, nominal robot, instrument at its nominal place:

* touches: each touch of a socket touched more than once ``p(q) - s``; per placement
  ``|s_a - s_b| - d`` and ``(C - A) . (D - B) / d_AC``, a socket touched once being
  where the probe was (as in ``measurement.artifact``);
* tracker: ``R p(q) + t`` with ``(t, R)`` the instrument frame (6 shared unknowns);
* sphere: ``|T(q) (p0 + l n) - c| - R`` with ``n`` varied in its tangent plane
  (2 unknowns) and ``c`` the centre (3 shared unknowns).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from robocal_casadi.kinematics import Kinematics

from .candidates import Candidate
from .setup import PlanSetup


@dataclass(frozen=True)
class Block:
    """``X`` (rows x (parameters + shared)) of one candidate, local unknowns projected out."""

    X: np.ndarray

    def __repr__(self) -> str:
        return f"Block({self.X.shape[0]} rows x {self.X.shape[1]} columns)"


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _project_out(G: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``G`` with its component in the column space of ``L`` removed."""
    if L.shape[1] == 0:
        return G
    U, s, _ = np.linalg.svd(L, full_matrices=False)
    U = U[:, s > 1e-12 * max(s.max(), 1e-300)]
    return G - U @ (U.T @ G)


class RowModel:
    """Jacobian rows of candidates of one set-up; CasADi functions built once here."""

    def __init__(self, setup: PlanSetup, kinematics: Kinematics):
        self.setup = setup
        self.kinematics = kinematics
        self.p = kinematics.nominal
        robot_names = kinematics.registry.names
        mounted = {"tracker_points": ("target_x", "target_y", "target_z"),
                   "sphere_laser": ("laser_x", "laser_y", "laser_z", "laser_n1", "laser_n2")}
        # (the engine's beam unknowns are laser_nx, _ny, _nz with |n| = 1 as a residual;
        # here the two directions normal to the nominal beam, the same subspace)
        self.mounted = mounted.get(setup.kind, ("probe_x", "probe_y", "probe_z"))
        self.parameters = tuple(robot_names) + self.mounted
        self.shared = {"tracker_points": 6, "sphere_laser": 3}.get(setup.kind, 0)
        self._touch_functions: dict[tuple[str, ...], ca.Function] = {}
        if setup.kind == "sphere_laser":
            self._sphere = self._sphere_function()

    def __repr__(self) -> str:
        return (f"RowModel({self.setup.kind}, parameters={len(self.parameters)}, "
                f"shared={self.shared})")

    def blocks(self, candidates: list[Candidate]) -> list[Block]:
        if self.setup.kind == "tracker_points":
            return self._tracker(candidates)
        if self.setup.kind == "sphere_laser":
            return [self._sphere_block(c) for c in candidates]
        return [self._touch_block(c) for c in candidates]

    # ------------------------------------------------------------------ tracker

    def _tracker(self, candidates):
        Q = np.vstack([c.joints for c in candidates])
        kin = self.kinematics
        f = kin.mapped(kin.point_jacobians, len(Q))
        world, J_p, _, J_offset = f(Q.T, self.p, self.setup.offset)
        world = np.asarray(world).T
        n_p = len(self.p)
        J_p = np.asarray(J_p).reshape(3, len(Q), n_p).transpose(1, 0, 2)
        J_offset = np.asarray(J_offset).reshape(3, len(Q), 3).transpose(1, 0, 2)
        blocks = []
        for i in range(len(Q)):
            S = np.hstack([np.eye(3), -_skew(world[i])])
            blocks.append(Block(np.hstack([J_p[i], J_offset[i], S])))
        return blocks

    # ------------------------------------------------------------------ touches

    def _touch_function(self, points: tuple[str, ...]) -> ca.Function:
        """Residual Jacobians of one placement whose rows touch ``points`` (cached)."""
        if points in self._touch_functions:
            return self._touch_functions[points]
        kin, dof = self.kinematics, self.kinematics.dof
        k = len(points)
        Q = ca.MX.sym("Q", dof, k)
        p = ca.MX.sym("p", len(self.p))
        probe = ca.MX.sym("probe", 3)
        repeated = sorted({n for n in points if points.count(n) > 1})
        local = ca.MX.sym("sockets", 3 * len(repeated))
        world = [kin.point(Q[:, j], p, probe) for j in range(k)]
        position, parts = {}, []
        for i, name in enumerate(repeated):
            position[name] = local[3 * i:3 * i + 3]
        for j, name in enumerate(points):
            if name in position:
                parts.append(world[j] - position[name])
            else:
                position[name] = world[j]
        known = {}
        for a, b, length in self.setup.distances:
            known[(a, b)] = known[(b, a)] = length
            if a in position and b in position:
                parts.append(ca.norm_2(position[a] - position[b]) - length)
        for a, c, b, d in self.setup.perpendicular:
            if all(s in position for s in (a, b, c, d)):
                ac, bd = position[c] - position[a], position[d] - position[b]
                scale = known.get((a, c))
                if scale is None:
                    scale = ca.sqrt(ca.norm_2(ac) * ca.norm_2(bd))
                parts.append(ca.dot(ac, bd) / scale)
        r = ca.vertcat(*parts)
        function = ca.Function("touch_rows", [Q, p, probe, local],
                               [ca.jacobian(r, ca.vertcat(p, probe)), ca.jacobian(r, local)])
        self._touch_functions[points] = function
        return function

    def _touch_block(self, candidate: Candidate) -> Block:
        function = self._touch_function(candidate.points)
        repeated = sorted({n for n in candidate.points if candidate.points.count(n) > 1})
        local = (np.concatenate([candidate.sockets[n] for n in repeated]) if repeated
                 else np.zeros(0))
        G, L = function(candidate.joints.T, self.p, self.setup.offset, local)
        G, L = np.asarray(G), np.asarray(L)
        return Block(_project_out(G, L.reshape(G.shape[0], -1)))

    # ------------------------------------------------------------------ sphere

    def _sphere_function(self) -> ca.Function:
        kin = self.kinematics
        q = ca.SX.sym("q", kin.dof)
        p = ca.SX.sym("p", len(self.p))
        origin = ca.SX.sym("origin", 3)
        tangent = ca.SX.sym("tangent", 2)
        centre = ca.SX.sym("centre", 3)
        reading = ca.SX.sym("reading")
        n0 = self.setup.axis / np.linalg.norm(self.setup.axis)
        helper = np.array([1.0, 0, 0]) if abs(n0[0]) < 0.9 else np.array([0, 1.0, 0])
        t1 = np.cross(n0, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n0, t1)
        n = n0 + tangent[0] * t1 + tangent[1] * t2
        n = n / ca.norm_2(n)
        T = kin.flange_pose(q, p)
        spot = T[:3, :3] @ (origin + reading * n) + T[:3, 3]
        r = ca.norm_2(spot - centre) - self.setup.radius
        return ca.Function("sphere_rows", [q, p, origin, tangent, centre, reading],
                           [ca.jacobian(r, ca.vertcat(p, origin, tangent)),
                            ca.jacobian(r, centre)])

    def _sphere_block(self, candidate: Candidate) -> Block:
        rows = []
        for q, reading in zip(candidate.joints, candidate.distance):
            G, S = self._sphere(q, self.p, self.setup.offset, np.zeros(2), self.setup.centre,
                                reading)
            rows.append(np.hstack([np.asarray(G), np.asarray(S)]))
        return Block(np.vstack(rows))
