"""Numerical inverse kinematics on the CasADi kinematics, with joint limits.

Three modes, each built once per ``Kinematics`` and cached:

* ``"pose"``: the tool frame ``T_world_tool`` onto a target pose (4x4, [m]);
* ``"flange_pose"``: the flange frame ``T_world_flange`` onto a target pose;
* ``"point"``: a point fixed in the flange frame (``offset`` [m]) onto a target
  position [m] in the world, with an optional preferred flange orientation that is
  soft: the position is met exactly, and of the joint values that meet it the solver
  settles near the one whose flange orientation is closest to the preferred one.

The residual is ``[p(q) - p_target; w (vec R(q) - vec R_target) / sqrt 2]`` (position
[m], orientation in the chordal metric, ``|R - R_target|_F / sqrt 2 = 2 sin(angle / 2)``
[rad]). Two solvers:

* ``"lm"`` (default): Levenberg-Marquardt with exact CasADi Jacobians, steps projected
  onto the joint limits and joints held at an active limit left out of the step;
* ``"ipopt"``: the same least-squares problem handed to IPOPT with the limits as bounds
  (point mode with a preferred orientation: the position as an equality constraint).

``benchmarks/ik.py`` measures both on the same targets, seeds and restarts: both solve
every reachable target to 1e-10 m, and LM takes 1.4 to 15 times less time per target
(IPOPT's interior-point machinery costs more than a few damped Gauss-Newton steps on a
6- or 7-unknown problem), so LM is the default.

The iterations run on ``common.exact``'s algebra, not BLAS: a solve gives the same joint
values to the last bit on every processor, so simulated readings and the branch kept do not
depend on the machine.

Every solve is honest: ``IKResult.success`` is True only when the reached errors are
within the tolerances; an unreachable target returns the best joint values found with
``success=False`` and the remaining errors. ``p`` (geometric parameters, registry order,
SI) defaults to the nominal robot, so a calibrated model works the same way.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..common import exact
from ..common.checks import array, choice, count, positive
from ..common.least_squares import Damping, Tolerances, levenberg_marquardt
from ..errors import InputError
from .kinematics import Kinematics

MODES = ("pose", "flange_pose", "point")
METHODS = ("lm", "ipopt")
POSITION_TOLERANCE = 1e-10  # [m]
ORIENTATION_TOLERANCE = 1e-10  # [rad]
DEFAULT_ORIENTATION_WEIGHT = 0.1  # [m/rad], the soft preference in point mode
STALL_WINDOW = 8  # LM stops when the cost fell by less than STALL_DECREASE over this many steps
STALL_DECREASE = 1e-3
STEP_TOLERANCE = 1e-15  # step relative to the joints, at rounding level
# Joint angles share one unit, so Levenberg's damping (mu I) keeps the step's direction in
# joint space; the gentle start and slow release let the search stay on the branch the
# seed is nearest to.
JOINT_DAMPING = Damping(scaling="identity", initial=1e-6, decrease=5.0)
SEED_SPAN_PRISMATIC = 1.0  # [m] half-width of random seeds of a prismatic joint without limits


@dataclass(frozen=True)
class IKResult:
    """One inverse-kinematics solve.

    ``q`` joint values [rad or m]; ``position_error`` [m] distance from the target
    position; ``orientation_error`` [rad] angle to the target orientation (pose modes) or
    to the preferred orientation (point mode; NaN without one; it does not decide
    success there); ``iterations`` summed over restarts; ``message`` says why it stopped.
    """

    q: np.ndarray
    success: bool
    position_error: float
    orientation_error: float
    iterations: int
    message: str

    def __repr__(self) -> str:
        q = np.array2string(np.asarray(self.q), precision=6, separator=", ")
        return (f"IKResult(success={self.success}, position_error={self.position_error:.3g} m, "
                f"orientation_error={self.orientation_error:.3g} rad, "
                f"iterations={self.iterations}, q={q}, message={self.message!r})")


@dataclass(frozen=True)
class IKBatchResult:
    """Many solves: arrays with one row per target (see ``IKResult`` for the units)."""

    q: np.ndarray  # (N, dof)
    success: np.ndarray  # (N,) bool
    position_error: np.ndarray  # (N,) [m]
    orientation_error: np.ndarray  # (N,) [rad]
    iterations: np.ndarray  # (N,)
    messages: tuple[str, ...] = field(repr=False, default=())

    def __len__(self) -> int:
        return len(self.success)

    def __repr__(self) -> str:
        return (f"IKBatchResult({len(self)} targets, {int(np.sum(self.success))} solved, "
                f"max position_error={np.nanmax(self.position_error, initial=0.0):.3g} m)")


def orientation_angle(R: np.ndarray, R_target: np.ndarray) -> float:
    """Angle [rad] of ``R_target^T R``, accurate near zero (from the chordal distance)."""
    chord = exact.norm(np.asarray(R) - np.asarray(R_target)) / (2.0 * math.sqrt(2.0))
    return 2.0 * math.asin(min(1.0, float(chord)))


class InverseKinematics:
    """IK of one ``Kinematics`` in one mode with one method; get it from ``inverse_kinematics``."""

    def __init__(self, kinematics: Kinematics, mode: str = "pose", method: str = "lm"):
        mode = choice(mode, MODES, "mode")
        method = choice(method, METHODS, "method")
        self.kinematics = kinematics
        self.mode = mode
        self.method = method
        self._residual = self._build_residual()
        self._ipopt: dict[bool, ca.Function] = {}

    def __repr__(self) -> str:
        return f"InverseKinematics({self.kinematics!r}, mode={self.mode!r}, method={self.method!r})"

    # ------------------------------------------------------------------ CasADi functions

    def _build_residual(self) -> ca.Function:
        """``(q, parameters) -> (r, J)``, r = [3 position; 9 orientation], J = dr/dq.

        ``parameters`` packs ``[p; position (3); rotation (9, column-major); offset (3);
        weight]`` (one input: a CasADi call costs about half as much as with six).
        """
        kin = self.kinematics
        n = len(kin.registry)
        q = ca.SX.sym("q", kin.dof)
        parameters = ca.SX.sym("parameters", n + 16)
        p = parameters[:n]
        position = parameters[n:n + 3]
        rotation = ca.reshape(parameters[n + 3:n + 12], 3, 3)
        offset = parameters[n + 12:n + 15]
        weight = parameters[n + 15]
        if self.mode == "pose":
            T = kin.tool_pose(q, p)
            reached = T[:3, 3]
        else:
            T = kin.flange_pose(q, p)
            reached = T[:3, :3] @ offset + T[:3, 3] if self.mode == "point" else T[:3, 3]
        r = ca.vertcat(reached - position,
                       weight * ca.vec(T[:3, :3] - rotation) / math.sqrt(2.0))
        return ca.Function(f"ik_residual_{self.mode}", [q, parameters], [r, ca.jacobian(r, q)],
                           ["q", "parameters"], ["r", "J"])

    @staticmethod
    def _pack(p, position, rotation, offset, weight) -> np.ndarray:
        return np.concatenate([p, position, np.asarray(rotation, dtype=float).ravel(order="F"),
                               offset, [weight]])

    def _ipopt_solver(self, constrained: bool) -> ca.Function:
        """IPOPT on ``0.5 |r|^2``; ``constrained``: position rows as equalities instead."""
        if constrained not in self._ipopt:
            q = ca.SX.sym("q", self.kinematics.dof)
            parameters = ca.SX.sym("parameters", self._residual.size1_in(1))
            r, _ = self._residual(q, parameters)
            if constrained:
                problem = {"x": q, "p": parameters, "f": 0.5 * ca.sumsqr(r[3:]), "g": r[:3]}
            else:
                problem = {"x": q, "p": parameters, "f": 0.5 * ca.sumsqr(r)}
            options: dict[str, Any] = {"print_time": False,
                       "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-16,
                                 "acceptable_tol": 1e-14, "max_iter": 300}}
            self._ipopt[constrained] = ca.nlpsol(f"ik_ipopt_{self.mode}", "ipopt", problem,
                                                 options)
        return self._ipopt[constrained]

    # ------------------------------------------------------------------ solving

    def solve(self, target, *, seed=None, p=None, offset=None, orientation=None,
              orientation_weight: float = DEFAULT_ORIENTATION_WEIGHT, bounds=None,
              restarts: int = 0, rng: np.random.Generator | int | None = None,
              position_tolerance: float = POSITION_TOLERANCE,
              orientation_tolerance: float = ORIENTATION_TOLERANCE,
              max_iterations: int = 200) -> IKResult:
        """Joint values that put the tool / flange / flange point on ``target``.

        ``target``: a 4x4 pose [m] (pose modes) or a position (3,) [m] (point mode), world
        frame. ``seed`` (dof,) start [rad or m], default the middle of the limits.
        ``p`` geometric parameters (registry order, SI), default nominal. ``offset`` (3,) [m]
        the flange-frame point (point mode). ``orientation`` (3x3) preferred flange
        orientation (point mode, soft, weight ``orientation_weight`` [m/rad] while
        converging). ``bounds`` ``(lower, upper)`` [rad or m], default the robot's limits.
        ``restarts``: further tries from random seeds within the bounds if the first
        fails (``rng`` a Generator or an int seed); with a preferred orientation they also
        run while the orientation is off by more than ``orientation_tolerance``, and the
        closest of the successful starts is kept.
        """
        kin = self.kinematics
        restarts = count(restarts, "restarts", minimum=0)
        max_iterations = count(max_iterations, "max_iterations")
        position_tolerance = positive(position_tolerance, "position_tolerance")
        orientation_tolerance = positive(orientation_tolerance, "orientation_tolerance")
        if seed is not None:
            seed = array(seed, (kin.dof,), "seed")
        p = kin.nominal if p is None else np.asarray(p, dtype=float)
        lower, upper = self._bounds(bounds)
        position, rotation, weight, soft = self._target(target, orientation, orientation_weight)
        offset = np.zeros(3) if offset is None else np.asarray(offset, dtype=float).reshape(3)
        if seed is None:
            seed = self._middle(lower, upper)
        seed = np.clip(np.asarray(seed, dtype=float).reshape(kin.dof), lower, upper)
        generator = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        args = (p, position, rotation, offset, weight, soft, lower, upper, position_tolerance,
                orientation_tolerance, max_iterations)
        best: IKResult | None = None
        iterations = 0
        for attempt in range(restarts + 1):
            start = seed if attempt == 0 else self._random_seed(generator, lower, upper)
            result = self._solve_once(start, *args)
            iterations += result.iterations
            if best is None or _better(result, best):
                best = result
            if best.success and not (soft and best.orientation_error > orientation_tolerance):
                break  # with a preferred orientation, further starts may come closer to it
        assert best is not None
        message = best.message if restarts == 0 else f"{best.message} ({attempt + 1} start(s))"
        return IKResult(best.q, best.success, best.position_error, best.orientation_error,
                        iterations, message)

    def solve_batch(self, targets, *, seeds=None, warm_start: bool = True, **options
                    ) -> IKBatchResult:
        """``solve`` for each target (``(N, 4, 4)`` poses or ``(N, 3)`` positions).

        ``seeds`` (N, dof) or one (dof,) seed for all; without per-row seeds and with
        ``warm_start`` each solve starts from the previous solution when that succeeded.
        ``options`` are those of ``solve`` (``offset``, ``orientation`` may be per row:
        ``orientation`` (N, 3, 3)).
        """
        targets = np.asarray(targets, dtype=float)
        count = len(targets)
        dof = self.kinematics.dof
        per_row_seeds = seeds is not None and np.ndim(seeds) == 2
        orientation = options.pop("orientation", None)
        per_row_orientation = orientation is not None and np.ndim(orientation) == 3
        Q = np.full((count, dof), np.nan)
        success = np.zeros(count, dtype=bool)
        position_error = np.full(count, np.nan)
        orientation_error = np.full(count, np.nan)
        iterations = np.zeros(count, dtype=int)
        messages = []
        previous = None if seeds is None or per_row_seeds else np.asarray(seeds, dtype=float)
        for i in range(count):
            seed = np.asarray(seeds)[i] if per_row_seeds else previous
            rotation = orientation[i] if per_row_orientation else orientation
            result = self.solve(targets[i], seed=seed, orientation=rotation, **options)
            Q[i] = result.q
            success[i] = result.success
            position_error[i] = result.position_error
            orientation_error[i] = result.orientation_error
            iterations[i] = result.iterations
            messages.append(result.message)
            if warm_start and result.success and not per_row_seeds:
                previous = result.q
        return IKBatchResult(Q, success, position_error, orientation_error, iterations,
                             tuple(messages))

    # ------------------------------------------------------------------ internals

    def _bounds(self, bounds) -> tuple[np.ndarray, np.ndarray]:
        robot = self.kinematics.robot
        if bounds is None:
            return robot.lower_limits.astype(float), robot.upper_limits.astype(float)
        lower, upper = (np.asarray(b, dtype=float).reshape(robot.dof) for b in bounds)
        if np.any(lower > upper):
            raise InputError(f"IK bounds: lower {lower} above upper {upper}")
        return lower, upper

    def _target(self, target, orientation, orientation_weight):
        target = np.asarray(target, dtype=float)
        if self.mode == "point":
            if target.shape != (3,):
                raise InputError("point IK target must be a position (3,), got shape "
                                 f"{target.shape}")
            if orientation is None:
                return target, np.eye(3), 0.0, False
            return target, np.asarray(orientation, dtype=float).reshape(3, 3), float(
                orientation_weight), True
        if target.shape != (4, 4):
            raise InputError(f"{self.mode} IK target must be a 4x4 pose, got shape {target.shape}")
        if orientation is not None:
            raise InputError("'orientation' applies to point mode only; the pose holds it")
        return target[:3, 3], target[:3, :3], 1.0, False

    def _middle(self, lower, upper) -> np.ndarray:
        lo, hi = self._seed_box(lower, upper)
        return 0.5 * (lo + hi)

    def _seed_box(self, lower, upper):
        span = np.array([math.pi if j.revolute else SEED_SPAN_PRISMATIC
                         for j in self.kinematics.robot.joints])
        lo = np.where(np.isfinite(lower), lower, np.minimum(-span, upper - 2 * span))
        hi = np.where(np.isfinite(upper), upper, np.maximum(span, lo + 2 * span))
        return lo, hi

    def _random_seed(self, generator, lower, upper) -> np.ndarray:
        lo, hi = self._seed_box(lower, upper)
        return generator.uniform(lo, hi)

    def _wrap(self, q, lower, upper) -> np.ndarray:
        """Revolute joints shifted by whole turns to lie within the limits where possible."""
        q = np.array(q, dtype=float)
        for i, joint in enumerate(self.kinematics.robot.joints):
            if not joint.revolute:
                continue
            centre = 0.5 * (lower[i] + upper[i]) if np.isfinite(lower[i] + upper[i]) else 0.0
            shifted = q[i] - 2 * math.pi * round((q[i] - centre) / (2 * math.pi))
            if lower[i] <= shifted <= upper[i]:
                q[i] = shifted
            else:
                for turns in (-1, 1):
                    if lower[i] <= shifted + 2 * math.pi * turns <= upper[i]:
                        q[i] = shifted + 2 * math.pi * turns
                        break
        return q

    def _errors(self, r: np.ndarray, weight: float) -> tuple[float, float]:
        position_error = exact.norm(r[:3])
        if weight == 0.0:
            return position_error, math.nan
        chord = exact.norm(r[3:]) / weight / 2.0  # = sin(angle / 2)
        return position_error, 2.0 * math.asin(min(1.0, float(chord)))

    def _closer(self, q_a, q_b, p, position, rotation, offset, weight) -> bool:
        """Whether ``q_a`` reaches the target better than ``q_b`` (position first, then
        the orientation, as ``_better`` orders results)."""
        w = 1.0 if weight else 0.0
        packed = self._pack(p, position, rotation, offset, w)
        a = self._errors(np.asarray(self._residual(q_a, packed)[0]).ravel(), w)
        b = self._errors(np.asarray(self._residual(q_b, packed)[0]).ravel(), w)
        tolerance = POSITION_TOLERANCE
        if (a[0] <= tolerance) != (b[0] <= tolerance):
            return a[0] <= tolerance
        return (a[0] if a[0] > tolerance else 0.0, np.nan_to_num(a[1])) < (
            b[0] if b[0] > tolerance else 0.0, np.nan_to_num(b[1]))

    def _solve_once(self, seed, p, position, rotation, offset, weight, soft, lower, upper,
                    position_tolerance, orientation_tolerance, max_iterations) -> IKResult:
        if self.method == "ipopt":
            q, iterations, message = self._ipopt_once(seed, p, position, rotation, offset, weight,
                                                      soft, lower, upper, max_iterations)
        else:
            packed = {w: self._pack(p, position, rotation, offset, w) for w in {0.0, weight}}

            def evaluate(q, w):
                r, J = self._residual(q, packed[w])
                return r.full().ravel(), J.full()

            def run(start, low, high):
                if soft:
                    # converge with the orientation preference, then meet the position exactly
                    q, it1, _ = _levenberg_marquardt(lambda q: evaluate(q, weight), start, low,
                                                     high, max_iterations)
                    q, it2, why = _levenberg_marquardt(
                        lambda q: _position_rows(evaluate(q, 0.0)), q, low, high, max_iterations)
                    return q, it1 + it2, why
                rows = _position_rows if weight == 0.0 else (lambda rJ: rJ)
                return _levenberg_marquardt(lambda q: rows(evaluate(q, weight)), start, low, high,
                                            max_iterations)

            # Free first (limits trap the search on the wrong branch), then wrap revolute
            # joints by whole turns into the limits; bounded search only if that fails.
            free = np.full(self.kinematics.dof, np.inf)
            q, iterations, message = run(seed, -free, free)
            q = self._wrap(q, lower, upper)
            r_free = evaluate(q, 0.0)[0][:3] if weight == 0.0 or soft else evaluate(q, weight)[0]
            inside = bool(np.all((q >= lower) & (q <= upper)))
            if not (inside and exact.norm(r_free) <= 1e-12):
                # bounded search from where the free one ended (clipped), which keeps the
                # branch it found; from the seed if that does not reach the target
                q_clipped, more, message_clipped = run(np.clip(q, lower, upper), lower, upper)
                iterations += more
                q, more, message = run(seed, lower, upper)
                iterations += more
                if self._closer(q_clipped, q, p, position, rotation, offset, weight):
                    q, message = q_clipped, message_clipped
        r, _ = self._residual(q, self._pack(p, position, rotation, offset,
                                            1.0 if weight else 0.0))
        position_error, orientation_error = self._errors(np.asarray(r).ravel(),
                                                         1.0 if weight else 0.0)
        success = position_error <= position_tolerance and (
            soft or weight == 0.0 or orientation_error <= orientation_tolerance)
        if not success:
            message = (f"target not reached: position error {position_error:.3g} m, "
                       f"orientation error {orientation_error:.3g} rad ({message})")
        return IKResult(np.asarray(q, dtype=float), bool(success), position_error,
                        orientation_error, int(iterations), message)

    def _ipopt_once(self, seed, p, position, rotation, offset, weight, soft, lower, upper,
                    max_iterations):
        solver = self._ipopt_solver(soft)
        parameters = self._pack(p, position, rotation, offset, weight)
        kwargs = dict(x0=seed, p=parameters, lbx=lower, ubx=upper)
        if soft:
            kwargs.update(lbg=np.zeros(3), ubg=np.zeros(3))
        solution = solver(**kwargs)
        stats = solver.stats()
        q = np.clip(np.asarray(solution["x"]).ravel(), lower, upper)
        return q, int(stats.get("iter_count", 0)), f"ipopt: {stats.get('return_status')}"


def _position_rows(rJ):
    r, J = rJ
    return r[:3], J[:3]


def _better(candidate: IKResult, best: IKResult) -> bool:
    if candidate.success != best.success:
        return candidate.success
    return (candidate.position_error, np.nan_to_num(candidate.orientation_error)) < (
        best.position_error, np.nan_to_num(best.orientation_error))


def _levenberg_marquardt(evaluate, q0, lower, upper, max_iterations: int,
                         stop: float = 1e-14) -> tuple[np.ndarray, int, str]:
    """The shared kernel within ``[lower, upper]``; returns (q, iterations, reason).

    Steps are clipped onto the bounds; a joint at a bound whose descent direction points
    outwards is held for that step. Stops when ``|r| <= stop`` [m], when the cost stalls
    (``STALL_DECREASE`` over ``STALL_WINDOW`` steps), or after ``max_iterations``.
    """
    tolerances = Tolerances(xtol=STEP_TOLERANCE, residual_floor=stop,
                            stall=(STALL_WINDOW, STALL_DECREASE))
    fit = levenberg_marquardt(lambda q, jacobian: evaluate(q), q0, bounds=(lower, upper),
                              max_iterations=max_iterations, tolerances=tolerances,
                              damping=JOINT_DAMPING, reproducible=True)
    reason = fit.word if fit.status == 4 else f"{fit.word}: {fit.message}"
    return fit.x, fit.iterations, reason


_CACHE: weakref.WeakKeyDictionary[Kinematics, dict] = weakref.WeakKeyDictionary()


def inverse_kinematics(kinematics: Kinematics, mode: str = "pose",
                       method: str = "lm") -> InverseKinematics:
    """The cached ``InverseKinematics`` of ``kinematics`` for ``mode`` and ``method``."""
    per_kinematics = _CACHE.setdefault(kinematics, {})
    key = (mode, method)
    if key not in per_kinematics:
        per_kinematics[key] = InverseKinematics(kinematics, mode, method)
    return per_kinematics[key]


def solve_ik(kinematics: Kinematics, target, *, mode: str = "pose", method: str = "lm",
             **options) -> IKResult:
    """One solve; see ``InverseKinematics.solve`` for ``options``."""
    return inverse_kinematics(kinematics, mode, method).solve(target, **options)


def solve_ik_batch(kinematics: Kinematics, targets, *, mode: str = "pose", method: str = "lm",
                   **options) -> IKBatchResult:
    """Many solves; see ``InverseKinematics.solve_batch``."""
    return inverse_kinematics(kinematics, mode, method).solve_batch(targets, **options)


def random_joints(robot, count: int, rng: np.random.Generator,
                  margin: float = 0.0) -> np.ndarray:
    """``count`` joint vectors uniform within the limits shrunk by ``margin`` (fraction).

    Joints without limits draw from [-pi, pi] (revolute) or [-1, 1] m (prismatic).
    """
    span = np.array([math.pi if j.revolute else SEED_SPAN_PRISMATIC for j in robot.joints])
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -span)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, span)
    inset = margin * (upper - lower)
    return rng.uniform(lower + inset, upper - inset, size=(count, robot.dof))


__all__: Sequence[str] = ("IKResult", "IKBatchResult", "InverseKinematics", "inverse_kinematics",
                          "solve_ik", "solve_ik_batch", "random_joints", "orientation_angle")
