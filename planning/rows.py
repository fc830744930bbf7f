"""Rows of the identification Jacobian contributed by each candidate.

For a candidate with residual ``r`` the planner needs ``G = dr/d(robot geometry,
mounted)``, ``L = dr/d(local placement)`` (unknowns of one candidate alone, e.g. the
sockets of one artifact placement touched more than once, projected out per candidate)
and ``S = dr/d(shared placement)`` (e.g. the tracker frame or the sphere centre, projected
out of the whole design). A ``Block`` holds ``X = P [G S]`` with ``P`` the projection
orthogonal to ``L``; the design's Jacobian stacks the blocks' ``X``.

The residual is the measurement model's own (``robocal_casadi.instruments``), at the
nominal robot, the file's mounted values (``nominal_mounted``) and the instrument at
its nominal place (``nominal_placement``): per row (``row_residual``) for models whose
residual has entries per row, else the model's ``residual`` of a dataset made of the
candidate's rows. The mounted unknowns are varied in the model's minimal coordinates
(``mounted_chart``: the laser beam in its tangent plane, two unknowns).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from robocal_casadi.common import exact
from robocal_casadi.instruments import MeasurementModel
from robocal_casadi.model.kinematics import Kinematics

from .candidates import Candidate
from .setup import PlanSetup


@dataclass(frozen=True)
class Block:
    """``X`` (rows x (parameters + shared)) of one candidate, local unknowns projected out."""

    X: np.ndarray

    def __repr__(self) -> str:
        return f"Block({self.X.shape[0]} rows x {self.X.shape[1]} columns)"


def _project_out(G: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``G`` with its component in the column space of ``L`` removed (``common.exact``:
    every later choice of the planner is made on these rows)."""
    if L.shape[1] == 0:
        return G
    return exact.project_out(G, L, 1e-12)


