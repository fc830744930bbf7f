"""What the final model leaves unexplained: is the residual noise, or structure?

After the effect search, the residual is tested for structure that no effect of the
library describes. The hypothesis class is broad on purpose: *some geometric parameter
of some joint takes a value that varies smoothly with some variable*. The variables are
each joint reading ``q<j>``, each joint's direction of motion ``direction_q<j>`` (the
sign of its change from the previous row; rows are in measurement order), where the robot
file declares a ``transmission``, each motor's direction ``direction_m<k>``, each numeric
extra column (``temperature``, ``time``, ``payload`` ...), and each pair of joint
readings. A length that sags with its angle, a joint offset that follows another joint,
backlash, a warm-up: each is such a variation, named or not.

For one variable ``v`` and one parameter ``p_c`` (``theta``, ``d``, ``a``, ``alpha`` of
each joint) the residual would move by ``sum_k S_c[:, k] g(v_k)``, with ``S_c`` the
row sensitivities (``Problem.row_sensitivities``) and ``g`` a flexible function of
``v``: piecewise-linear on knots at the quantiles of ``v``, plus the first two harmonics
for a joint angle (a product of two piecewise-linear functions for a pair; one value per
sign for a direction). The columns are projected off everything the
model already fits; the drop of the residual sum of squares gives a likelihood-ratio
statistic, compared with the chi-square quantile at a family-wise level ``ALPHA`` shared
over all tests (Bonferroni). The strongest significant tests (distinct variables, at most
``COMBINED``) are then fitted together and judged by K-fold cross-validation over units
of data (rows, or whole placements): the share of the held-out mean square they remove,
applied to the fit's own mean square, is the structured part (so it never exceeds the fit
RMS); what stays held out estimates the noise floor. Where the model alone predicts the
held-out units far worse than a least-squares fit of its size should (too few units, each
fold extrapolated), the comparison would measure that extrapolation, and nothing is
reported.

``find`` returns None when nothing is significant, the cross-validation does not
improve, or the structured part is below ``MIN_SHARE`` of the remaining mean square.
Linearised at the final solution; residuals [m] are those of ``Problem.residual``,
RMS values over the per-measurement errors as ``Problem.rms``. The records it returns
(``Unexplained``, ``StructureTest``) are results, defined in ``results``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..effects.motion import directions_of_motion, motor_directions_of_motion
from ..results import StructureTest, Unexplained
from .folds import FoldGrams, fold_schemes

ALPHA = 1e-3  # family-wise false-alarm level over all tests
MIN_SHARE = 0.02  # structure below this share of the remaining mean square is not reported
COMBINED = 3  # strongest variables fitted together
KNOTS = 5  # knots of a single variable's piecewise-linear function
PAIR_KNOTS = 3  # knots per variable of a pair's function
MAX_ENTRIES = 9000  # residual entries tested (whole units drawn at random beyond)
MIN_SPAN = {True: 1e-3, False: 1e-4}  # [rad] / [m]: a joint that moves less is still
STEMS = ("theta", "d", "a", "alpha", "x", "y", "z", "roll", "pitch", "yaw")  # DH or URDF
PAIR_GAIN = 1.25  # a pair's statistic over the better of its two variables alone
LISTED = 0.25  # variables listed down to this fraction of the strongest statistic
CV_SLACK = 3.0  # held-out error of the model alone, over what a sound fold split gives


# ----------------------------------------------------------------------------- variables


@dataclass(frozen=True)
class _Variable:
    name: str
    basis: np.ndarray  # (rows x K) over the stacked data rows


def _hats(values: np.ndarray, knots: int) -> np.ndarray | None:
    """Piecewise-linear hat functions on knots at the quantiles of ``values``."""
    points = np.unique(np.quantile(values, np.linspace(0, 1, knots)))
    if len(points) < 2:
        return None
    basis = np.zeros((len(values), len(points)))
    position = np.clip(np.searchsorted(points, values, side="right") - 1, 0, len(points) - 2)
    left, right = points[position], points[position + 1]
    weight = np.clip((values - left) / (right - left), 0.0, 1.0)
    rows = np.arange(len(values))
    basis[rows, position] = 1 - weight
    basis[rows, position + 1] += weight
    return basis


def _variables(problem) -> list[_Variable]:
    robot = problem.robot
    joints_parts, directions_parts, extras_parts, motor_parts = [], [], [], []
    columns: set[str] | None = None
    for model in problem.models:
        dataset = model.dataset
        readings = dataset.joints if model.uses_robot and dataset.joints is not None \
            else np.full((dataset.rows, robot.dof), np.nan)
        joints_parts.append(readings)
        directions_parts.append(directions_of_motion(readings))
        motor_parts.append(motor_directions_of_motion(readings, robot))
        numeric = {k for k, v in dataset.extras.items()
                   if np.asarray(v).dtype.kind in "fiu"}
        columns = numeric if columns is None else columns & numeric
        extras_parts.append(dataset.extras)
    joints = np.vstack(joints_parts)
    directions = np.vstack(directions_parts)
    out: list[_Variable] = []
    moving = []
    for j, joint in enumerate(robot.joints):
        values = joints[:, j]
        if not np.all(np.isfinite(values)) or np.ptp(values) < MIN_SPAN[joint.revolute]:
            continue
        moving.append(j)
        basis = _hats(values, KNOTS)
        if basis is not None and joint.revolute:
            # Hats follow any shape between knots; the first two harmonics follow what
            # turns with the joint (gears, eccentric loads) across the whole range.
            basis = np.column_stack([basis, np.sin(values), np.cos(values),
                                     np.sin(2 * values), np.cos(2 * values)])
        if basis is not None:
            out.append(_Variable(f"q{j + 1}", basis))
        sign = directions[:, j]
        if np.any(sign > 0) and np.any(sign < 0):
            out.append(_Variable(f"direction_q{j + 1}",
                                 np.column_stack([sign > 0, sign < 0]).astype(float)))
    # a motor of a differential turns several joints: its reversals are a variable of
    # their own (play in its drive shows where it reverses, not where a joint does)
    for name in motor_parts[0] if motor_parts else ():
        sign = np.concatenate([part[name] for part in motor_parts])
        if np.any(sign > 0) and np.any(sign < 0):
            out.append(_Variable(name, np.column_stack([sign > 0, sign < 0]).astype(float)))
    for name in sorted(columns or ()):
        values = np.concatenate([np.asarray(e[name], float) for e in extras_parts])
        if np.all(np.isfinite(values)) and np.ptp(values) > 0:
            basis = _hats(values, KNOTS - 1)
            if basis is not None:
                out.append(_Variable(name, basis))
    for a_index, a in enumerate(moving):
        for b in moving[a_index + 1:]:
            first, second = _hats(joints[:, a], PAIR_KNOTS), _hats(joints[:, b], PAIR_KNOTS)
            if first is None or second is None:
                continue
            basis = (first[:, :, None] * second[:, None, :]).reshape(len(joints), -1)
            out.append(_Variable(f"q{a + 1}*q{b + 1}", basis))
    return out


def _names(variable: str) -> list[str]:
    return variable.split("*")


# ----------------------------------------------------------------------------- the test


def _chi2_quantile(k: int, tail: float) -> float:
    """Upper ``tail`` quantile of chi-square with ``k`` degrees of freedom
    (Wilson-Hilferty; within a few percent for the small tails used here)."""
    z = NormalDist().inv_cdf(1.0 - tail)
    h = 2.0 / (9.0 * k)
    return k * (1.0 - h + z * math.sqrt(h)) ** 3


def _orthonormal(X: np.ndarray) -> np.ndarray | None:
    """Orthonormal basis of what the model cannot already do (singular values of the
    unit-scaled, projected columns ``X`` above 1e-3), from the small Gram matrix; None
    when ``X`` is zero."""
    if not np.any(X):
        return None
    eigenvalues, vectors = np.linalg.eigh(X.T @ X)
    big = eigenvalues > 1e-6
    return X @ (vectors[:, big] / np.sqrt(eigenvalues[big]))


def _units_subset(problem, n: int, seed: int) -> np.ndarray:
    """Residual entries to test: all, or whole units drawn at random up to MAX_ENTRIES."""
    if n <= MAX_ENTRIES:
        return np.arange(n)
    keys = np.concatenate([np.asarray(m.residual_groups()) + 1_000_000 * k
                           for k, m in enumerate(problem.models)])
    units = np.unique(keys)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(units))
    share = MAX_ENTRIES / n
    chosen = units[order[:max(1, int(len(units) * share))]]
    return np.flatnonzero(np.isin(keys, chosen))


@dataclass(frozen=True)
class _Linearised:
    """The residual at the final solution, on the entries tested (``keep`` of all of them):
    ``r`` those entries, ``U`` an orthonormal basis of the model's own (free) columns
    there, ``r_perp`` the residual off them and ``rss0`` its sum of squares [m^2]."""

    r_all: np.ndarray
    keep: np.ndarray
    r: np.ndarray
    U: np.ndarray
    r_perp: np.ndarray
    rss0: float

    @property
    def n(self) -> int:
        return len(self.r)


@dataclass(frozen=True)
class _Sensitivities:
    """How each tested geometric parameter (``names``) of each data row moves the tested
    residual entries: per non-zero, the entry (``entries``, 0-based among those tested),
    the data row (``rows``) and one value per parameter (``values``)."""

    names: list[str]
    entries: np.ndarray
    rows: np.ndarray
    values: np.ndarray

    def projected_columns(self, variable: _Variable, lin: _Linearised) -> np.ndarray:
        """(n x channels x K) columns of every parameter varying with ``variable``,
        unit-scaled and projected off the model's own columns (one product for all)."""
        n, names = lin.n, self.names
        K = variable.basis.shape[1]
        rows_of_columns = np.empty((len(names) * K, n))  # one column per row, for speed
        basis = variable.basis[self.rows]
        for channel in range(len(names)):
            weights = self.values[:, channel]
            for k in range(K):
                rows_of_columns[channel * K + k] = np.bincount(
                    self.entries, weights=weights * basis[:, k], minlength=n)
        size = np.sqrt(np.einsum("ij,ij->i", rows_of_columns, rows_of_columns))
        rows_of_columns[size > 0] /= size[size > 0, None]
        rows_of_columns -= (rows_of_columns @ lin.U) @ lin.U.T
        return rows_of_columns.reshape(len(names), K, n).transpose(2, 0, 1)

    def basis(self, variable: _Variable, parameter: str, lin: _Linearised) -> np.ndarray:
        """The orthonormal columns of ``parameter`` varying with ``variable`` (a pair
        tested before, so not zero)."""
        columns = self.projected_columns(variable, lin)
        Q = _orthonormal(columns[:, self.names.index(parameter), :])
        assert Q is not None  # it was tested
        return Q


