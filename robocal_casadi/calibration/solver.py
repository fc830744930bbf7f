"""Nonlinear least squares over a subset of a ``Problem``'s unknowns.

Methods:

* ``lm``: Levenberg-Marquardt on the exact Jacobian (the package's kernel,
  ``least_squares.levenberg_marquardt``: Marquardt-scaled damping, a Cholesky solve of
  the damped normal equations; the default, as it exploits the least-squares structure);
* ``ipopt``: the same objective ``0.5 |r|^2`` handed to IPOPT through CasADi;
* ``linearised``: the published cross-bar method's iterated ``A dx = b`` (undamped
  Gauss-Newton steps; docs/methods.md#cross-bar-calibration);
* ``two_stage``: that method's scheme: angles with lengths held, then lengths with angles
  held, each stage iterated, repeated until the update is small; a last joint
  linearised pass over all free unknowns settles what the alternation leaves.

``loss='huber'`` reweights residual components (iteratively reweighted least squares)
so that outliers pull less. Standard errors come from ``s^2 (J^T J)^-1`` at the solution
with ``s^2 = RSS / (m - n)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal, Protocol, get_args

import casadi as ca
import numpy as np

from ..common.checks import array, choice, count, positive
from ..common.least_squares import DAMPING, Tolerances, levenberg_marquardt
from ..errors import ArgumentError, SolverError
from ..model.parameters import ParameterRegistry

Method = Literal["lm", "ipopt", "linearised", "two_stage"]
Loss = Literal["linear", "huber"]
METHODS: tuple[Method, ...] = get_args(Method)
LOSSES: tuple[Loss, ...] = get_args(Loss)
TWO_STAGE_TOLERANCE = 1e-6  # relative cost decrease of a round below which two_stage stops
CONVERGED_DECREASE = 1e-15  # relative cost decrease of a step at rounding level: converged


class LeastSquaresProblem(Protocol):
    """What ``solve`` needs of a problem: ``Problem`` and ``prior.PriorProblem`` offer it."""

    @property
    def unknowns(self) -> ParameterRegistry: ...

    def mask(self, *keys: str) -> np.ndarray: ...

    def residual(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray: ...

    def symbolic_residual(self, x: ca.MX) -> ca.MX: ...


@dataclass(frozen=True)
class Solution:
    """Result of a solve: ``x`` (full vector), ``covariance`` of the free unknowns."""

    x: np.ndarray
    free: np.ndarray
    covariance: np.ndarray
    cost: float
    iterations: int
    status: str
    method: Method
    seconds: float
    residual: np.ndarray = field(repr=False)

    @property
    def std(self) -> np.ndarray:
        """Standard error of every unknown (NaN for fixed ones) [SI]."""
        out = np.full(len(self.x), np.nan)
        out[self.free] = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        return out

    def __repr__(self) -> str:
        rms = float(np.sqrt(np.mean(self.residual**2))) if self.residual.size else 0.0
        return (f"Solution(method={self.method}, status={self.status!r}, "
                f"free={int(self.free.sum())}, iterations={self.iterations}, "
                f"rms_residual={rms:.4g}, seconds={self.seconds:.3g})")


def _huber_weights(r: np.ndarray) -> np.ndarray:
    sigma = 1.4826 * np.median(np.abs(r - np.median(r))) or 1e-12
    delta = 1.345 * sigma
    a = np.abs(r)
    return np.where(a <= delta, 1.0, delta / np.maximum(a, 1e-300))


def _covariance(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    m, n = J.shape
    dof = max(m - n, 1)
    s2 = float(r @ r) / dof
    try:
        return s2 * np.linalg.pinv(J.T @ J, rcond=1e-14, hermitian=True)
    except np.linalg.LinAlgError:
        return np.full((n, n), np.nan)


def _levenberg_marquardt(problem: LeastSquaresProblem, x: np.ndarray, free: np.ndarray, *,
                         loss: Loss, max_iterations: int, damping: bool, tolerance: float,
                         decrease: float = CONVERGED_DECREASE):
    """The shared kernel over ``x[free]``: damped (``lm``) or plain Gauss-Newton steps."""
    last: list = [None, None]  # the state last evaluated and its residual

    def evaluate(z: np.ndarray, jacobian: bool):
        full = x.copy()
        full[free] = z
        # The kernel asks for the Jacobian of a state whose residual it already has.
        if last[0] is not None and np.array_equal(last[0], z):
            r = last[1]
        else:
            r = problem.residual(full)
            last[:] = [np.array(z, copy=True), r]
        return r, problem.jacobian(full, free) if jacobian else None

    fit = levenberg_marquardt(
        evaluate, x[free].copy(), max_iterations=max_iterations,
        tolerances=Tolerances(ftol=decrease, xtol=tolerance),
        damping=DAMPING if damping else None,
        reweight=_huber_weights if loss == "huber" else None)
    x = x.copy()
    x[free] = fit.x
    r, covariance = _finish(problem, x, free, loss, fit.residual, fit.jacobian)
    return x, r, covariance, fit.cost, fit.iterations, fit.word


def _finish(problem: LeastSquaresProblem, x: np.ndarray, free: np.ndarray, loss: Loss,
            r: np.ndarray | None = None, J: np.ndarray | None = None):
    """Residual and covariance of the free unknowns at ``x`` (``r`` and ``J``: the
    residual and the free columns' Jacobian there, when the fit already has them)."""
    r = problem.residual(x) if r is None else r
    w = np.sqrt(_huber_weights(r)) if loss == "huber" else np.ones_like(r)
    J = problem.jacobian(x, free) if J is None else J
    return r, _covariance(J * w[:, None], r * w)


def _ipopt(problem: LeastSquaresProblem, x0: np.ndarray, free: np.ndarray, max_iterations: int):
    index = np.flatnonzero(free)
    z = ca.MX.sym("z", len(index))
    fixed = ca.MX.sym("fixed", len(x0))
    full = ca.vertcat(*[z[int(np.searchsorted(index, i))] if free[i] else fixed[i]
                        for i in range(len(x0))])
    r_symbolic = problem.symbolic_residual(full)
    nlp = {"x": z, "p": fixed, "f": 0.5 * ca.dot(r_symbolic, r_symbolic)}
    solver = ca.nlpsol("calibration", "ipopt", nlp, {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
        "ipopt.max_iter": max_iterations, "ipopt.tol": 1e-14,
        "ipopt.hessian_approximation": "exact"})
    out = solver(x0=x0[free], p=x0)
    x = x0.copy()
    x[free] = np.asarray(out["x"]).ravel()
    stats = solver.stats()
    r = problem.residual(x)
    J = problem.jacobian(x, free)
    # IPOPT stops short of its tolerance at an exact least-squares minimum when the
    # search direction vanishes: that is convergence too.
    done = stats.get("success") or stats.get("return_status") in (
        "Search_Direction_Becomes_Too_Small", "Solved_To_Acceptable_Level")
    status = "converged" if done else str(stats.get("return_status"))
    return x, r, _covariance(J, r), 0.5 * float(r @ r), int(stats.get("iter_count", 0)), status


def solve(problem: LeastSquaresProblem, x0: np.ndarray, free: np.ndarray, *, method: Method = "lm",
          loss: Loss = "linear", max_iterations: int = 100, tolerance: float = 1e-10,
          decrease: float = CONVERGED_DECREASE) -> Solution:
    """Minimise ``0.5 |r(x)|^2`` over ``x[free]``, the rest held at ``x0``.

    ``tolerance``: a scaled step below this fraction of the scaled state ends the fit;
    ``decrease``: so does an accepted step lowering the cost by less than this fraction of
    it (``lm`` and ``linearised``).

    ``x0`` (all unknowns, SI) and ``free`` (boolean, same length) are checked at the
    door, as are ``method``, ``loss``, ``max_iterations`` and ``tolerance``
    (``ArgumentError``, a ``ValueError``).
    """
    method = choice(method, METHODS, "method")
    loss = choice(loss, LOSSES, "loss")
    max_iterations = count(max_iterations, "max_iterations")
    tolerance = positive(tolerance, "tolerance")
    decrease = positive(decrease, "decrease")
    size = len(problem.unknowns)
    x0 = array(x0, (size,), "x0")
    free = np.asarray(free)
    if free.shape != (size,) or free.dtype != bool:
        raise ArgumentError(f"expected {size} booleans, got {free.dtype} of shape {free.shape}",
                            argument="free")
    start = time.perf_counter()
    if not free.any():
        r = problem.residual(x0)
        return Solution(x0.copy(), free, np.zeros((0, 0)), 0.5 * float(r @ r), 0, "nothing_free",
                        method, 0.0, r)
    if method == "lm":
        x, r, cov, cost, it, status = _levenberg_marquardt(
            problem, x0, free, loss=loss, max_iterations=max_iterations, damping=True,
            tolerance=tolerance, decrease=decrease)
    elif method == "linearised":
        x, r, cov, cost, it, status = _levenberg_marquardt(
            problem, x0, free, loss=loss, max_iterations=max_iterations, damping=False,
            tolerance=tolerance, decrease=decrease)
    elif method == "ipopt":
        x, r, cov, cost, it, status = _ipopt(problem, x0, free, max_iterations)
    else:
        x, r, cov, cost, it, status = _two_stage(problem, x0, free, loss, max_iterations,
                                                 tolerance)
    seconds = time.perf_counter() - start
    if not np.all(np.isfinite(x)):
        raise SolverError(f"the {method} solve diverged (non-finite estimate)",
                          stats={"iterations": it, "status": status})
    return Solution(x, free, cov, cost, it, status, method, seconds, r)


def _two_stage(problem: LeastSquaresProblem, x0, free, loss, max_iterations, tolerance):
    quantity = np.array([problem.unknowns.quantities[i] for i in range(len(x0))])
    robot = problem.mask("robot")
    others = free & ~robot
    angles = free & robot & (quantity == "angle")
    lengths = free & robot & (quantity != "angle")
    x = x0.copy()
    total = 0
    status = "max_iterations"
    cost = 0.5 * float(np.sum(problem.residual(x) ** 2))
    for _ in range(max(1, max_iterations)):
        for stage in (angles | others, lengths | others):
            x, _, _, stage_cost, it, _ = _levenberg_marquardt(
                problem, x, stage, loss=loss, max_iterations=max_iterations, damping=False,
                tolerance=tolerance)
            total += it
        # Alternating blocks converge linearly; stop when a round no longer pays.
        if cost - stage_cost <= TWO_STAGE_TOLERANCE * cost:
            status = "converged"
            break
        cost = stage_cost
    # Where angles and lengths are strongly coupled, alternating rounds crawl towards the
    # minimum (each round gaining a near-constant fraction); a joint linearised pass over
    # all free unknowns from where the rounds stopped settles the coupling, so the scheme
    # ends at the same minimum as the other methods.
    x, _, _, _, it, joint_status = _levenberg_marquardt(
        problem, x, free, loss=loss, max_iterations=max_iterations, damping=False,
        tolerance=tolerance)
    total += it
    status = "converged" if joint_status == "converged" else status
    r, covariance = _finish(problem, x, free, loss)
    return x, r, covariance, 0.5 * float(r @ r), total, status