class RowModel:
    """Jacobian rows of candidates of one set-up; CasADi functions built once here."""

    def __init__(self, setup: PlanSetup, kinematics: Kinematics):
        self.setup = setup
        self.kinematics = kinematics
        self.p = kinematics.nominal
        self.instrument = setup.model
        template = self._model([Candidate(np.zeros((1, kinematics.dof)), ("socket",),
                                          distance=np.zeros(1))])
        self.nominal = template.nominal_mounted()
        self.mounted, self._chart = template.mounted_chart(self.nominal)
        self.parameters = tuple(kinematics.registry.names) + tuple(self.mounted)
        self.shared = len(template.placement) if self.instrument.placement_shared else 0
        self._per_row = template.per_row
        self._template = template
        self._functions: dict[tuple[str, ...], tuple[ca.Function, MeasurementModel]] = {}
        if self._per_row:
            self._row = self._row_function(template)

    def __repr__(self) -> str:
        return (f"RowModel({self.setup.kind}, parameters={len(self.parameters)}, "
                f"shared={self.shared})")

    def _model(self, candidates: list[Candidate]) -> MeasurementModel:
        """The measurement model of a dataset made of ``candidates`` (nominal readings)."""
        joints = np.vstack([c.joints for c in candidates])
        pose = np.concatenate([np.full(len(c.joints), k + 1) for k, c in enumerate(candidates)])
        point = tuple(p for c in candidates for p in c.points)
        distance = (np.concatenate([c.distance for c in candidates])
                    if all(c.distance is not None for c in candidates) else None)
        dataset = self.instrument.planned_dataset(self.setup.dataset, joints, self.kinematics,
                                                  pose=pose, point=point, distance=distance)
        return self.instrument(dataset, "plan")

    def blocks(self, candidates: list[Candidate]) -> list[Block]:
        if self._per_row:
            return self._row_blocks(candidates)
        return [self._group_block(c) for c in candidates]

    def symbolic_block(self, candidate: Candidate, Q, data=None):
        """The block ``P [G S]`` of ``candidate`` with joint readings ``Q`` (dof x k, CasADi)
        and, for per-row models, each row's data ``data[k]`` (``row_data``, numbers or
        CasADi; default the candidate's nominal readings), as CasADi expressions (for
        continuous refinement)."""
        if self._per_row:
            if data is None:
                data = self._model([candidate]).row_data()
            placement = self._placement(candidate)
            rows = []
            for k in range(Q.shape[1]):
                G, S = self._row(Q[:, k], data[k], self.p, np.zeros(len(self.mounted)), placement)
                rows.append(ca.horzcat(G, S))
            return self._project(ca.vertcat(*rows), None)
        function, model = self._group_function(candidate)
        G, L = function(Q, self.p, np.zeros(len(self.mounted)), self._placement(candidate, model))
        return self._project(G, L)

    def row_jacobians(self, q, data):
        """``(G, S)`` of one row of a per-row model at joint reading ``q`` and row data
        ``data`` (numbers or CasADi; the laser reading for a laser), instrument nominal."""
        return self._row(q, data, self.p, np.zeros(len(self.mounted)),
                         self._template.nominal_placement())

    # ------------------------------------------------------------------ per-row models

    def _row_function(self, model: MeasurementModel) -> ca.Function:
        """``(q, data, p, delta, placement) -> (dr/d(p, delta), dr/d placement)`` of one row."""
        kin = self.kinematics
        q = ca.SX.sym("q", kin.dof)
        data = ca.SX.sym("data", model.row_data().shape[1])
        p = ca.SX.sym("p", len(self.p))
        delta = ca.SX.sym("delta", len(self.mounted))
        placement = ca.SX.sym("placement", len(model.placement))
        mounted = self._chart(delta)
        point = kin.point(q, p, model.row_offset(data, mounted))
        r = model.row_residual(point, data, mounted, placement, ca.DM(model.row_constants()))
        return ca.Function("instrument_rows", [q, data, p, delta, placement],
                           [ca.jacobian(r, ca.vertcat(p, delta)), ca.jacobian(r, placement)])

    def _placement(self, candidate: Candidate, model: MeasurementModel | None = None):
        return (model or self._template).nominal_placement(candidate.sockets)

    def _row_blocks(self, candidates: list[Candidate]) -> list[Block]:
        Q = np.vstack([c.joints for c in candidates])
        data = self._model(candidates).row_data()
        n = len(Q)
        G, S = self._row.map(n)(Q.T, data.T, self.p, np.zeros(len(self.mounted)),
                                self._placement(candidates[0]))
        G, S = np.asarray(G), np.asarray(S)
        size = G.shape[0]
        G = G.reshape(size, n, -1).transpose(1, 0, 2)
        S = S.reshape(size, n, -1).transpose(1, 0, 2)
        blocks, start = [], 0
        for candidate in candidates:
            k = len(candidate.joints)
            # the candidate's k readings' rows, stacked
            X = np.concatenate([G[start:start + k].reshape(-1, G.shape[2]),
                                S[start:start + k].reshape(-1, S.shape[2])], axis=1)
            blocks.append(Block(X if self.shared else _project_out(X[:, :G.shape[2]],
                                                                   X[:, G.shape[2]:])))
            start += k
        return blocks

    # ------------------------------------------------------------------ group models

    def _group_function(self, candidate: Candidate):
        """Residual Jacobians of a candidate's rows, cached by its sockets touched."""
        key = candidate.points
        if key not in self._functions:
            kin = self.kinematics
            model = self._model([candidate])
            k = len(candidate.joints)
            Q = ca.MX.sym("Q", kin.dof, k)
            p = ca.MX.sym("p", len(self.p))
            delta = ca.MX.sym("delta", len(self.mounted))
            placement = ca.MX.sym("placement", len(model.placement))

            def points(offsets):
                columns = offsets.shape[1]
                return ca.horzcat(*[kin.point(Q[:, j], p, offsets[:, j if columns > 1 else 0])
                                    for j in range(k)])

            r = model.residual(points, self._chart(delta), placement)
            function = ca.Function("instrument_rows", [Q, p, delta, placement],
                                   [ca.jacobian(r, ca.vertcat(p, delta)),
                                    ca.jacobian(r, placement)])
            self._functions[key] = (function, model)
        return self._functions[key]

    def _group_block(self, candidate: Candidate) -> Block:
        function, model = self._group_function(candidate)
        G, L = function(candidate.joints.T, self.p, np.zeros(len(self.mounted)),
                        self._placement(candidate, model))
        G, L = np.asarray(G), np.asarray(L)
        if self.shared:
            return Block(np.hstack([G, L]))
        return Block(_project_out(G, L.reshape(G.shape[0], -1)))

    def _project(self, X, L):
        """``X`` with the local placement columns projected out (CasADi)."""
        if self.shared:
            return X if L is None else ca.horzcat(X, L)
        if L is None:
            m = len(self.parameters)
            X, L = X[:, :m], X[:, m:]
        if L.shape[1] == 0:
            return X
        P = ca.DM.eye(X.shape[0]) - L @ ca.solve(L.T @ L, L.T)
        return P @ X
