"""A learned map, last and honest: a smooth correction where the named effects run out.

When the final model leaves a structured residual (``unexplained`` not None), the tool
position is corrected by a smooth function of the joint readings the structure follows
(``effects.residual_map``), learned by kernel ridge regression:

1. Targets. For data whose every row sees a shift of the tool point in all three
   directions (tracker points), the shift ``t_k`` [m, world frame] that best removes row
   k's residual: ``r_k + S_k t_k = min``, ``S_k`` the row's sensitivity to the base's
   translation (``Problem.row_sensitivities``). Other data are not offered a map.
2. Regression. ``alpha = (K + lambda I)^-1 T`` with the Gaussian kernel
   ``K_ik = exp(-|u_i - u_k|^2 / (2 l^2))`` over the readings scaled to the trained region
   (``u`` in [0, 1]), by Cholesky factors (scipy.linalg). The system is that of
   ``scipy.interpolate.RBFInterpolator`` with a Gaussian kernel, smoothing ``lambda``
   and no polynomial tail; it is written out because the effects file must hold the
   coefficients and CasADi must evaluate them.
   No polynomial tail: with none, the map shrinks to zero away from its data, as its fade
   does. scipy is a core dependency already: no new one.
3. Length scale and smoothing are chosen by the fold schemes of ``folds`` (units at
   random, ranges and halves of each joint, clusters, datasets): the pair with the
   smallest held-out squared error summed over them. Each fold's map is trained on its
   training rows only, with the region (and so the fade) of those rows.
4. Kept only when the folds confirm it: the held-out RMS over the random folds falls by
   at least ``MIN_GAIN``, the summed held-out error of the extrapolating schemes falls,
   and no extrapolating scheme grows by more than its tolerance
   (the numbers diagnosis judges physical effects by).

Linear in the targets: the geometry stays as the final fit left it while the map is
learned, then is refitted once with the map in (the map's gain held at 1), under the tolerance
prior the geometry was fitted with.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve, eigh

from ..common.memory import release_freed
from ..common.units import Units, display_units
from ..effects.residual_map import (
    FADE,
    GAIN,
    KERNEL_BLOCK,
    SHIFT,
    ResidualMap,
    fade_weight,
    gaussian,
    kernel_of,
    squared_distances,
)
from ..results import EffectFinding
from .diagnosis import EXTRAPOLATION_TOLERANCE, MIN_GAIN, embed, sibling_problem
from .folds import fold_schemes
from .prior import Prior, PriorProblem, copy_weights, settled_decrease
from .problem import Problem
from .solver import Loss, Method, Solution, solve

LENGTH_SCALES = (0.1, 0.2, 0.4)  # [1] of each variable's trained span
SMOOTHING = (1e-3, 1e-2, 1e-1, 1.0, 10.0)  # [1] lambda, against the kernel's unit diagonal
MAX_VARIABLES = 3  # joint readings the map may follow
MAX_ROWS = 800  # rows a map is trained on (evenly spread over the data beyond)
RANK_TOLERANCE = 1e-6  # of a row's largest sensitivity: below, a direction is not seen


@dataclass(frozen=True)
class LearnedMap:
    """What ``learn`` found: the ``effect`` (None when it does not pay), the held-out RMS
    [m] on the random folds without and with it, the summed held-out error ratio of the
    extrapolating schemes, the chosen ``length_scale`` and ``smoothing``, and why not."""

    effect: ResidualMap | None
    cv_before: float
    cv_after: float
    extrapolation: float
    length_scale: float
    smoothing: float
    reason: str = ""


@dataclass(frozen=True)
class _Rows:
    """The data rows a map is learned on: readings ``X`` (N x k) [rad or m] of its
    variables, targets ``T`` (N x 3) [m], and per row what its squared residual after a
    shift ``s`` is, ``c + 2 b.s + s.G.s`` (``c`` [m^2], ``b`` (N x 3) [m], ``G``
    (N x 3 x 3) [1]: ``r.r``, ``S^T r``, ``S^T S``); the fold of each row per scheme."""

    X: np.ndarray
    T: np.ndarray
    c: np.ndarray
    b: np.ndarray
    G: np.ndarray
    folds: list[tuple[str, bool, float, np.ndarray]]  # (name, extrapolating, tolerance, fold)

    def squared(self, rows: np.ndarray, shift: np.ndarray | None = None) -> float:
        """Squared residual [m^2] of ``rows`` after ``shift`` (len(rows) x 3) [m]."""
        total = float(self.c[rows].sum())
        if shift is not None:
            total += float(2.0 * np.sum(self.b[rows] * shift)
                           + np.einsum("ki,kij,kj->", shift, self.G[rows], shift))
        return total


def tolerance_of(scheme) -> float:
    """How much a map may grow the held-out squared error of an extrapolating scheme."""
    return EXTRAPOLATION_TOLERANCE if scheme.tolerance is None else float(scheme.tolerance)


def joints_named(variables: Sequence[str], dof: int) -> tuple[int, ...]:
    """The joints (1-based) among the unexplained ``variables`` (``q2``, ``q2*q3``), in
    order, at most ``MAX_VARIABLES``; directions and data columns are not joint readings."""
    out: list[int] = []
    for variable in variables:
        for part in variable.split("*"):
            if part.startswith("q") and part[1:].isdigit() and 1 <= int(part[1:]) <= dof:
                if int(part[1:]) not in out:
                    out.append(int(part[1:]))
    return tuple(out[:MAX_VARIABLES])


def _rows(problem: Problem, x: np.ndarray, joints: tuple[int, ...]) -> _Rows | None:
    """Targets and sensitivities per data row; None when a row does not see all three
    directions of a shift (the map cannot be learned from such data)."""
    if not all(m.uses_robot and m.dataset.joints is not None for m in problem.models):
        return None
    index = [problem.kinematics.registry.index(n) for n in SHIFT]
    entries, rows, values = problem.row_sensitivities(x, index)
    n_rows = sum(m.dataset.rows for m in problem.models)
    if not len(entries) or len(np.unique(rows)) != n_rows:
        return None
    r = problem.residual(x)
    order = np.argsort(rows, kind="stable")
    bounds = np.searchsorted(rows[order], np.arange(n_rows + 1))
    T, c, b, G = (np.zeros((n_rows, 3)), np.zeros(n_rows), np.zeros((n_rows, 3)),
                  np.zeros((n_rows, 3, 3)))
    for k in range(n_rows):
        chosen = order[bounds[k]:bounds[k + 1]]
        block, own = values[chosen], r[entries[chosen]]
        singular = np.linalg.svd(block, compute_uv=False)
        if len(singular) < 3 or singular[-1] <= RANK_TOLERANCE * singular[0]:
            return None
        T[k] = -np.linalg.lstsq(block, own, rcond=None)[0]
        c[k], b[k], G[k] = own @ own, block.T @ own, block.T @ block
    Q = np.vstack([m.dataset.joints for m in problem.models])
    folds = []
    for scheme in fold_schemes(problem):
        row_fold = np.full(n_rows, -1)
        row_fold[rows] = scheme.fold[entries]
        folds.append((scheme.name, scheme.extrapolating, tolerance_of(scheme), row_fold))
    return _Rows(Q[:, [j - 1 for j in joints]], T, c, b, G, folds)


def _spread(n: int) -> np.ndarray:
    """At most ``MAX_ROWS`` row indices spread evenly over ``n``."""
    return np.arange(n) if n <= MAX_ROWS else np.linspace(0, n - 1, MAX_ROWS).round().astype(int)


def _region(X: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(lower, upper) [rad or m] of the rows ``X``; None when a variable does not move."""
    lower, upper = X.min(axis=0), X.max(axis=0)
    return None if np.any(upper - lower <= 0) else (lower, upper)


