"""``Tracker``: keep the tool facing a moving target, level with the worktable, cycle by cycle.

Built once for a robot, a camera mount and a standoff; ``step(q_capture, observation)``
then computes the goal end pose from the method's frame chain (``tracking.goal``),
solves the per-cycle NLP from the previous answer (``tracking.problem``,
``tracking.solver``; from inverse kinematics where that fails), takes each joint to its
equivalent value nearest the previous answer, verifies the constraint errors, and answers
with a ``TrackStep``. An answer that is not verified is never returned as ``ok``: the step
says ``limited`` (a bounded step towards a verified answer), ``unreachable`` or ``failed``
(the last safe joints).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from ..common.checks import choice, rotation_matrix
from ..errors import InputError
from ..model.ik import inverse_kinematics
from ..model.robot import Robot
from .conventions import (
    MARKER_CONVENTIONS,
    MarkerConvention,
    method_observation,
    observation_rotation,
)
from .problem import TrackingProblem
from .solver import GaussNewtonSolver, NlpsolSolver, SolveOutcome, bind_buffer

#: ``step`` answers ``ok`` only below these errors: position [m] and angle [rad].
POSITION_TOLERANCE = 1e-6
ANGLE_TOLERANCE = 1e-6
#: Random restarts of the inverse kinematics that seeds a cycle the warm start cannot solve.
IK_RESTARTS = 4
#: How far outside a bound [rad or m] a verified answer may sit (rounding) before clipping.
BOUND_TOLERANCE = 1e-12
STATUSES = ("ok", "limited", "unreachable", "failed")
TrackingMethod = Literal["gauss_newton", "sqpmethod", "ipopt"]
QpSolver = Literal["qrqp", "qpoases"]
METHODS: tuple[TrackingMethod, ...] = get_args(TrackingMethod)
QPSOLS: tuple[QpSolver, ...] = get_args(QpSolver)


@dataclass(frozen=True)
class TrackStep:
    """One cycle's answer.

    ``q`` (n, read-only) the joints to command [rad or m], SI; the last safe joints when
    ``status`` is ``unreachable`` or ``failed``. ``status`` is ``ok`` (the goal is met),
    ``limited`` (the goal is reachable but farther than the step bound allows: ``q`` is
    the bounded step towards it, and the errors are those of that step), ``unreachable``
    (no solution within the joint limits, found from the previous joints nor from inverse
    kinematics) or ``failed`` (the solver gave no verified answer, or the observation was
    not finite). ``solve_ms`` [ms] is the whole
    cycle (goal, solve, verification). ``constraint_error`` is the larger of
    ``position_error`` [m] and ``angle_error`` [rad] of the solver's answer (NaN when
    none was computed); ``iterations`` the solver's iterations.
    """

    q: np.ndarray
    status: str
    solve_ms: float
    constraint_error: float
    position_error: float = math.nan
    angle_error: float = math.nan
    iterations: int = 0

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def __repr__(self) -> str:
        joints = ", ".join(f"{v:.6g}" for v in self.q)
        return (f"TrackStep(status={self.status!r}, q=[{joints}], solve_ms={self.solve_ms:.3f}, "
                f"constraint_error={self.constraint_error:.3g}, iterations={self.iterations})")


def _vector(value, length: int, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=float).ravel()
    if array.shape != (length,):
        raise InputError(f"expected {length} values, got shape {np.shape(value)}", where=name)
    return array


def unit_up(up: Sequence[float] | np.ndarray, *, file=None, where: str = "up") -> np.ndarray:
    """The worktable normal as a unit vector; zero or non-finite is an ``InputError``."""
    vector = np.asarray(up, dtype=float).ravel()
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise InputError(f"expected 3 finite numbers, got {up!r}", file=file, where=where)
    norm = float(np.linalg.norm(vector))
    if norm < 1e-12:
        raise InputError("the worktable normal must not be zero", file=file, where=where)
    return vector / norm


def reach_bound(robot: Robot, p: np.ndarray | None = None) -> float:
    """An upper bound [m] on the distance from the joint-1 frame origin to the end origin.

    Sum over links of ``sqrt(a^2 + d^2)`` (a prismatic joint at its farthest reading),
    plus the tool offset.
    """
    model = robot if p is None else robot.with_parameters(p)
    return model.reach()


class Tracker:
    """Real-time tracking of a target seen by a camera on the end frame.

    ``robot`` the arm (at least 6 joints); ``camera_xyz`` [m] the camera origin in the end
    frame (axes parallel to it); ``standoff`` Z [m] > 0, the target is held at
    ``(0, 0, Z)`` in the end frame; ``up`` the worktable normal in the world frame
    (normalised here); ``max_step`` the largest joint move per cycle [rad or m], one value
    or one per joint, None for none; ``p`` the geometric parameter vector
    (``ParameterRegistry`` order, SI; default the robot's own); ``weights`` (n) the
    weights of the smallest-move objective (default 1); ``method`` the NLP solver:
    ``gauss_newton`` (real-time), ``sqpmethod`` or ``ipopt`` (references); ``qpsol`` the
    QP solver of ``sqpmethod`` (``qrqp`` or ``qpoases``); ``compiled`` runs the per-cycle
    CasADi functions as machine code (compiled once per robot structure and cached on
    disk, see ``codegen``); ``problem`` a ``TrackingProblem`` of the same robot structure
    to share; ``camera_rotation`` (3x3) the camera axes in the end frame (hand-eye; default
    parallel to it); ``marker_convention`` how an observation's orientation reads:
    ``method`` ``(x, y, z [m], roll, pitch, yaw [rad])`` of the target frame, or
    ``opencv`` ``(tvec [m], rvec [rad])`` of an OpenCV/ArUco marker
    (``tracking.conventions``); ``seed_from_ik`` lets a cycle that the warm start cannot
    solve start again from inverse kinematics of the goal pose (a first capture far from
    the answer, a target that jumped).

    Of the joints that meet the goal, the answer is the one nearest the previous answer
    (weighted): each revolute joint on its nearest whole turn within its limits, and the
    last joint on its nearest half turn where that turns the end frame about its own z
    axis (the level x axis may point either way). With ``max_step``, a goal that needs
    a larger move is approached by the largest step allowed along the straight line in
    joint space (status ``limited``), and met in later cycles.

    In a control loop::

        tracker = Tracker(robot, camera_xyz=[0.05, 0, 0.02], standoff=0.3)
        while running:
            step = tracker.step(q_capture, [x, y, z, roll, pitch, yaw])
            if step.ok:
                command(step.q)
    """

    def __init__(self, robot: Robot, camera_xyz: Sequence[float] | np.ndarray, standoff: float,
                 up: Sequence[float] | np.ndarray = (0.0, 0.0, 1.0),
                 max_step: float | Sequence[float] | None = None,
                 p: np.ndarray | None = None, *, weights: Sequence[float] | None = None,
                 method: TrackingMethod = "gauss_newton", qpsol: QpSolver = "qrqp",
                 compiled: bool = True,
                 problem: TrackingProblem | None = None, seed_from_ik: bool = True,
                 camera_rotation: Sequence[Sequence[float]] | None = None,
                 marker_convention: MarkerConvention = "method"):
        if robot.dof < 6:
            raise InputError(f"tracking needs at least 6 joints (three position and three "
                             f"orientation conditions); robot {robot.name!r} has {robot.dof}")
        method = choice(method, METHODS, "method")
        qpsol = choice(qpsol, QPSOLS, "qpsol")
        self.robot = robot
        self.problem = problem if problem is not None else TrackingProblem(robot)
        n = robot.dof
        self.camera_xyz = _vector(camera_xyz, 3, "camera_xyz")
        if not np.all(np.isfinite(self.camera_xyz)):
            raise InputError(f"expected finite numbers, got {camera_xyz!r}", where="camera_xyz")
        self.standoff = _positive_standoff(standoff)
        self.up = unit_up(up)
        self.marker_convention = choice(marker_convention, MARKER_CONVENTIONS,
                                        "marker_convention")
        self.camera_rotation = (np.eye(3) if camera_rotation is None
                                else rotation_matrix(camera_rotation, "camera_rotation"))
        # The method's own description needs no conversion per cycle.
        self._converts = (self.marker_convention != "method"
                          or not np.array_equal(self.camera_rotation, np.eye(3)))
        self.max_step = _positive_steps(max_step, n)
        self.p = (robot.parameter_vector() if p is None
                  else _vector(p, self.problem.parameter_count, "p"))
        self.weights = np.ones(n) if weights is None else _vector(weights, n, "weights")
        if np.any(self.weights <= 0) or not np.all(np.isfinite(self.weights)):
            raise InputError(f"weights must be positive, got {list(self.weights)}",
                             where="weights")
        self.method = method
        self.seed_from_ik = bool(seed_from_ik)
        self.solver: GaussNewtonSolver | NlpsolSolver
        if method == "gauss_newton":
            self.solver = GaussNewtonSolver(self.problem, self.p, self.up, self.weights,
                                            compiled=compiled)
        else:
            self.solver = NlpsolSolver(self.problem, self.p, self.up, self.weights,
                                       plugin=method, qpsol=qpsol)
        self.lower = robot.lower_limits
        self.upper = robot.upper_limits
        self.revolute = np.array([j.revolute for j in robot.joints])
        self.reach = reach_bound(robot, self.p)
        self._base_origin = np.asarray(
            self.problem.kinematics.joint_frames(np.zeros(n), self.p)[0])[:3, 3]
        self._previous: np.ndarray | None = None
        self._bind_goal(compiled)

    def _bind_goal(self, compiled: bool) -> None:
        """The goal function through the buffer interface: its arrays bound once."""
        n = self.robot.dof
        self._goal_in = [np.zeros(n), np.zeros(6), self.p.copy(), self.camera_xyz.copy(),
                         np.array([self.standoff]), self.up.copy()]
        self._goal_out = np.zeros(12)
        self._goal_function = self.problem.compiled_goal if compiled else self.problem.goal
        self._goal_buffer, self._goal_evaluate = self._goal_function.buffer()
        bind_buffer(self._goal_buffer, self._goal_in, (self._goal_out,))

    def __repr__(self) -> str:
        steps = None if self.max_step is None else list(self.max_step)
        return (f"Tracker({self.robot.name!r}, camera_xyz={list(self.camera_xyz)}, "
                f"standoff={self.standoff} m, up={list(self.up)}, max_step={steps}, "
                f"method={self.method!r})")

    # ------------------------------------------------------------------ state

    @property
    def previous(self) -> np.ndarray | None:
        """The last safe joints [rad or m] (None before the first step)."""
        return None if self._previous is None else self._previous.copy()

    def reset(self, q: Sequence[float] | None = None) -> None:
        """Forget the history; the next step starts from ``q`` (default: its capture joints)."""
        if q is None:
            self._previous = None
            return
        self._previous = _vector(q, self.robot.dof, "q").copy()
        self._previous.setflags(write=False)

    # ------------------------------------------------------------------ one cycle

    def goal(self, q_capture: Sequence[float], observation: Sequence[float]) -> np.ndarray:
        """The levelled goal end pose ``A''`` (4x4, world frame) [m] of one observation."""
        vector = self._goal_vector(_vector(q_capture, self.robot.dof, "q_capture"),
                                   _vector(observation, 6, "observation"))
        pose = np.eye(4)
        pose[:3, 3] = vector[0:3]
        pose[:3, 0], pose[:3, 1], pose[:3, 2] = vector[3:6], vector[6:9], vector[9:12]
        return pose

    def _goal_vector(self, q_capture: np.ndarray, observation: np.ndarray) -> np.ndarray:
        if self._converts:
            observation = method_observation(
                self.camera_xyz, self.camera_rotation, observation[:3],
                observation_rotation(observation, self.marker_convention),
                self.marker_convention)
        self._goal_in[0][:] = q_capture
        self._goal_in[1][:] = observation
        self._goal_evaluate()
        return self._goal_out

    def step(self, q_capture: Sequence[float] | np.ndarray,
             observation: Sequence[float] | np.ndarray, *,
             max_step: Sequence[float] | np.ndarray | None = None) -> TrackStep:
        """One cycle: joints facing the target from the standoff, level, closest to the
        previous answer.

        ``q_capture`` (n) [rad or m] the joints when the image was taken; ``observation``
        ``(x, y, z [m], roll, pitch, yaw [rad])`` the target in the camera; ``max_step``
        (n) [rad or m] this cycle's largest move per joint (e.g. the speed limits times
        the cycle time), combined with the tracker's own by the smaller of the two.
        """
        start = time.perf_counter()
        steps = self._cycle_steps(max_step)
        q_read = _vector(q_capture, self.robot.dof, "q_capture")
        target = _vector(observation, 6, "observation")
        finite = bool(np.isfinite(q_read).all() and np.isfinite(target).all())
        if self._previous is None:
            if not np.isfinite(q_read).all():
                raise InputError("the first capture joints must be finite", where="q_capture")
            self._previous = np.minimum(np.maximum(q_read, self.lower), self.upper)
            self._previous.setflags(write=False)
        previous = self._previous
        if not finite:
            return self._refuse("failed", start)
        goal = self._goal_vector(q_read, target)
        if math.dist(goal[0:3], self._base_origin) > self.reach:
            return self._refuse("unreachable", start)
        lower, upper = self.lower, self.upper
        if steps is not None:
            lower = np.maximum(lower, previous - steps)
            upper = np.minimum(upper, previous + steps)
        outcome = self.solver.solve(previous, goal, lower, upper)
        q, position_error, angle_error, verified = self._settle(outcome, previous, goal, lower,
                                                                upper)
        iterations = outcome.iterations
        status = "ok"
        if not verified:
            # Nothing meets the goal near the previous joints (within the step bound, if
            # any): look for the goal within the joint limits alone, from the previous
            # joints and then from inverse kinematics, and approach it by a bounded step.
            far, iterations_far = self._search(previous, goal, steps)
            iterations += iterations_far
            if far is None:
                status = "unreachable" if outcome.infeasible or self.seed_from_ik else "failed"
                q = previous
            else:
                q, position_error, angle_error, status = self._approach(previous, far, goal,
                                                                        steps)
        if status in ("ok", "limited"):
            q.setflags(write=False)  # shared by the answer and the tracker's memory
            self._previous = q
        constraint_error = max(position_error, angle_error)
        return TrackStep(q, status, (time.perf_counter() - start) * 1e3, constraint_error,
                         position_error, angle_error, iterations)

    def _approach(self, previous: np.ndarray, far: tuple[np.ndarray, float, float],
                  goal: np.ndarray, steps: np.ndarray | None
                  ) -> tuple[np.ndarray, float, float, str]:
        """``(q, position error [m], angle error [rad], status)`` of a move towards the
        joints ``far`` found within the limits alone: all the way (``ok``), or the
        largest step the bound allows along the straight line (``limited``)."""
        q, position_error, angle_error = far
        if steps is not None:
            move = np.abs(q - previous)
            share = float(np.min(np.where(move > 0, steps / np.where(
                move > 0, move, 1.0), np.inf), initial=1.0))
            if share < 1.0:
                q = previous + share * (q - previous)
                np.maximum(q, self.lower, out=q)
                np.minimum(q, self.upper, out=q)
                errors = self.problem.errors(q, goal, self.up, self.p)
                return q, float(errors[0]), float(errors[1]), "limited"
        return q, position_error, angle_error, "ok"

    def _cycle_steps(self, max_step) -> np.ndarray | None:
        """This cycle's step bound (n) [rad or m]: the smaller of the tracker's and
        ``max_step`` (non-negative; zero holds the joint), None for neither."""
        if max_step is None:
            return self.max_step
        steps = _vector(max_step, self.robot.dof, "max_step")
        if not (np.all(np.isfinite(steps)) and np.all(steps >= 0)):
            raise InputError(f"max_step must be non-negative, got {list(steps)}",
                             where="max_step")
        return steps if self.max_step is None else np.minimum(steps, self.max_step)

    def _settle(self, outcome: SolveOutcome, previous: np.ndarray, goal: np.ndarray,
                lower: np.ndarray, upper: np.ndarray
                ) -> tuple[np.ndarray, float, float, bool]:
        """The solver's answer on its nearest equivalent branch, verified: ``(q,
        position_error [m], angle_error [rad], verified)``; ``q`` is clipped into the
        bounds when verified."""
        q = self._nearest_branch(outcome.q, previous, lower, upper, goal)
        position_error, angle_error = outcome.position_error, outcome.angle_error
        if q is not outcome.q:
            errors = self.problem.errors(q, goal, self.up, self.p)
            position_error, angle_error = float(errors[0]), float(errors[1])
        verified = (position_error < POSITION_TOLERANCE and angle_error < ANGLE_TOLERANCE
                    and bool((q >= lower - BOUND_TOLERANCE).all())
                    and bool((q <= upper + BOUND_TOLERANCE).all()))
        if verified:
            q = np.minimum(np.maximum(q, lower), upper)
        return q, position_error, angle_error, verified

    def _search(self, previous: np.ndarray, goal: np.ndarray, steps: np.ndarray | None
                ) -> tuple[tuple[np.ndarray, float, float] | None, int]:
        """Joints meeting ``goal`` within the joint limits (no step bound), smallest move
        from ``previous`` near where they were found: ``((q, position_error,
        angle_error) or None, iterations)``.

        First the warm start without the step bound (when there is one), then inverse
        kinematics of the goal pose and of it turned half about its z axis, each refined
        by the tracking solver towards the smallest move (kept as found where the
        refinement does not verify, e.g. a redundant arm stopped by a limit).
        """
        iterations = 0
        if steps is not None:
            outcome = self.solver.solve(previous, goal, self.lower, self.upper)
            iterations += outcome.iterations
            q, position_error, angle_error, verified = self._settle(
                outcome, previous, goal, self.lower, self.upper)
            if verified:
                return (q, position_error, angle_error), iterations
        if not self.seed_from_ik:
            return None, iterations
        found = []
        for seed in self._ik_solutions(previous, goal):
            outcome = self.solver.solve(previous, goal, self.lower, self.upper, start=seed)
            iterations += outcome.iterations
            settled = self._settle(outcome, previous, goal, self.lower, self.upper)
            if not settled[3]:
                errors = self.problem.errors(seed, goal, self.up, self.p)
                as_found = SolveOutcome(seed, True, False, 0, float(errors[0]),
                                        float(errors[1]))
                settled = self._settle(as_found, previous, goal, self.lower, self.upper)
            if settled[3]:
                found.append(settled[:3])
        if not found:
            return None, iterations
        return min(found, key=lambda f: float(self.weights @ (f[0] - previous) ** 2)), iterations

    def _ik_solutions(self, previous: np.ndarray, goal: np.ndarray) -> list[np.ndarray]:
        """Inverse kinematics within the joint limits of the goal pose ``A''`` and of
        ``A'' Rz(pi)`` (the level x axis the other way), started from ``previous``, then
        from random joints (fixed seed: repeatable)."""
        pose = np.eye(4)
        pose[:3, 3] = goal[0:3]
        pose[:3, 0], pose[:3, 1], pose[:3, 2] = goal[3:6], goal[6:9], goal[9:12]
        flipped = pose.copy()
        flipped[:3, 0:2] *= -1.0
        solver = inverse_kinematics(self.problem.kinematics, "pose")
        out = []
        for target in (pose, flipped):
            result = solver.solve(target, seed=previous, p=self.p, restarts=IK_RESTARTS, rng=0,
                                  position_tolerance=POSITION_TOLERANCE * 1e-3,
                                  orientation_tolerance=ANGLE_TOLERANCE * 1e-3)
            if result.success:
                out.append(result.q)
        return out

    def _refuse(self, status: str, start: float) -> TrackStep:
        assert self._previous is not None  # set by ``step`` before any refusal
        return TrackStep(self._previous, status, (time.perf_counter() - start) * 1e3,
                         math.nan)

    def _nearest_branch(self, q: np.ndarray, previous: np.ndarray, lower: np.ndarray,
                        upper: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The equivalent joints nearest ``previous`` within the bounds.

        The constraints are 2 pi periodic in every revolute joint; when the last joint
        turns the end frame about its own z axis, a half turn of it keeps the goal too
        (the x axis stays level, pointing the other way), checked here rather than
        assumed. The weighted move is a sum over joints, so each joint takes its nearest
        equivalent value on its own. Returns ``q`` itself when nothing is nearer.
        """
        move = np.abs(previous - q)
        if float(move.max()) <= math.pi / 2:
            return q
        period = np.where(self.revolute, 2 * math.pi, 0.0)
        last = self.robot.dof - 1
        if self.revolute[last] and move[last] > math.pi / 2:
            flipped = q.copy()
            flipped[last] += math.pi
            errors = self.problem.errors(flipped, goal, self.up, self.p)
            if float(errors[0]) < POSITION_TOLERANCE and float(errors[1]) < ANGLE_TOLERANCE:
                period[last] = math.pi
        moved = q.copy()
        for j in np.flatnonzero(period > 0):
            turns = np.round((previous[j] - q[j]) / period[j])
            for k in (turns, turns - 1, turns + 1):  # the nearest that fits the bounds
                value = q[j] + k * period[j]
                if lower[j] <= value <= upper[j] and abs(value - previous[j]) < abs(
                        moved[j] - previous[j]):
                    moved[j] = value
        return q if np.array_equal(moved, q) else moved


def _positive_standoff(standoff: float) -> float:
    """The standoff Z [m], refused unless a positive finite length."""
    standoff = float(standoff)
    if not (math.isfinite(standoff) and standoff > 0):
        raise InputError(f"the standoff must be a positive length, got {standoff}",
                         where="standoff")
    return standoff


def _positive_steps(max_step: float | Sequence[float] | None, n: int) -> np.ndarray | None:
    """``max_step`` (one value or ``n``) as ``n`` positive bounds [rad or m], or None."""
    if max_step is None:
        return None
    try:
        steps = np.broadcast_to(np.asarray(max_step, dtype=float), (n,)).copy()
    except ValueError:
        raise InputError(f"expected one value or {n}, got {max_step!r}",
                         where="max_step") from None
    if not (np.all(np.isfinite(steps)) and np.all(steps > 0)):
        raise InputError(f"max_step must be positive, got {max_step}",
                         where="max_step")
    return steps
