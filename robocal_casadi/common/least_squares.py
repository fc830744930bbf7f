"""One Levenberg-Marquardt kernel for every nonlinear least-squares fit in the package.

Minimises ``0.5 |r(x)|^2`` (``r`` in the caller's units, e.g. [m]). Each step solves the
damped normal equations, by default with Marquardt's scaling,

    (J^T J + mu diag(J^T J)) dx = -J^T r,

computed on the columns scaled to unit norm (``D = diag(|J_j|)``) so the system is well
scaled: ``(Js^T Js + mu I) D dx = -Js^T r``; Levenberg's ``J^T J + mu I`` (``D = I``) is the
choice for unknowns of one unit. ``mu`` starts at ``Damping.initial``, grows by
``increase`` after a step that raises the cost and shrinks by ``decrease`` after one that
does not; a step is sought until ``mu`` passes ``ceiling``, or until a refused step is
already below ``xtol`` with a predicted decrease within rounding of the cost (the
minimum, to rounding: status 3).

The state may live on a manifold: ``retract(x, dx)`` maps a step in the local
coordinates the Jacobian is taken in to a new state (default ``x + dx``), and
``coordinates(x)`` gives the state in those coordinates (default ``x``). Simple bounds
(vector states only) clip each step; an unknown at a bound whose descent points outwards
is held for that step.

Termination is reported as a status code with one message each (``STATUS``), in the
manner of ``scipy.optimize.least_squares``; codes above 0 are convergence.

``reproducible=True`` forms and solves the normal equations with ``common.exact`` instead
of BLAS / LAPACK: the same iterates to the last bit on every processor, for small problems
whose results are written or decide something (inverse kinematics in the simulator).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from . import exact

StatusWord = Literal["converged", "max_iterations", "stalled", "held"]

#: status code -> (word, message). Codes above 0 mean a minimum was reached.
STATUS: dict[int, tuple[StatusWord, str]] = {
    -2: ("held", "every unknown is held at a bound"),
    -1: ("stalled", "the cost fell by less than the stall fraction over the stall window"),
    0: ("max_iterations", "the iteration limit was reached"),
    1: ("converged", "the gradient is orthogonal to the residual within gtol"),
    2: ("converged", "an accepted step lowered the cost by less than ftol of itself"),
    3: ("converged", "the scaled step fell below xtol of the scaled state"),
    4: ("converged", "the residual fell to its floor (an exact fit)"),
    5: ("converged", "no damped step lowers the cost: the gradient vanishes to rounding"),
}

# An evaluation returns the residual and, when asked or when it comes for free, the
# Jacobian in the local coordinates of the state (None when not computed).
Evaluate = Callable[[Any, bool], tuple[np.ndarray, "np.ndarray | None"]]


@dataclass(frozen=True)
class Damping:
    """Damping schedule (dimensionless).

    ``scaling="marquardt"`` damps with ``diag(J^T J)``, for unknowns of mixed units (lengths
    and angles); ``"identity"`` with ``I`` (Levenberg), for unknowns of one unit, e.g.
    joint angles [rad], whose columns' sizes carry meaning.
    """

    scaling: Literal["marquardt", "identity"] = "marquardt"
    initial: float = 1e-4
    increase: float = 10.0  # factor after a step that raised the cost
    decrease: float = 10.0  # divisor after an accepted step
    floor: float = 1e-12
    ceiling: float = 1e12  # beyond this no step is sought: status 5


DAMPING = Damping()


@dataclass(frozen=True)
class Tolerances:
    """Stopping tests; a zero or None test is off (status codes in brackets).

    ``gtol`` [1]: every column's cosine with the residual (MINPACK's test) (1);
    ``ftol`` [1]: an accepted step's relative cost decrease (2);
    ``xtol`` [1]: ``|D dx| <= xtol (1 + |D x|)``, the scaled step against the scaled state
    (``D`` the column norms of ``J``, ``x`` the state's local coordinates) (3);
    ``residual_floor`` [residual units]: ``|r|`` at or below it (4);
    ``stall``: ``(window, fraction)``, the cost fell by less than ``fraction`` over the last
    ``window`` accepted steps (-1).
    """

    gtol: float = 0.0
    ftol: float = 0.0
    xtol: float = 0.0
    residual_floor: float = 0.0
    stall: tuple[int, float] | None = None


@dataclass(frozen=True)
class LeastSquaresResult:
    """Where the kernel stopped: state ``x``, residual and Jacobian there (the Jacobian is
    None when no step was taken from the last accepted state), ``cost = 0.5 |r|^2``,
    accepted steps, and the status code (see ``STATUS``)."""

    x: Any
    residual: np.ndarray = field(repr=False)
    jacobian: np.ndarray | None = field(repr=False)
    cost: float
    iterations: int
    status: int

    @property
    def word(self) -> StatusWord:
        """One word for the outcome: converged, max_iterations, stalled or held."""
        return STATUS[self.status][0]

    @property
    def message(self) -> str:
        return STATUS[self.status][1]

    @property
    def converged(self) -> bool:
        return self.status > 0


class _Blas:
    """The normal equations' algebra on NumPy's BLAS / LAPACK (fast; last bits per kernel)."""

    @staticmethod
    def normal(Js: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return Js.T @ Js, -(Js.T @ r)

    @staticmethod
    def project(J: np.ndarray, r: np.ndarray) -> np.ndarray:
        return J.T @ r

    @staticmethod
    def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
        return A @ x

    @staticmethod
    def dot(a: np.ndarray, b: np.ndarray) -> float:
        return float(a @ b)

    @staticmethod
    def norm(x: np.ndarray) -> float:
        return float(np.linalg.norm(x))

    @staticmethod
    def solve(A: np.ndarray, g: np.ndarray, Js: np.ndarray, r: np.ndarray,
              mu: float) -> np.ndarray:
        n = Js.shape[1]
        try:
            if mu > 0.0:
                return np.linalg.solve(A, g)
            L = np.linalg.cholesky(A)
            return np.linalg.solve(L.T, np.linalg.solve(L, g))
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(np.vstack([Js, np.sqrt(mu) * np.eye(n)]),
                                   np.concatenate([-r, np.zeros(n)]), rcond=None)[0]


class _Exact(_Blas):
    """The same on ``common.exact``: identical bits on every processor and kernel."""

    @staticmethod
    def normal(Js: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return exact.gram(Js), -exact.transpose_times(Js, r)

    @staticmethod
    def project(J: np.ndarray, r: np.ndarray) -> np.ndarray:
        return exact.transpose_times(J, r)

    @staticmethod
    def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
        return exact.matmul(A, x)

    @staticmethod
    def dot(a: np.ndarray, b: np.ndarray) -> float:
        return exact.dot(a, b)

    @staticmethod
    def norm(x: np.ndarray) -> float:
        return exact.norm(x)

    @staticmethod
    def solve(A: np.ndarray, g: np.ndarray, Js: np.ndarray, r: np.ndarray,
              mu: float) -> np.ndarray:
        try:
            return exact.solve(A, g)
        except exact.SingularMatrix:
            # the undamped system is singular: the smallest damping that makes it regular
            n = len(g)
            return exact.solve(A + max(mu, 1e-12) * max(1.0, float(np.max(np.abs(A))))
                               * np.eye(n), g)


def damped_step(Js: np.ndarray, r: np.ndarray, mu: float) -> np.ndarray:
    """Minimiser ``s`` of ``|Js s + r|^2 + mu |s|^2`` for unit-scaled columns ``Js``.

    Normal equations (well scaled, since the columns have unit norm); the damped matrix is
    positive definite, an undamped one (``mu = 0``) is factored by Cholesky, and one that
    Cholesky refuses falls back to an SVD solve of the stacked problem.
    """
    return _damped_solve(normal_equations(Js, r), Js, r, mu)


def normal_equations(Js: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Js^T Js, -Js^T r)``: what every damped step from one state shares, formed once
    per state however many damping values are tried."""
    return _Blas.normal(Js, r)


def _damped_solve(normal: tuple[np.ndarray, np.ndarray], Js: np.ndarray, r: np.ndarray,
                  mu: float, algebra: type[_Blas] = _Blas) -> np.ndarray:
    """``damped_step`` from the shared normal equations (``normal_equations(Js, r)``)."""
    n = Js.shape[1]
    A = normal[0].copy()
    A.flat[::n + 1] += mu
    return algebra.solve(A, normal[1], Js, r, mu)


def column_scale(J: np.ndarray) -> np.ndarray:
    """Column norms of ``J``, a zero column counted as 1 (it takes no part)."""
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    return scale


def _vector_retract(x: np.ndarray, step: np.ndarray) -> np.ndarray:
    return x + step


@dataclass
class _State:
    x: Any
    r: np.ndarray
    J: np.ndarray | None
    cost: float


def _jacobian(evaluate: Evaluate, x: Any) -> np.ndarray:
    """The Jacobian ``evaluate`` gives at ``x`` when asked for one."""
    J = evaluate(x, True)[1]
    if J is None:
        raise TypeError("evaluate(x, True) returned no Jacobian")
    return J


# long: the outer (accepted steps) and inner (damping) loops read as the algorithm of the
# module docstring in one place; every part of a step is already a helper of its own.
def levenberg_marquardt(evaluate: Evaluate, x0: Any, *, max_iterations: int,
                        tolerances: Tolerances = Tolerances(), damping: Damping | None = DAMPING,
                        retract: Callable[[Any, np.ndarray], Any] = _vector_retract,
                        bounds: tuple[np.ndarray, np.ndarray] | None = None,
                        reweight: Callable[[np.ndarray], np.ndarray] | None = None,
                        coordinates: Callable[[Any], np.ndarray] = np.asarray,
                        reproducible: bool = False) -> LeastSquaresResult:
    """Minimise ``0.5 |w r(x)|^2`` from ``x0``; see the module docstring.

    ``evaluate(x, jacobian)`` returns ``(r, J)``, ``J`` may be None unless ``jacobian``.
    ``damping=None`` takes undamped Gauss-Newton steps, each accepted whatever it does to
    the cost. ``bounds = (lower, upper)`` for a vector state. ``reweight(r)`` gives
    per-entry weights ``w**2`` (iteratively reweighted least squares), renewed after every
    accepted step. ``reproducible``: the algebra of ``common.exact`` (small problems).
    """
    algebra = _Exact if reproducible else _Blas
    if bounds is not None:
        x0 = np.clip(np.asarray(x0, dtype=float), *bounds)
    r, J = evaluate(x0, False)
    weights = reweight(r) if reweight is not None else None
    state = _State(x0, r, J, _cost(r, weights, algebra))
    mu = damping.initial if damping is not None else 0.0
    history = [state.cost]
    for iteration in range(max_iterations):
        if state.J is None:
            state.J = _jacobian(evaluate, state.x)
        J, r = _weighted(state.J, state.r, weights)
        stop = _stop_before_step(J, r, state.cost, tolerances, history, algebra)
        if stop is not None:
            return _result(state, iteration, stop)
        free = _free_unknowns(state.x, J, r, bounds, algebra)
        if not free.any():
            return _result(state, iteration, -2)
        scale = column_scale(J[:, free]) if damping is None or damping.scaling == "marquardt" \
            else np.ones(int(free.sum()))
        Js = J[:, free] / scale
        normal = algebra.normal(Js, r)
        while True:
            scaled_step = _damped_solve(normal, Js, r, mu, algebra)
            step = np.zeros(J.shape[1])
            step[free] = scaled_step / scale
            x_trial, step, clipped = _moved(state.x, step, retract, bounds)
            r_trial, J_trial = evaluate(x_trial, False)
            cost_trial = _cost(r_trial, weights, algebra)
            # A step the bounds cut short must lower the cost, or a shorter one is tried.
            if damping is None or cost_trial < state.cost or (
                    cost_trial == state.cost and not clipped):
                break
            # A refused step below xtol whose predicted gain is rounding: the state is
            # where the steps end. (At the minimum more damping would only shrink the step
            # further, each trial evaluated in turn and refused.)
            if _rounding_only(normal, scaled_step, state.cost, algebra) and _below_xtol(
                    scaled_step, coordinates(state.x)[free] * scale, tolerances, algebra):
                return _result(state, iteration, 3)
            mu = max(mu * damping.increase, damping.floor)
            if mu > damping.ceiling:
                return _result(state, iteration, 5)
        decrease = state.cost - cost_trial
        state = _State(x_trial, r_trial, J_trial, cost_trial)
        if reweight is not None:
            weights = reweight(r_trial)
            state.cost = _cost(r_trial, weights, algebra)
        history.append(state.cost)
        if damping is not None:
            mu = max(mu / damping.decrease, damping.floor)
        stop = _stop_after_step(step[free] * scale, coordinates(state.x)[free] * scale,
                                state.cost, decrease, tolerances, algebra)
        if stop is not None:
            return _result(state, iteration + 1, stop)
    return _result(state, max_iterations, 0)


def _cost(r: np.ndarray, weights: np.ndarray | None, algebra: type[_Blas] = _Blas) -> float:
    """``0.5 |w r|^2``; a non-finite value counts as infinite."""
    cost = 0.5 * float(algebra.dot(r, r) if weights is None else np.sum(weights * r**2))
    return cost if np.isfinite(cost) else np.inf


def _free_unknowns(x, J: np.ndarray, r: np.ndarray,
                   bounds: tuple[np.ndarray, np.ndarray] | None,
                   algebra: type[_Blas] = _Blas) -> np.ndarray:
    """All unknowns but those at a bound whose descent direction points outwards."""
    if bounds is None:
        return np.ones(J.shape[1], dtype=bool)
    gradient = algebra.project(J, r)
    return ~(((x <= bounds[0]) & (gradient > 0)) | ((x >= bounds[1]) & (gradient < 0)))


def _moved(x, step: np.ndarray, retract, bounds) -> tuple[Any, np.ndarray, bool]:
    """The state after ``step`` (clipped onto the bounds), the step taken, and whether the
    bounds cut it short."""
    moved = retract(x, step)
    if bounds is None:
        return moved, step, False
    moved = np.clip(moved, *bounds)
    taken = moved - x
    return moved, taken, not np.array_equal(taken, step)


def _weighted(J: np.ndarray, r: np.ndarray, weights: np.ndarray | None):
    if weights is None:
        return J, r
    w = np.sqrt(weights)
    return J * w[:, None], r * w


def _stop_before_step(J: np.ndarray, r: np.ndarray, cost: float, tolerances: Tolerances,
                      history: list[float], algebra: type[_Blas] = _Blas) -> int | None:
    norm = np.sqrt(2.0 * cost)
    if norm <= tolerances.residual_floor:
        return 4
    if tolerances.gtol and J.shape[1]:
        cosine = np.abs(algebra.project(J, r)) / column_scale(J)
        if np.max(cosine) <= tolerances.gtol * norm:
            return 1
    if tolerances.stall is not None:
        window, fraction = tolerances.stall
        if len(history) > window and cost > (1.0 - fraction) * history[-window - 1]:
            return -1
    return None


def _stop_after_step(scaled_step: np.ndarray, scaled_x: np.ndarray, cost: float,
                     decrease: float, tolerances: Tolerances,
                     algebra: type[_Blas] = _Blas) -> int | None:
    if abs(decrease) <= tolerances.ftol * cost:
        return 2
    if _below_xtol(scaled_step, scaled_x, tolerances, algebra):
        return 3
    return None


def _rounding_only(normal: tuple[np.ndarray, np.ndarray], scaled_step: np.ndarray,
                   cost: float, algebra: type[_Blas] = _Blas) -> bool:
    """The linear model's decrease for ``scaled_step`` (``g.s - |Js s|^2 / 2`` from the
    normal equations) is within rounding of ``cost``."""
    A, g = normal
    predicted = algebra.dot(g, scaled_step) - 0.5 * algebra.dot(
        scaled_step, algebra.matvec(A, scaled_step))
    return bool(predicted <= np.finfo(float).eps * cost)


def _below_xtol(scaled_step: np.ndarray, scaled_x: np.ndarray, tolerances: Tolerances,
                algebra: type[_Blas] = _Blas) -> bool:
    """The scaled step at or below ``xtol`` of the scaled state."""
    return bool(algebra.norm(scaled_step) <= tolerances.xtol * (1.0 + algebra.norm(scaled_x)))


def _result(state: _State, iterations: int, status: int) -> LeastSquaresResult:
    return LeastSquaresResult(state.x, state.r, state.J, state.cost, iterations, status)