def _spectrum(U: np.ndarray, length_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (clipped at 0) and eigenvectors of the kernel matrix of ``U``."""
    eigenvalues, vectors = eigh(gaussian(U, U, length_scale))
    return np.clip(eigenvalues, 0.0, None), vectors


def fit_map(joints: tuple[int, ...], X: np.ndarray, T: np.ndarray, length_scale: float,
            smoothing: float) -> ResidualMap | None:
    """The map trained on readings ``X`` (N x k) and targets ``T`` (N x 3) [m]: kernel
    ridge regression ``alpha = (K + smoothing I)^-1 T``; None when a variable does not
    move in these rows."""
    keep = _spread(len(X))
    X, T = X[keep], T[keep]
    region = _region(X)
    if region is None:
        return None
    lower, upper = region
    U = (X - lower) / (upper - lower)
    eigenvalues, vectors = _spectrum(U, length_scale)
    alpha = vectors @ ((vectors.T @ T) / (eigenvalues + smoothing)[:, None])
    return ResidualMap(joints, U, alpha, length_scale, lower, upper)


def _fold_errors(data: _Rows, train: np.ndarray, held: np.ndarray) -> np.ndarray:
    """Held-out squared error [m^2] of one fold per (length scale, smoothing) of the map
    trained on ``train``, the region and fade those rows give; the error without a map
    where a variable does not move in them.

    The squared distances are formed once for every length scale, and each smoothing's
    system is the kernel matrix with its diagonal raised in a copy factored in place."""
    before = data.squared(held)
    out = np.full((len(LENGTH_SCALES), len(SMOOTHING)), before)
    train = train[_spread(len(train))]
    region = _region(data.X[train])
    if region is None or not len(held):
        return out
    lower, upper = region
    span = upper - lower
    weight = fade_weight(data.X[held], lower, upper, FADE * span)
    inside = weight > 0
    if not inside.any():
        return out
    U, V = (data.X[train] - lower) / span, (data.X[held][inside] - lower) / span
    inner, outer = squared_distances(U, U), squared_distances(V, U)
    diagonal = np.arange(len(U))
    for a, length_scale in enumerate(LENGTH_SCALES):
        K = kernel_of(inner, length_scale)
        alphas = []
        for smoothing in SMOOTHING:
            system = K.copy()
            system[diagonal, diagonal] += smoothing
            alphas.append(cho_solve(cho_factor(system, overwrite_a=True, check_finite=False),
                                    data.T[train], check_finite=False))
        for b, predicted in enumerate(_predicted(outer, length_scale, alphas)):
            shift = np.zeros((len(held), 3))
            shift[inside] = weight[inside, None] * predicted
            out[a, b] = data.squared(held, shift)
    return out


def _predicted(squared: np.ndarray, length_scale: float,
               alphas: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``K @ alpha`` (rows x 3) [m] for each of ``alphas``, ``K`` the Gaussian kernel of
    the ``squared`` distances (rows x centres), formed a block of rows at a time: the
    held-out rows of a fold that holds out half the data would otherwise make a kernel
    matrix as large as the distances beside them."""
    out = [np.empty((len(squared), 3)) for _ in alphas]
    for start in range(0, len(squared), KERNEL_BLOCK):
        block = kernel_of(squared[start:start + KERNEL_BLOCK], length_scale)
        for predicted, alpha in zip(out, alphas):
            predicted[start:start + KERNEL_BLOCK] = block @ alpha
    return out


def _scheme_errors(data: _Rows, fold: np.ndarray) -> tuple[float, np.ndarray]:
    """Held-out squared error [m^2] of one fold scheme summed over its folds: without a
    map, and per (length scale, smoothing) (L x M)."""
    before = 0.0
    after = np.zeros((len(LENGTH_SCALES), len(SMOOTHING)))
    for f in range(int(fold.max()) + 1):
        held, train = np.flatnonzero(fold == f), np.flatnonzero(fold != f)
        before += data.squared(held)
        after += _fold_errors(data, train, held)
    return before, after


def _cross_validated(data: _Rows, known: dict[int, tuple[float, np.ndarray]]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Held-out squared error [m^2] per scheme without a map (S,) and with one per
    (scheme, length scale, smoothing) (S x L x M); ``known``: schemes already summed."""
    before = np.zeros(len(data.folds))
    after = np.zeros((len(data.folds), len(LENGTH_SCALES), len(SMOOTHING)))
    for s, (_, _, _, fold) in enumerate(data.folds):
        before[s], after[s] = known[s] if s in known else _scheme_errors(data, fold)
    return before, after


def _hopeless(data: _Rows, n_errors: int) -> tuple[LearnedMap | None, dict]:
    """The first random scheme's errors, and the map's refusal when no length scale and
    smoothing lowers its held-out RMS by ``MIN_GAIN`` (or there is no random scheme):
    ``_verdict`` then refuses whichever pair the other schemes would pick, so they need
    not be computed."""
    random = [k for k, f in enumerate(data.folds) if not f[1]]
    if not random:
        return LearnedMap(None, math.nan, math.nan, math.nan, math.nan, math.nan,
                          "no fold holds out data at random"), {}
    without, cv = _scheme_errors(data, data.folds[random[0]][3])
    before, after = math.sqrt(without / n_errors), np.sqrt(cv / n_errors)
    if np.any(after <= (1.0 - MIN_GAIN) * before):
        return None, {random[0]: (without, cv)}
    a, b = np.unravel_index(int(np.argmin(after)), after.shape)
    best = float(after[a, b])
    reason = (f"held-out RMS {best / before - 1:+.2%} at best (needs -{MIN_GAIN:.0%})")
    return LearnedMap(None, before, best, math.nan, LENGTH_SCALES[a], SMOOTHING[b], reason), {}


def _verdict(data: _Rows, sse: np.ndarray, n_errors: int) -> tuple[str, float, float, float]:
    """(why not or '', random-fold RMS before and after [m], extrapolating ratio) for the
    map whose errors per scheme are ``sse`` (before: ``sse[:, 0]``, after: ``sse[:, 1]``)."""
    random = [k for k, f in enumerate(data.folds) if not f[1]]
    before = math.sqrt(sse[random[0], 0] / n_errors) if random else float("nan")
    after = math.sqrt(sse[random[0], 1] / n_errors) if random else float("nan")
    extrapolating = [k for k, f in enumerate(data.folds) if f[1]]
    total = float(sse[extrapolating, 1].sum() / sse[extrapolating, 0].sum()) \
        if extrapolating else float("nan")
    if not random or not after <= (1.0 - MIN_GAIN) * before:
        return (f"held-out RMS {after / before - 1:+.2%} (needs -{MIN_GAIN:.0%})", before, after,
                total)
    growth = [(data.folds[k][0], sse[k, 1] / sse[k, 0], data.folds[k][2])
              for k in extrapolating if sse[k, 0] > 0]
    name, ratio, tolerance = max(growth, key=lambda p: p[1] / (1.0 + p[2]),
                                 default=("", 0.0, 0.0))
    if np.isfinite(total) and (total >= 1.0 or ratio > 1.0 + tolerance):
        return (f"does not extrapolate (held out {name}: squared error x{ratio:.3g}; all "
                f"extrapolating folds x{total:.3g})", before, after, total)
    return "", before, after, total


def learn(problem: Problem, x: np.ndarray, variables: Sequence[str]) -> LearnedMap | None:
    """The map over the joints among ``variables`` for ``problem`` at ``x``, judged by
    the folds; None when the data or the variables allow none (see the module)."""
    joints = joints_named(variables, problem.robot.dof)
    if not joints:
        return None
    data = _rows(problem, x, joints)
    if data is None or not data.folds:
        return None
    release_freed()  # what the calibration freed, before the folds' kernel matrices
    n_errors = sum(len(e) for e in problem.errors(x))
    refused, known = _hopeless(data, n_errors)
    if refused is not None:
        return refused
    without, cv = _cross_validated(data, known)
    a, b = np.unravel_index(int(np.argmin(cv.sum(axis=0))), cv.shape[1:])
    sse = np.column_stack([without, cv[:, a, b]])
    reason, before, after, ratio = _verdict(data, sse, n_errors)
    effect = None if reason else fit_map(joints, data.X, data.T, LENGTH_SCALES[a],
                                         SMOOTHING[b])
    return LearnedMap(effect, before, after, ratio, LENGTH_SCALES[a], SMOOTHING[b], reason)


@dataclass(frozen=True)
class MapFolds:
    """How a model fares with a map over ``joints`` added, fold by fold: held-out squared
    error [m^2] per fold scheme without a map (``without``) and with the map those folds
    choose (``with_map``, each fold's map trained on its training rows), the fit's squared
    error with that map trained on every row (``fit_sse``), the schemes as
    (name, extrapolating, tolerance), the per-measurement error count, and the map's own
    verdict (``reason``: '' when it pays, as in ``learn``)."""

    without: np.ndarray
    with_map: np.ndarray
    fit_sse: float
    schemes: tuple[tuple[str, bool, float], ...]
    n_errors: int
    reason: str

    def random_rms(self) -> float:
        """Held-out RMS [m] with the map on the first scheme that deals units at random
        (nan when none does)."""
        random = [k for k, s in enumerate(self.schemes) if not s[1]]
        return math.sqrt(self.with_map[random[0]] / self.n_errors) if random else math.nan


def map_folds(problem: Problem, x: np.ndarray, joints: tuple[int, ...]) -> MapFolds | None:
    """``MapFolds`` of ``problem`` at ``x`` with a map over ``joints`` (every fold scheme
    summed, none skipped); None when the data allow no map (see ``learn``)."""
    data = _rows(problem, x, joints)
    if data is None or not data.folds:
        return None
    release_freed()
    n_errors = sum(len(e) for e in problem.errors(x))
    without, cv = _cross_validated(data, {})
    a, b = np.unravel_index(int(np.argmin(cv.sum(axis=0))), cv.shape[1:])
    sse = np.column_stack([without, cv[:, a, b]])
    reason = _verdict(data, sse, n_errors)[0]
    every = np.arange(len(data.X))
    effect = fit_map(joints, data.X, data.T, LENGTH_SCALES[a], SMOOTHING[b])
    fit_sse = data.squared(every) if effect is None else data.squared(
        every, effect.weight(data.X)[:, None] * effect.kernel_part(data.X))
    return MapFolds(without, sse[:, 1].copy(), fit_sse,
                    tuple((name, extrapolating, tolerance)
                          for name, extrapolating, tolerance, _ in data.folds),
                    n_errors, reason)


def with_map(problem: Problem, solution: Solution, effect: ResidualMap, *,
             prior: Prior | None = None, method: Method = "lm",
             loss: Loss = "linear") -> tuple[Problem, Solution]:
    """``problem`` with the map added (gain held at 1) and the geometry refitted with it.

    With ``prior`` (the tolerance prior the geometry was fitted under), the refit keeps
    it: the parameters the data barely see stay where the prior held them, instead of
    drifting along the directions the map leaves flat, and the fit ends as the maximum a
    posteriori fit does (``settled_decrease``)."""
    mapped = sibling_problem(problem, tuple(problem.effects) + (effect,))
    x = embed(problem, solution.x, mapped)
    x[mapped.unknowns.index(GAIN)] = 1.0
    free = np.zeros(len(mapped.unknowns), dtype=bool)
    names = [problem.unknowns.names[i] for i in np.flatnonzero(solution.free)]
    free[mapped.unknowns.indices(names)] = True
    if prior is None:
        return mapped, solve(mapped, x, free, method=method, loss=loss)
    fit = solve(PriorProblem(mapped, prior.placed_in(mapped), copy_weights(mapped)), x, free,
                method=method, loss=loss, decrease=settled_decrease(mapped))
    r = mapped.residual(fit.x)
    return mapped, replace(fit, residual=r, cost=0.5 * float(r @ r))


def finding(learned: LearnedMap, fit_rms: tuple[float, float], units: Units) -> EffectFinding:
    """The map as a finding of the result: its gain, evidence and one sentence (lengths
    and angles in ``units``); ``fit_rms`` [m] the fit RMS without and with it."""
    effect = learned.effect
    assert effect is not None
    units = display_units(units)  # the sentence is read: lengths in mm
    scale, length = units.length_scale, units.length
    summary = (f"{effect.describe({}, units)}; it lowers the cross-validated RMS of the fit "
               f"data (folds of the fit readings held out in turn) from "
               f"{learned.cv_before / scale:.3g} {length} to {learned.cv_after / scale:.3g} "
               f"{length}")
    evidence = {"rms_drop": 1.0 - fit_rms[1] / fit_rms[0], "fit_rms_without": fit_rms[0],
                "cv_rms_before": learned.cv_before,
                "cv_rms_after": learned.cv_after, "extrapolation": learned.extrapolation,
                "length_scale": learned.length_scale, "smoothing": learned.smoothing}
    return EffectFinding(name=effect.name, joints=effect.joints, parameters={GAIN: 1.0},
                         unit=effect.unit, evidence=evidence, std={GAIN: None}, summary=summary)