def find(problem, x: np.ndarray, free: np.ndarray, *, seed: int = 0) -> Unexplained | None:
    """Test the residual of ``problem`` at ``x`` (``free``: the unknowns fitted) for
    structure; see the module. None when what remains is consistent with noise."""
    if not any(m.uses_robot for m in problem.models):
        return None
    lin = _linearised(problem, x, free, seed)
    if lin.n < 10 or lin.rss0 <= 0:
        return None
    sensitivities = _sensitivities(problem, x, lin)
    variables = _variables(problem)
    tests = _tests(variables, sensitivities, lin)
    significant = sorted((t for t in tests if t.significant), key=lambda t: -t.statistic)
    if not significant:
        return None
    chosen = _strongest(significant)
    # The chosen bases are formed again (the same numbers) rather than every test's
    # basis held meanwhile: hundreds of them at thousands of rows each.
    by_name = {variable.name: variable for variable in variables}
    X = np.column_stack([sensitivities.basis(by_name[t.variable], t.parameter, lin)
                         for t in chosen])
    held_out = _held_out(problem, lin, X, seed)
    if held_out is None:
        return None
    sse0, sse1 = held_out
    share = (sse0 - sse1) / sse0
    if share < MIN_SHARE:
        return None
    # The structured part is the share of what the fit leaves (its mean square over the
    # per-measurement errors), so it can never exceed the fit RMS it is part of.
    n_errors = sum(len(m.errors(np.zeros(m.residual_size()))) for m in problem.models)
    fit_ms = float(lin.r_all @ lin.r_all) / n_errors
    ordered, carriers = _ranking(significant)
    fitted = X @ np.linalg.lstsq(X, lin.r_perp, rcond=None)[0]
    curve = _curve(problem, chosen[0].variable, sensitivities.entries, sensitivities.rows,
                   lin.r, lin.r - fitted)
    scale = len(lin.keep) / len(lin.r_all)
    return Unexplained(rms=math.sqrt(share * fit_ms), share=float(share),
                       variables=tuple(ordered[:6]), parameters=tuple(carriers[:6]),
                       noise_floor=math.sqrt(sse1 / (n_errors * scale)), tests=tuple(tests),
                       curve=curve)


