"""What the robot can reach: joint limits, a worktable, and batched inverse kinematics.

``Workspace`` solves, for many targets at once, joint readings that put a flange-frame
point on a world position [m] (``solve_points``) or a flange-frame point and axis on a
world point and direction (``solve_beams``, for a point laser), by damped least squares
from random seeds, clamped to the joint limits. A solution counts only when it is
within the limits and its residual is below ``tolerance`` [m].

The worktable is the plane ``z_world = table_height`` [m]: the touched or measured
point and every joint frame origin after the first must lie above it.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from robocal_casadi.common import exact
from robocal_casadi.model.kinematics import Kinematics

CHUNK = 64  # targets solved together (one mapped CasADi call)
DEFAULT_SPAN = np.pi  # [rad] half-range for seeds of joints without limits


@dataclass(frozen=True)
class Solutions:
    """Joint readings ``joints`` (N x dof) [rad or m] and which of them ``ok`` (N,)."""

    joints: np.ndarray
    ok: np.ndarray
    error: np.ndarray  # [m] remaining task error per target

    def __repr__(self) -> str:
        return f"Solutions({int(self.ok.sum())} of {len(self.ok)} solved)"


class Workspace:
    """Limits, worktable and inverse kinematics of one robot at parameters ``p`` [SI]."""

    def __init__(self, kinematics: Kinematics, p: np.ndarray | None = None, *,
                 table_height: float | None = None, tolerance: float = 1e-9, body=None):
        self.kinematics = kinematics
        self.robot = kinematics.robot
        self.p = kinematics.nominal if p is None else np.asarray(p, float)
        self.dof = kinematics.dof
        self.lower = self.robot.lower_limits
        self.upper = self.robot.upper_limits
        base_z = float(self.robot.base.xyz[2])
        self.table_height = base_z if table_height is None else float(table_height)
        self.tolerance = tolerance
        self.body = body
        """``collision.Body`` whose capsules must be clear as well, or None."""
        q = ca.SX.sym("q", self.dof)
        p_sym = ca.SX.sym("p", len(kinematics.registry))
        origin = ca.SX.sym("origin", 3)
        axis = ca.SX.sym("axis", 3)
        T = kinematics.flange_pose(q, p_sym)
        o_world = T[:3, :3] @ origin + T[:3, 3]
        d_world = T[:3, :3] @ axis
        beam = ca.Function("beam", [q, p_sym, origin, axis],
                           [o_world, d_world, ca.jacobian(o_world, q), ca.jacobian(d_world, q)])
        self._beam = beam.map(CHUNK, "serial")
        frames = kinematics.joint_frames(q, p_sym)
        heights = ca.vertcat(*[frames[i][2, 3] for i in range(1, self.dof + 1)])
        self.heights = ca.Function("heights", [q, p_sym], [heights])
        """``(q, p) -> z`` [m] of the joint frame origins 1..n, world frame."""
        self._heights = self.heights.map(CHUNK, "serial")

    def __repr__(self) -> str:
        return (f"Workspace({self.robot.name!r}, table_height={self.table_height:.4g} m, "
                f"dof={self.dof})")

    # ------------------------------------------------------------------ sampling and checks

    def seed_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.where(np.isfinite(self.lower), self.lower, -DEFAULT_SPAN)
        hi = np.where(np.isfinite(self.upper), self.upper, DEFAULT_SPAN)
        return lo, hi

    def random_joints(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` readings drawn uniformly within the limits (N x dof)."""
        lo, hi = self.seed_bounds()
        return lo + (hi - lo) * rng.random((count, self.dof))

    def within_limits(self, Q: np.ndarray, margin: float = 0.0) -> np.ndarray:
        Q = np.atleast_2d(Q)
        return np.all((Q >= self.lower + margin) & (Q <= self.upper - margin), axis=1)

    def frame_heights(self, Q: np.ndarray) -> np.ndarray:
        """World z [m] of the joint frame origins 1..n (N x dof)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        out = []
        for start in range(0, len(Q), CHUNK):
            block = _pad(Q[start:start + CHUNK])
            out.append(np.asarray(self._heights(block.T, self.p)).T[:min(CHUNK, len(Q) - start)])
        return np.vstack(out) if out else np.zeros((0, self.dof))

    def clear_of_table(self, Q: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """True where every joint frame origin (and ``points``, N x 3 [m]) is above the table
        and, with a ``body``, its capsules are clear of the table, each other and the line
        of sight."""
        ok = np.all(self.frame_heights(Q) > self.table_height, axis=1)
        if self.body is not None and len(ok):
            ok &= self.body.clear(Q)
        if points is not None:
            ok &= np.atleast_2d(points)[:, 2] > self.table_height
        return ok

    # ------------------------------------------------------------------ inverse kinematics

    def solve_points(self, targets: np.ndarray, offset: np.ndarray, seeds: np.ndarray,
                     iterations: int = 80) -> Solutions:
        """Joints putting flange point ``offset`` [m] on ``targets`` (N x 3) [m], world frame."""
        return self._solve(np.atleast_2d(targets), None, np.asarray(offset, float),
                           np.array([0.0, 0.0, 1.0]), np.atleast_2d(seeds), iterations)

    def solve_beams(self, origins: np.ndarray, directions: np.ndarray, origin: np.ndarray,
                    axis: np.ndarray, seeds: np.ndarray, iterations: int = 100) -> Solutions:
        """Joints putting flange point ``origin`` on ``origins`` and flange axis ``axis``
        along ``directions`` (unit, N x 3), world frame [m]."""
        return self._solve(np.atleast_2d(origins), np.atleast_2d(directions),
                           np.asarray(origin, float), np.asarray(axis, float),
                           np.atleast_2d(seeds), iterations)

    def _solve(self, targets, directions, origin, axis, seeds, iterations) -> Solutions:
        n = len(targets)
        joints = np.empty((n, self.dof))
        errors = np.empty(n)
        for start in range(0, n, CHUNK):
            stop = min(start + CHUNK, n)
            d = None if directions is None else directions[start:stop]
            joints[start:stop], errors[start:stop] = self._solve_chunk(
                targets[start:stop], d, origin, axis, seeds[start:stop], iterations)
        ok = (errors < self.tolerance) & self.within_limits(joints)
        return Solutions(joints, ok, errors)

    def _evaluate(self, Q, origin, axis):
        o, d, Jo, Jd = self._beam(Q.T, self.p, origin, axis)
        k = len(Q)
        o = np.asarray(o).T
        d = np.asarray(d).T
        Jo = np.asarray(Jo).reshape(3, CHUNK, self.dof).transpose(1, 0, 2)
        Jd = np.asarray(Jd).reshape(3, CHUNK, self.dof).transpose(1, 0, 2)
        return o[:k], d[:k], Jo[:k], Jd[:k]

    def _solve_chunk(self, targets, directions, origin, axis, seeds, iterations):
        k = len(targets)
        lo, hi = self.lower, self.upper
        Q = np.clip(_pad(seeds.astype(float)), lo, hi)
        damping = 1e-4
        error = np.full(CHUNK, np.inf)
        previous = np.full(CHUNK, np.inf)
        for iteration in range(iterations):
            o, d, Jo, Jd = self._evaluate(Q, origin, axis)
            e = _pad(targets) - o
            J = Jo
            if directions is not None:
                # Direction error scaled by 0.1 m so that 1 rad weighs like 0.1 m.
                e = np.concatenate([e, 0.1 * (_pad(directions) - d)], axis=1)
                J = np.concatenate([Jo, 0.1 * Jd], axis=1)
            error = exact.norm(e, axis=1)
            active = error[:k] >= self.tolerance * 1e-2
            if not active.any():
                break
            progress = (previous[:k] - error[:k]) / np.maximum(error[:k], 1e-300)
            if iteration >= 15 and np.all(progress[active] < 1e-2):
                break  # the rest are stuck (unreachable from their seeds)
            previous = error
            # common.exact, not BLAS: whether a target counts as reached decides which
            # candidates exist, and must not depend on the processor
            JJt = exact.matmul(J, J.transpose(0, 2, 1)) + damping * np.eye(J.shape[1])
            weights = exact.solve_stack(JJt, e)
            step = (J * weights[:, :, None]).sum(axis=1)  # J^T w, summed in order
            largest = np.max(np.abs(step), axis=1, keepdims=True)
            step *= np.minimum(1.0, 0.5 / np.maximum(largest, 1e-300))
            Q = np.clip(Q + step, lo, hi)
        o, d, _, _ = self._evaluate(Q, origin, axis)
        error = exact.norm(_pad(targets) - o, axis=1)
        if directions is not None:
            error = np.maximum(error, 0.1 * exact.norm(_pad(directions) - d, axis=1))
        return Q[:k], error[:k]


def _pad(block: np.ndarray) -> np.ndarray:
    """Rows of ``block`` repeated (last row) up to ``CHUNK`` rows."""
    block = np.atleast_2d(block)
    if len(block) == CHUNK:
        return block
    return np.vstack([block, np.repeat(block[-1:], CHUNK - len(block), axis=0)])
