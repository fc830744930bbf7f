"""Link volumes of the arm as capsules, checked against the worktable, each other and the
tracker's line of sight.

The arm is a chain of straight segments through the DH frames: for joint ``i``, from
frame ``i-1``'s origin along ``z_{i-1}`` by ``d_i``, then along ``x_i`` by ``a_i``
(standard DH; modified DH: along ``x_{i-1}`` by ``a``, then ``z_i`` by ``d``), and last
from the flange to the measured point (probe, reflector, laser). Segments of zero
nominal length are left out. Each arm segment is a capsule of radius
``RADIUS_FRACTION`` of the longest arm segment (within ``RADIUS_BOUNDS``); the tool's
is half that.

A configuration is clear when

* table: every arm capsule but the pedestal (the fixed segments before joint 1's frame) is
  above the table plane ``z = table_height``, and the tool segment too (its end, the
  measured point, may be close to the table: the artifact lies on it);
* self: capsules do not overlap. Capsules next to each other along the chain touch at
  the joint between them; for a pair whose chain distance (the length of the segments
  between them) is below ``JOINT_SKIP`` times the sum of their radii, both are checked from it
  away from the joint (real links beside a joint are offset along its
  axis; a forearm folded back onto its upper arm is still caught: within about 12 deg
  of each other for a UR's);
* sight (tracker, when the instrument position is known): the line from the instrument
  to the reflector, up to ``SIGHT_MARGIN`` before the reflector, misses every arm capsule.

All lengths [m], world frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from robocal_casadi.model.kinematics import Kinematics

RADIUS_FRACTION = 0.1
RADIUS_BOUNDS = (0.02, 0.08)  # [m]
TOOL_RADIUS_SHARE = 0.5
SIGHT_MARGIN = 0.03  # [m] the line of sight is checked up to this far before the reflector
JOINT_SKIP = 2.0  # beside a joint, capsules are checked this many radii sums away from it
SOFTNESS = 2e-3  # [m] of the smooth minimum over the gaps (``Body.clearance_bound``)
CHUNK = 64


@dataclass(frozen=True)
class Clearance:
    """Which configurations pass each check (N,)."""

    table: np.ndarray
    self: np.ndarray
    sight: np.ndarray

    @property
    def clear(self) -> np.ndarray:
        return self.table & self.self & self.sight

    def __repr__(self) -> str:
        return (f"Clearance({int(self.clear.sum())} of {len(self.clear)} clear; collisions: "
                f"table {int((~self.table).sum())}, self {int((~self.self).sum())}, sight "
                f"{int((~self.sight).sum())})")


def segment_distances(P0, P1, Q0, Q1) -> np.ndarray:
    """Shortest distances [m] between segments ``P0-P1`` and ``Q0-Q1`` (arrays ... x 3,
    broadcast), by clamped closest points."""
    d1, d2, r = P1 - P0, Q1 - Q0, P0 - Q0
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    b = np.einsum("...i,...i->...", d1, d2)
    c = np.einsum("...i,...i->...", d1, r)
    f = np.einsum("...i,...i->...", d2, r)
    tiny = 1e-300
    denom = a * e - b * b
    s = np.where(denom > 1e-14 * np.maximum(a * e, tiny),
                 np.clip((b * f - c * e) / np.maximum(denom, tiny), 0.0, 1.0), 0.0)
    t = (b * s + f) / np.maximum(e, tiny)
    s = np.where(t < 0, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0),
                 np.where(t > 1, np.clip((b - c) / np.maximum(a, tiny), 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    s = np.where(a <= tiny, 0.0, s)
    t = np.where(e <= tiny, 0.0, np.where(a <= tiny, np.clip(f / np.maximum(e, tiny), 0, 1), t))
    gap = (P0 + s[..., None] * d1) - (Q0 + t[..., None] * d2)
    return np.linalg.norm(gap, axis=-1)


def soft_minimum(values, softness: float):
    """``min - softness log(sum exp(-(v - min) / softness))`` of a CasADi vector: smooth,
    and never above the smallest value (below it by at most ``softness log(len)``), so
    a constraint on it is safe for every value."""
    smallest = ca.mmin(values)
    return smallest - softness * ca.log(ca.sum1(ca.exp(-(values - smallest) / softness)))


def segment_distance(P0, P1, Q0, Q1):
    """``segment_distances`` for one pair of segments as a CasADi expression (3-vectors)."""
    d1, d2, r = P1 - P0, Q1 - Q0, P0 - Q0
    a, e, b = ca.dot(d1, d1), ca.dot(d2, d2), ca.dot(d1, d2)
    c, f = ca.dot(d1, r), ca.dot(d2, r)
    tiny = 1e-300
    denom = a * e - b * b
    s = ca.if_else(denom > 1e-14 * ca.fmax(a * e, tiny),
                   ca.fmin(ca.fmax((b * f - c * e) / ca.fmax(denom, tiny), 0.0), 1.0), 0.0)
    t = (b * s + f) / ca.fmax(e, tiny)
    s = ca.if_else(t < 0, ca.fmin(ca.fmax(-c / ca.fmax(a, tiny), 0.0), 1.0),
                   ca.if_else(t > 1, ca.fmin(ca.fmax((b - c) / ca.fmax(a, tiny), 0.0), 1.0), s))
    t = ca.fmin(ca.fmax(t, 0.0), 1.0)
    return ca.norm_2(P0 + s * d1 - (Q0 + t * d2))


class Body:
    """Capsules of one robot carrying a measured point ``offset`` [m] (flange frame)."""

    def __init__(self, kinematics: Kinematics, offset: np.ndarray, table_height: float,
                 instrument: np.ndarray | None = None, p: np.ndarray | None = None):
        self.kinematics = kinematics
        self.p = kinematics.nominal if p is None else np.asarray(p, float)
        self.offset = np.asarray(offset, float)
        self.table_height = float(table_height)
        self.instrument = None if instrument is None else np.asarray(instrument, float)
        robot = kinematics.robot
        q = ca.SX.sym("q", kinematics.dof)
        p_sym = ca.SX.sym("p", len(kinematics.registry))
        frames = kinematics.joint_frames(q, p_sym)
        points, lengths = [frames[0][:3, 3]], []
        for i, joint in enumerate(robot.joints, start=1):
            after = frames[i]
            if robot.convention == "mdh":
                knee = after[:3, 3] - joint.d * after[:3, 2]
                first, second = abs(joint.a), abs(joint.d)
            else:
                knee = after[:3, 3] - joint.a * after[:3, 0]
                first, second = abs(joint.d), abs(joint.a)
            points += [knee, after[:3, 3]]
            lengths += [first, second]
        T = frames[-1]
        points.append(T[:3, :3] @ self.offset + T[:3, 3])
        lengths.append(float(np.linalg.norm(self.offset)))
        self._points_function = ca.Function("capsule_points", [q, p_sym],
                                            [ca.horzcat(*points)])
        self._points = self._points_function.map(CHUNK, "serial")
        kept = [k for k, length in enumerate(lengths) if length > 1e-6]
        self.segments = np.array([(k, k + 1) for k in kept])  # indices into the points
        self.lengths = np.array([lengths[k] for k in kept])
        arm = self.lengths[:-1] if lengths[-1] > 1e-6 else self.lengths
        radius = float(np.clip(RADIUS_FRACTION * (arm.max() if arm.size else 0.0),
                               *RADIUS_BOUNDS))
        self.tool = lengths[-1] > 1e-6  # the last segment is the tool's
        self.radii = np.full(len(kept), radius)
        if self.tool:
            self.radii[-1] = TOOL_RADIUS_SHARE * radius
        # the pedestal: fixed segments up to joint 1's frame (standard DH: along z_0 by
        # d_1; modified DH: along x_0 by a_1, then z_1 by d_1)
        fixed = 2 if robot.convention == "mdh" else 1
        self.pedestal = np.array([k < fixed for k in kept])
        self.pairs, self.trims = self._pairs()

    def __repr__(self) -> str:
        return (f"Body({len(self.segments)} capsules, radius {self.radii[0]:.3g} m, "
                f"{len(self.pairs)} pairs checked)")

    @classmethod
    def of(cls, setup, kinematics: Kinematics) -> Body:
        """The body of a plan set-up: its measured point, table and (tracker) instrument."""
        table = setup.table_height
        if table is None:
            table = float(kinematics.robot.base.xyz[2])
        return cls(kinematics, setup.offset, table, setup.instrument)

    def _pairs(self):
        """Capsule pairs to check and how much to skip [m] at the joint between them (the
        end of the earlier, the start of the later)."""
        pairs, trims = [], []
        n = len(self.segments)
        for i in range(n):
            for j in range(i + 1, n):
                between = float(self.lengths[i + 1:j].sum())
                reach = self.radii[i] + self.radii[j]
                trim = JOINT_SKIP * reach if between < JOINT_SKIP * reach else 0.0
                if trim < min(self.lengths[i], self.lengths[j]):
                    pairs.append((i, j))
                    trims.append(trim)
        return np.array(pairs, int).reshape(-1, 2), np.array(trims)

    def points(self, Q: np.ndarray) -> np.ndarray:
        """Chain points (N x points x 3) [m] for joint readings ``Q`` (N x dof)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        out = []
        for start in range(0, len(Q), CHUNK):
            block = Q[start:start + CHUNK]
            padded = np.vstack([block, np.repeat(block[-1:], CHUNK - len(block), axis=0)])
            values = np.asarray(self._points(padded.T, self.p))  # 3 x (CHUNK * points)
            count = values.shape[1] // CHUNK
            out.append(values.T.reshape(CHUNK, count, 3)[:len(block)])
        return np.concatenate(out) if out else np.zeros((0, 0, 3))

    def check(self, Q: np.ndarray) -> Clearance:
        """Which of the configurations ``Q`` (N x dof) pass each check."""
        X = self.points(Q)
        A, B = X[:, self.segments[:, 0]], X[:, self.segments[:, 1]]  # N x S x 3
        low = np.minimum(A[..., 2], B[..., 2])
        radii = self.radii.copy()
        if self.tool:
            radii[-1] = 0.0  # the measured point may sit just above the table
        table = np.all((low - radii > self.table_height) | self.pedestal, axis=1)
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        trim = self.trims[None, :, None]
        end = B[:, i] - trim * (B[:, i] - A[:, i]) / self.lengths[i][None, :, None]
        start = A[:, j] + trim * (B[:, j] - A[:, j]) / self.lengths[j][None, :, None]
        gaps = segment_distances(A[:, i], end, start, B[:, j])
        apart = np.all(gaps >= (self.radii[i] + self.radii[j]) - 1e-9, axis=1)
        sight = np.ones(len(X), bool)
        if self.instrument is not None:
            target = B[:, -1] if self.tool else A[:, -1]
            towards = self.instrument - target
            near = target + SIGHT_MARGIN * towards / np.linalg.norm(towards, axis=1,
                                                                    keepdims=True)
            arm = slice(0, len(self.segments) - 1 if self.tool else len(self.segments))
            gaps = segment_distances(A[:, arm], B[:, arm], near[:, None],
                                     np.broadcast_to(self.instrument, near.shape)[:, None])
            sight = np.all(gaps > self.radii[arm], axis=1)
        return Clearance(table, apart, sight)

    def clearances(self, q) -> ca.SX:
        """Symbolic gaps [m] at joint reading ``q`` (CasADi, dof): per non-pedestal
        capsule its height above the table less its radius (the tool capsule's end may
        touch it, as in ``check``), per checked pair the distance between the trimmed
        segments less the two radii, and with an instrument per arm capsule its distance
        from the line of sight less its radius. ``check`` passes where all are >= 0 (up
        to 1e-9; the line of sight strictly)."""
        X = self._points_symbolic(q)
        gaps = []
        for k, (a, b) in enumerate(self.segments):
            if self.pedestal[k]:
                continue
            radius = 0.0 if (self.tool and k == len(self.segments) - 1) else self.radii[k]
            gaps.append(ca.fmin(X[2, a], X[2, b]) - radius - self.table_height)
        for (i, j), trim in zip(self.pairs, self.trims):
            A_i, B_i = X[:, self.segments[i, 0]], X[:, self.segments[i, 1]]
            A_j, B_j = X[:, self.segments[j, 0]], X[:, self.segments[j, 1]]
            end = B_i - trim * (B_i - A_i) / self.lengths[i]
            start = A_j + trim * (B_j - A_j) / self.lengths[j]
            gaps.append(segment_distance(A_i, end, start, B_j) - self.radii[i] - self.radii[j])
        if self.instrument is not None:
            last = len(self.segments) - 1
            target = X[:, self.segments[last, 1] if self.tool else self.segments[last, 0]]
            towards = self.instrument - target
            near = target + SIGHT_MARGIN * towards / ca.norm_2(towards)
            for k in range(last if self.tool else last + 1):
                A, B = X[:, self.segments[k, 0]], X[:, self.segments[k, 1]]
                gaps.append(segment_distance(A, B, near, ca.DM(self.instrument))
                            - self.radii[k])
        return ca.vertcat(*gaps)

    def clearance_bound(self, q, softness: float = SOFTNESS):
        """A smooth lower bound [m] of the smallest of ``clearances(q)``: ``>= 0`` implies
        every gap is (``soft_minimum``)."""
        return soft_minimum(self.clearances(q), softness)

    def _points_symbolic(self, q):
        return self._points_function(q, self.p)

    def clear(self, Q: np.ndarray) -> np.ndarray:
        """True where configuration ``Q`` (N x dof) passes every check."""
        return self.check(Q).clear