def _linearised(problem, x: np.ndarray, free: np.ndarray, seed: int) -> _Linearised:
    """The residual at ``x`` on the entries tested, and what the model already fits
    there (``free``'s columns)."""
    r_all = problem.residual(x)
    keep = _units_subset(problem, len(r_all), seed)
    r = r_all[keep]
    A = problem.jacobian(x, np.flatnonzero(free))[keep]
    norms = np.linalg.norm(A, axis=0)
    A = A[:, norms > 0] / norms[norms > 0]
    U, singular, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, singular > singular[0] * 1e-10] if singular.size else U[:, :0]
    r_perp = r - U @ (U.T @ r)
    return _Linearised(r_all, keep, r, U, r_perp, float(r_perp @ r_perp))


def _sensitivities(problem, x: np.ndarray, lin: _Linearised) -> _Sensitivities:
    """The row sensitivities of every geometric parameter of every joint, restricted to
    the entries tested."""
    registry = problem.kinematics.registry.names
    names = [f"{stem}{j}" for j in range(1, problem.robot.dof + 1) for stem in STEMS
             if f"{stem}{j}" in registry]
    indices = [registry.index(name) for name in names]
    entries, rows, values = problem.row_sensitivities(x, indices)
    position = np.full(len(lin.r_all), -1)
    position[lin.keep] = np.arange(lin.n)
    inside = position[entries] >= 0
    return _Sensitivities(names, position[entries[inside]], rows[inside], values[inside])


