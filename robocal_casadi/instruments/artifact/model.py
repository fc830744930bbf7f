"""Probe touches of sockets on a rigid artifact (``artifact_touches``).

Unknowns: the probe-ball centre in the flange frame (mounted: ``probe_x, probe_y,
probe_z`` [m]) and, per placement, the position of every socket touched more than once
(placement: ``<label>/pose<k>/<socket>_x`` ... [m], world frame). A socket touched once
is simply where the probe was.

Residuals [m], per placement:

* each touch's deviation from its socket (3 components; sockets touched more than once),
* each known distance: ``|S_a - S_b| - L``,
* each perpendicularity ``[A, C, B, D]``: ``(C - A) . (D - B) / L_AC`` with ``L_AC`` the
  known distance A-C when given, else ``sqrt(|AC| |BD|)``.

The cross bar is the artifact with one touch per socket,
distances ``A-C`` and ``B-D`` and one perpendicularity.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ...model.parameters import ParameterRegistry
from ...results import ErrorTerm
from ..dataset import dataset_rows
from ..model import MeasurementModel, PointsFunction


@dataclass(frozen=True)
class _Socket:
    pose: int
    name: str
    rows: tuple[int, ...]
    unknown_index: int | None  # index of its x in the placement vector, None when touched once


class ArtifactModel(MeasurementModel):
    """Residuals of touch data; see the module docstring."""

    kind = "artifact_touches"
    table = "touches.csv"
    reach = "sockets"
    unit_name = "placements"
    reading_name = "touch"
    instrument_name = "touch probe"
    default_noise = (5e-6, 0.0)  # [m] a ball seated in a machined socket, per coordinate

    @classmethod
    def table_rows_per_unit(cls, sockets: int, touches: int) -> int:
        return sockets * touches
    error_title = "artifact error"
    placement_shared = False
    # placements differ in information more than tracker readings: with 16 candidates per
    # placement the pool's bound on the tool error comes within about 6% of what 1,200
    # candidates allow (benchmarks/design_bound.py)
    pool_size = (240, 16)
    invisible_reason = "it moves no touched point relative to the others"
    absorbed_reason = ("absorbed by the unknown socket positions (touch data carry no "
                       "absolute position)")

    def __init__(self, dataset, label: str):
        super().__init__(dataset, label)
        sockets: list[_Socket] = []
        names: list[str] = []
        for pose in sorted(set(int(p) for p in dataset.pose)):
            rows_of_pose = np.flatnonzero(dataset.pose == pose)
            for socket in sorted({dataset.point[i] for i in rows_of_pose}):
                rows = tuple(int(i) for i in rows_of_pose if dataset.point[i] == socket)
                index = None
                if len(rows) > 1:
                    index = len(names)
                    names += [f"{self.placement_prefix}/pose{pose}/{socket}_{axis}"
                              for axis in "xyz"]
                sockets.append(_Socket(pose, socket, rows, index))
        self.sockets = tuple(sockets)
        self._placement = ParameterRegistry(tuple(names), ("length",) * len(names))
        self._by_key = {(s.pose, s.name): s for s in sockets}
        known = {}
        for a, b, length in dataset.distances:
            known[(a, b)] = known[(b, a)] = length
        self._known = known
        self._size = self._count_residuals()

    # ------------------------------------------------------------------ unknowns

    @property
    def mounted(self) -> ParameterRegistry:
        return ParameterRegistry(("probe_x", "probe_y", "probe_z"), ("length",) * 3)

    @property
    def placement(self) -> ParameterRegistry:
        return self._placement

    def initial_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.probe, dtype=float).copy()

    def initial_placement(self, points, mounted) -> np.ndarray:
        world = points(np.asarray(mounted, float).reshape(3, 1))  # 3 x N
        values = np.zeros(len(self._placement))
        for socket in self.sockets:
            if socket.unknown_index is not None:
                values[socket.unknown_index:socket.unknown_index + 3] = \
                    world[:, list(socket.rows)].mean(axis=1)
        return values

    def consistent_dataset(self, kinematics, p, mounted, placement):
        """The dataset with every repeated touch moved onto its socket (joint-space Newton).

        Each touch (a row belongs to one socket) takes up to 8 Newton steps of its own,
        stopping once within 1e-12 m; all touches are evaluated together, one mapped
        call a step, each step's solve its own."""
        if not any(s.unknown_index is not None for s in self.sockets):
            return None
        joints = np.array(self.dataset.joints, dtype=float)
        rows = [row for s in self.sockets if s.unknown_index is not None for row in s.rows]
        targets = np.array([placement[s.unknown_index:s.unknown_index + 3]
                            for s in self.sockets if s.unknown_index is not None
                            for _ in s.rows]).reshape(-1, 3)
        if not rows:
            return replace(self.dataset, joints=joints)
        Q = joints[rows]
        moving = np.ones(len(rows), dtype=bool)
        function = kinematics.mapped(kinematics.point_jacobians, len(rows))
        dof = Q.shape[1]
        for _ in range(8):
            if not moving.any():
                break
            points, _, J_q, _ = function(Q.T, p, mounted)
            points = np.asarray(points).reshape(3, len(rows))
            J_q = np.asarray(J_q).reshape(3, len(rows), dof)
            for k in np.flatnonzero(moving):
                error = targets[k] - points[:, k]
                if np.linalg.norm(error) < 1e-12:
                    moving[k] = False
                    continue
                Q[k] = Q[k] + np.linalg.lstsq(J_q[:, k, :], error, rcond=None)[0]
        joints[rows] = Q
        return replace(self.dataset, joints=joints)

    # ------------------------------------------------------------------ residuals

    def _poses(self):
        return sorted({s.pose for s in self.sockets})

    def _count_residuals(self) -> int:
        count = sum(3 * len(s.rows) for s in self.sockets if s.unknown_index is not None)
        for pose in self._poses():
            count += len(self._distances(pose)) + len(self._perpendiculars(pose))
        return count

    def _distances(self, pose: int):
        return [(a, b, L) for a, b, L in self.dataset.distances
                if (pose, a) in self._by_key and (pose, b) in self._by_key]

    def _perpendiculars(self, pose: int):
        return [entry for entry in self.dataset.perpendicular
                if all((pose, s) in self._by_key for s in entry)]

    def residual_size(self) -> int:
        return self._size

    def residual(self, points: PointsFunction, mounted, placement) -> ca.MX:
        world = points(mounted)  # 3 x N
        position = {}
        parts = []
        for socket in self.sockets:
            if socket.unknown_index is None:
                position[(socket.pose, socket.name)] = world[:, socket.rows[0]]
            else:
                k = socket.unknown_index
                centre = placement[k:k + 3]
                position[(socket.pose, socket.name)] = centre
                for row in socket.rows:
                    parts.append(world[:, row] - centre)
        for pose in self._poses():
            for a, b, length in self._distances(pose):
                parts.append(ca.norm_2(position[(pose, a)] - position[(pose, b)]) - length)
            for a, c, b, d in self._perpendiculars(pose):
                ac = position[(pose, c)] - position[(pose, a)]
                bd = position[(pose, d)] - position[(pose, b)]
                scale = self._known.get((a, c))
                if scale is None:
                    scale = ca.sqrt(ca.norm_2(ac) * ca.norm_2(bd))
                parts.append(ca.dot(ac, bd) / scale)
        return ca.vertcat(*parts) if parts else ca.MX(0, 1)

    def _layout(self):
        """(rows, sizes) of each error: touches first (3 residuals each), then scalars."""
        rows, sizes = [], []
        for socket in self.sockets:
            if socket.unknown_index is not None:
                rows += list(socket.rows)
                sizes += [3] * len(socket.rows)
        for pose in self._poses():
            n = len(self._distances(pose)) + len(self._perpendiculars(pose))
            rows += [-1] * n
            sizes += [1] * n
        return np.array(rows, dtype=int), np.array(sizes, dtype=int)

    def entry_noise(self) -> np.ndarray:
        """The standard deviation [m] of each residual entry the touches' noise alone gives
        (``a`` per coordinate of a touch), propagated through the entry's formula: a touch's
        deviation from the socket fitted as the mean of its ``n`` touches, ``a sqrt(1 -
        1/n)`` per coordinate; a distance between two sockets, the noise of each end along
        the line (``a`` for a socket touched once); a perpendicularity ``AC . BD / L``, the
        noise of each of the four ends times the other arm's length over ``L`` (about 1).
        Entries between sockets located by repeated touches are certified: zero."""
        sigma = self.instrument_noise.a
        touches = {(s.pose, s.name): len(s.rows) for s in self.sockets}
        located = {(s.pose, s.name) for s in self.sockets if s.unknown_index is not None}
        out: list[float] = []
        for socket in self.sockets:
            if socket.unknown_index is not None:
                n = len(socket.rows)
                out += [sigma * np.sqrt(max(1.0 - 1.0 / n, 0.0))] * (3 * n)

        def end(pose: int, name: str) -> float:  # variance of one end along a line [m^2]
            return 0.0 if (pose, name) in located else sigma**2 / touches[(pose, name)]

        for pose in self._poses():
            for a, b, _ in self._distances(pose):
                out.append(float(np.sqrt(end(pose, a) + end(pose, b))))
            for names in self._perpendiculars(pose):
                out.append(float(np.sqrt(sum(end(pose, n) for n in names))))
        return np.array(out)

    def certified_entries(self) -> np.ndarray:
        """The distances and perpendicularities between sockets that are all placement
        unknowns (touched more than once): they compare the fitted socket positions with
        the artifact's certified geometry and hold no touch of their own. Where a socket
        is touched once, its touch enters the entry, which then carries its noise."""
        located = {(s.pose, s.name) for s in self.sockets if s.unknown_index is not None}
        out = [False] * sum(3 * len(s.rows) for s in self.sockets if s.unknown_index is not None)
        for pose in self._poses():
            for a, b, _ in self._distances(pose):
                out.append((pose, a) in located and (pose, b) in located)
            for names in self._perpendiculars(pose):
                out.append(all((pose, n) in located for n in names))
        return np.array(out, dtype=bool)

    def residual_groups(self) -> np.ndarray:
        """The placement (pose id) of every residual entry."""
        groups: list[int] = []
        for socket in self.sockets:
            if socket.unknown_index is not None:
                groups += [socket.pose] * (3 * len(socket.rows))
        for pose in self._poses():
            groups += [pose] * (len(self._distances(pose)) + len(self._perpendiculars(pose)))
        return np.array(groups, dtype=int)

    def row_units(self) -> np.ndarray:
        """The placement (pose id) of every data row."""
        return np.asarray(self.dataset.pose, dtype=int)

    def subset(self, groups: np.ndarray):
        """The dataset with only the placements (pose ids) in ``groups``."""
        return dataset_rows(self.dataset, np.isin(self.dataset.pose, groups))

    def errors(self, residual: np.ndarray) -> np.ndarray:
        _, sizes = self._layout()
        residual = np.asarray(residual, float).ravel()
        out = np.empty(len(sizes))
        start = 0
        for i, size in enumerate(sizes):
            out[i] = np.linalg.norm(residual[start:start + size])
            start += size
        return out

    def error_rows(self) -> np.ndarray:
        return self._layout()[0]

    def error_entries(self) -> list[np.ndarray]:
        """Three residual entries per touch, one per distance or perpendicularity."""
        ends = np.cumsum(self._layout()[1])
        return [np.arange(end - size, end) for end, size in zip(ends, self._layout()[1])]

    # ------------------------------------------------------------------ planning

    def nominal_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.probe, dtype=float).copy()

    def nominal_placement(self, sockets=None) -> np.ndarray:
        """The placement vector with every socket touched more than once at its position
        in ``sockets`` (name -> world position [m]; one placed artifact)."""
        values = np.zeros(len(self._placement))
        for socket in self.sockets:
            if socket.unknown_index is not None:
                k = socket.unknown_index
                values[k:k + 3] = np.asarray(sockets[socket.name], dtype=float)
        return values

    @classmethod
    def plan_columns(cls, joints):
        return ["pose", "point"] + list(joints) + ["socket_x", "socket_y", "socket_z"]

    @classmethod
    def plan_row(cls, pose, joints, point, socket):
        return [pose, point] + list(joints) + list(socket)

    @classmethod
    def planned_dataset(cls, dataset, joints, kinematics, *, pose=None, point=(), distance=None):
        """The touches asked for: placement ids ``pose`` and socket names ``point``."""
        return replace(dataset, joints=np.asarray(joints, dtype=float),
                       pose=np.asarray(pose, dtype=int), point=tuple(point), extras={})

    component_frame = "base"

    def error_components(self, residual: np.ndarray) -> np.ndarray:
        """Touch minus socket x, y, z (world frame) for touches; the signed length or
        perpendicularity error in column 0 (NaN after) for the rest [m]."""
        _, sizes = self._layout()
        residual = np.asarray(residual, float).ravel()
        out = np.full((len(sizes), 3), np.nan)
        start = 0
        for i, size in enumerate(sizes):
            out[i, :size] = residual[start:start + size]
            start += size
        return out

    def error_terms(self) -> tuple:
        """``position`` per touch, then per placement its distances and perpendiculars."""
        terms = [ErrorTerm("position", socket.pose, (socket.name,))
                 for socket in self.sockets if socket.unknown_index is not None
                 for _ in socket.rows]
        for pose in self._poses():
            terms += [ErrorTerm("distance", pose, (a, b)) for a, b, _ in self._distances(pose)]
            terms += [ErrorTerm("perpendicular", pose, tuple(entry))
                      for entry in self._perpendiculars(pose)]
        return tuple(terms)

