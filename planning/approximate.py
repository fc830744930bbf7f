"""The best any selection from the candidates could do: the optimal approximate design.

An approximate design gives each candidate ``c`` of the pool a weight ``w_c >= 0``,
``sum w_c = 1``: the share of the plan's poses taken there. Its information per pose is
``A(w) = sum w_c A_c`` (``A_c = X_c^T X_c``, identifiable then shared columns) and the
placement unknowns are removed by the Schur complement ``S(w)``. For the index ``tool``
(``accuracy``) the predicted squared tool error per unit noise and per pose is

    f(w) = trace(W S(w)^-1),

convex in ``w`` (the Schur complement is concave in ``A``, ``trace(W X^-1)`` convex and
decreasing in ``X``). It is minimised by the multiplicative algorithm
``w_c <- w_c sqrt(d_c / f)`` with ``d_c = -df/dw_c = trace(S^-1 W S^-1 Z^T A_c Z)``,
``Z = [I; -A_ss^-1 A_sp]`` (Silvey, Titterington and Torsney). Because ``f`` is convex
and ``sum w_c d_c = f`` (``f`` is homogeneous of degree -1), every iterate certifies

    f* >= 2 f(w) - max_c d_c,

a lower bound on the optimum (the equivalence theorem: at the optimum ``max_c d_c =
f``). A plan of ``N`` candidates from the pool is the approximate design with weights
``k_c / N``, so no such plan predicts a tool error below ``sigma sqrt(f* / N)``: the
number ``design.Plan.tool_error_bound`` reports. Continuous refinement (``refine``)
leaves the pool and may go below it; the bound says how much any choice among the
candidates could still gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .information import Information

ITERATIONS = 2000
SETTLED = 1.005  # max_c d_c / f at which the design counts as optimal (0.5% in f)


@dataclass(frozen=True)
class ApproximateDesign:
    """Weights over the pool (sum 1), ``value`` ``f(w)`` and its certified ``lower`` bound
    [tool error^2 per unit noise^2 per pose], after ``iterations`` updates."""

    weights: np.ndarray
    value: float
    lower: float
    iterations: int

    def __repr__(self) -> str:
        support = int(np.sum(self.weights > 1e-3))
        return (f"ApproximateDesign(f={self.value:.6g}, lower bound {self.lower:.6g}, "
                f"{support} candidates above 0.1%, {self.iterations} iterations)")

    def tool_error_bound(self, count: int, noise: float) -> float:
        """Lower bound [m] on the predicted tool error of any plan of ``count`` candidates
        from the pool at reading noise ``noise`` [m]."""
        return float(noise * math.sqrt(max(self.lower, 0.0) / count))


def optimal_approximate(info: Information, iterations: int = ITERATIONS,
                        settled: float = SETTLED) -> ApproximateDesign:
    """The ``tool``-optimal approximate design over ``info``'s candidates (see the module
    docstring); ``info`` must carry tool weights."""
    A, m, W = info.matrices, info.m, _tool_weights(info)
    w = np.full(len(A), 1.0 / len(A))
    value, d = _value_and_descent(A, w, m, W)
    done = 0
    while done < iterations and d.max() > settled * value:
        w = w * np.sqrt(np.clip(d, 0.0, None) / value)
        w /= w.sum()
        value, d = _value_and_descent(A, w, m, W)
        done += 1
    return ApproximateDesign(w, float(value), float(2.0 * value - d.max()), done)


def design_value(info: Information, weights: np.ndarray) -> float:
    """``f(w)`` of the approximate design with ``weights`` (one per candidate, sum 1)."""
    return _value_and_descent(info.matrices, np.asarray(weights, float), info.m,
                              _tool_weights(info))[0]


def _tool_weights(info: Information) -> np.ndarray:
    if info.tool_weights is None:
        raise ValueError("an approximate design needs tool weights (Information(..., "
                         "tool_weights=...))")
    return info.tool_weights


def _value_and_descent(A: np.ndarray, w: np.ndarray, m: int, W: np.ndarray):
    """``f(w)`` and ``d_c = -df/dw_c`` for every candidate."""
    M = np.einsum("c,cij->ij", w, A)
    if M.shape[0] > m:  # shared placement unknowns: Z = [I; -A_ss^-1 A_sp]
        Z = np.vstack([np.eye(m), -np.linalg.solve(M[m:, m:], M[m:, :m])])
    else:
        Z = np.eye(m)
    S = Z.T @ M @ Z
    S_inverse = np.linalg.inv(S)
    value = float(np.trace(W @ S_inverse))
    H = Z @ (S_inverse @ W @ S_inverse) @ Z.T
    return value, np.einsum("cij,ij->c", A, H)