def _tests(variables: list[_Variable], sensitivities: _Sensitivities,
           lin: _Linearised) -> list[StructureTest]:
    """Every variable against every parameter, with its chi-square threshold at the
    family-wise level ``ALPHA`` shared over all of them."""
    n, U = lin.n, lin.U
    tests = []
    for variable in variables:
        X_all = sensitivities.projected_columns(variable, lin)
        for channel, parameter in enumerate(sensitivities.names):
            Q = _orthonormal(X_all[:, channel, :])
            if Q is None or not Q.shape[1] or Q.shape[1] >= n - U.shape[1] - 1:
                continue
            drop = float(np.sum((Q.T @ lin.r_perp) ** 2))
            rss1 = max(lin.rss0 - drop, 1e-300)
            statistic = n * math.log(lin.rss0 / rss1)
            tests.append(StructureTest(variable.name, parameter, Q.shape[1], statistic,
                                       0.0, drop / lin.rss0))
    if not tests:
        return []
    tail = ALPHA / len(tests)
    return [StructureTest(t.variable, t.parameter, t.columns, t.statistic,
                          _chi2_quantile(t.columns, tail), t.rss_drop) for t in tests]


def _strongest(significant: list[StructureTest]) -> list[StructureTest]:
    """The strongest tests of distinct variables, at most ``COMBINED``."""
    chosen: list[StructureTest] = []
    for test in significant:
        if test.variable not in {t.variable for t in chosen}:
            chosen.append(test)
        if len(chosen) == COMBINED:
            break
    return chosen


def _held_out(problem, lin: _Linearised, X: np.ndarray, seed: int
              ) -> tuple[float, float] | None:
    """Held-out SSE [m^2] of the model alone and with the structure ``X`` fitted, over
    folds of units of data; None when they do not show an improvement the folds can be
    trusted for (``_cross_validation_holds``)."""
    schemes = [s for s in fold_schemes(problem, 5, seed) if not s.extrapolating]
    if not schemes:
        return None
    U = lin.U
    fold = schemes[0].fold[lin.keep]
    grams = FoldGrams(np.column_stack([U, X, lin.r]), fold)
    sse0 = grams.held_out_sse(list(range(U.shape[1])))
    sse1 = grams.held_out_sse(list(range(U.shape[1] + X.shape[1])))
    if not (np.isfinite(sse0) and np.isfinite(sse1)) or sse1 >= sse0:
        return None
    if not _cross_validation_holds(sse0, lin.rss0, lin.n, U.shape[1], fold):
        return None
    return sse0, sse1


def _cross_validation_holds(sse0: float, rss0: float, n: int, p: int, fold: np.ndarray) -> bool:
    """Whether the model's own held-out error ``sse0`` is what a linear fit of ``p``
    columns to ``n`` entries should give against its in-sample ``rss0``.

    For least squares with noise, the in-sample sum of squares is about ``(1 - p/n)`` of
    the noise's and a held-out one about ``1 / (1 - p/n_train)`` times it. With few units
    of data (a dozen bar placements) a fold left out is extrapolated and its error is
    orders of magnitude above that: the comparison then measures the extrapolation, not
    structure in the residual, and nothing is reported. ``CV_SLACK`` allows for the
    spread of the ratio and for a real structure inflating ``sse0``.
    """
    smallest_train = n - int(np.max(np.bincount(fold[fold >= 0]))) if np.any(fold >= 0) else 0
    if smallest_train <= p or n <= p:
        return False
    expected = 1.0 / ((1.0 - p / n) * (1.0 - p / smallest_train))
    return sse0 <= CV_SLACK * expected * rss0


def _ranking(significant: list[StructureTest]) -> tuple[list[str], list[str]]:
    """Variable names strongest first, each with the parameter of its strongest test.

    A pair counts only where it beats both its variables alone by ``PAIR_GAIN``; a
    variable is listed while its statistic is at least ``LISTED`` of the strongest.
    """
    best: dict[str, StructureTest] = {}
    for test in significant:
        if test.variable not in best or test.statistic > best[test.variable].statistic:
            best[test.variable] = test
    single = {v: t.statistic for v, t in best.items() if "*" not in v}
    ranked = []
    for variable, test in best.items():
        parts = _names(variable)
        if len(parts) > 1 and test.statistic < PAIR_GAIN * max(single.get(p, 0.0)
                                                               for p in parts):
            continue
        ranked.append(test)
    ranked.sort(key=lambda t: -t.statistic)
    top = ranked[0].statistic if ranked else 0.0
    ordered: list[str] = []
    carriers: list[str] = []
    for test in ranked:
        if test.statistic < LISTED * top:
            break
        for name in _names(test.variable):
            if name not in ordered:
                ordered.append(name)
                carriers.append(test.parameter)
    return ordered, carriers


def _curve(problem, variable: str, entries: np.ndarray, rows: np.ndarray,
           before: np.ndarray, after: np.ndarray) -> dict[str, np.ndarray]:
    """Per data row: the strongest single variable, and the RMS [m] of the residual
    entries that row moves, before and after removing the structure."""
    name = _names(variable)[0]
    pairs = np.unique(np.column_stack([entries, rows]), axis=0)
    total = sum(m.dataset.rows for m in problem.models)
    counts = np.bincount(pairs[:, 1], minlength=total)
    seen = counts > 0
    square_before = np.bincount(pairs[:, 1], before[pairs[:, 0]] ** 2, total)
    square_after = np.bincount(pairs[:, 1], after[pairs[:, 0]] ** 2, total)
    return {"variable": np.array(name), "value": _values_of(problem, name)[seen],
            "before": np.sqrt(square_before[seen] / counts[seen]),
            "after": np.sqrt(square_after[seen] / counts[seen])}


def _values_of(problem, name: str) -> np.ndarray:
    parts = []
    for model in problem.models:
        dataset = model.dataset
        if name.startswith("direction_q"):
            j = int(name[len("direction_q"):]) - 1
            parts.append(directions_of_motion(dataset.joints)[:, j])
        elif name.startswith("direction_m"):
            parts.append(motor_directions_of_motion(dataset.joints, problem.robot)[name])
        elif name.startswith("q") and name[1:].isdigit():
            parts.append(dataset.joints[:, int(name[1:]) - 1])
        else:
            parts.append(np.asarray(dataset.extras[name], float))
    return np.concatenate(parts)
