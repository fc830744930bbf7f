"""Ways of holding data out: the fold schemes diagnosis judges candidate effects on.

A fold scheme gives every residual entry of a problem a fold number; cross-validation
fits on all folds but one and measures the error on the one held out. The unit held out
together is the one a model's ``residual_groups`` names (a data row; a whole placement
for artifacts and bars, whose socket positions belong to the placement).

* ``units``: the units dealt at random into folds. It tests whether an effect describes
  data like the fit data, nothing more.
* ``q<j> ranges``: contiguous ranges of joint j (by the mean reading of the unit), each
  held out in turn. The fit never sees the range it is judged on, so an effect must
  extrapolate along that joint, as it must when the robot later works elsewhere.
* ``q<j> halves``: the lower and the upper half of joint j's range, each held out in
  turn: the fit sees one half and must predict the other, as when a robot calibrated in
  one part of its workspace later works in another. The quarters of ``q<j> ranges`` are
  too close to their training data to expose an effect the geometry mostly imitates:
  on the fit data the two cancel (a bending term of millimetres paired with a link
  length changed by as much), and only a held-out region far enough away breaks the
  cancellation. Half the data is a weak fit, and while other effects are still
  missing the geometry refitted on it extrapolates their signal poorly: a true effect
  found early may leave a half's error somewhat larger. So a half may grow its squared
  error up to ``HALVES_TOLERANCE`` (double) before it refuses an effect; a cancellation
  breaking down far away grows it by orders of magnitude. Halves are held out only when
  each holds at least as many units as the robot has parameters (``_least_units``).
* ``clusters``: groups of nearby configurations (k-means over all joint readings), each
  held out in turn: regions of the workspace rather than ranges of one joint.
* ``datasets``: each dataset held out in turn, when there are several (another
  placement of the instrument, another day).

The last three are *extrapolating* schemes. Residual entries that belong to no unit
(fold -1) always stay in the training part.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

RANGES = 4  # contiguous ranges per joint
HALVES = 2  # the coarsest split of a joint's range: fit one half, predict the other
HALVES_TOLERANCE = 1.0  # an effect may at most double a held-out half's squared error
CLUSTERS = 5
MIN_UNITS_PER_FOLD = 3  # a scheme needs at least this many units in every fold
MIN_SPAN = {True: 0.05, False: 0.005}  # [rad] revolute, [m] prismatic: below, a joint is still


@dataclass(frozen=True)
class FoldScheme:
    """Fold number per residual entry (-1: always trained on) and what it holds out.

    ``tolerance``: for an extrapolating scheme, by how much (relative) an effect may grow
    its held-out squared error; None: the judge's default.
    """

    name: str
    fold: np.ndarray
    extrapolating: bool
    tolerance: float | None = None  # growth of its held-out squared error an effect may cause

    @property
    def count(self) -> int:
        return int(self.fold.max()) + 1 if self.fold.size and self.fold.max() >= 0 else 0

    def __repr__(self) -> str:
        return f"FoldScheme({self.name!r}, {self.count} folds)"


@dataclass(frozen=True)
class _Units:
    """The units of a problem: one key per residual entry and mean joints per unit."""

    entry_unit: np.ndarray  # index into ``joints`` per residual entry, -1 for none
    joints: np.ndarray  # (units x dof) mean joint readings [rad or m]
    dataset: np.ndarray  # dataset index per unit


def _units(problem) -> _Units:
    entry_unit: list[np.ndarray] = []
    joints: list[np.ndarray] = []
    dataset: list[int] = []
    for k, model in enumerate(problem.models):
        groups = np.asarray(model.residual_groups())
        row_units = np.asarray(model.row_units())
        readings = model.dataset.joints
        ids = np.unique(groups[groups >= 0])
        start = len(joints)
        if readings is not None and len(row_units):
            # Mean joint readings of each unit's rows.
            index = np.searchsorted(ids, row_units)
            inside = (index < len(ids)) & (ids[np.minimum(index, len(ids) - 1)] == row_units)
            sums = np.zeros((len(ids), readings.shape[1]))
            np.add.at(sums, index[inside], readings[inside])
            counts = np.bincount(index[inside], minlength=len(ids))[:, None]
            means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        else:
            means = np.full((len(ids), problem.robot.dof), np.nan)
        joints.extend(means)
        dataset.extend([k] * len(ids))
        index = np.searchsorted(ids, groups)
        unit = np.full(len(groups), -1)
        valid = groups >= 0
        unit[valid] = start + index[valid]
        entry_unit.append(unit)
    dof = problem.robot.dof
    return _Units(np.concatenate(entry_unit) if entry_unit else np.zeros(0, int),
                  np.array(joints).reshape(-1, dof), np.array(dataset, dtype=int))


def _entry_folds(units: _Units, unit_fold: np.ndarray) -> np.ndarray:
    fold = np.full(len(units.entry_unit), -1)
    has = units.entry_unit >= 0
    fold[has] = unit_fold[units.entry_unit[has]]
    return fold


def _enough(unit_fold: np.ndarray, count: int, least: int = MIN_UNITS_PER_FOLD) -> bool:
    sizes = np.bincount(unit_fold[unit_fold >= 0], minlength=count)
    return count >= 2 and bool(np.all(sizes >= least))


def _least_units(problem, parts: int, tolerance: float | None) -> int:
    """The fewest units a fold of a joint's range must hold. A half is judged only when it
    holds at least as many units as the robot has parameters: the geometry refitted on
    one half must be fixed by that half's own data (each bar or artifact placement brings
    unknowns of its own) for its prediction of the other half to say anything about an
    effect; on fewer, a true effect can fail the halves merely because the half-fit is
    weak (a gear-ratio error on 60 bar placements grew a half's squared error 5.7x)."""
    if parts != HALVES or tolerance is None:
        return MIN_UNITS_PER_FOLD
    return max(MIN_UNITS_PER_FOLD, int(problem.mask("robot").sum()))


def _kmeans(points: np.ndarray, count: int, seed: int, iterations: int = 30) -> np.ndarray:
    """Cluster labels of ``points`` (k-means, k-means++ start, fixed seed)."""
    rng = np.random.default_rng(seed)
    centres = [points[rng.integers(len(points))]]
    for _ in range(1, count):
        distance = np.min([np.sum((points - c) ** 2, axis=1) for c in centres], axis=0)
        total = distance.sum()
        if total <= 0:
            break
        centres.append(points[rng.choice(len(points), p=distance / total)])
    centres_array = np.array(centres)
    labels = np.zeros(len(points), dtype=int)
    for _ in range(iterations):
        distance = ((points[:, None, :] - centres_array[None]) ** 2).sum(axis=2)
        labels = np.argmin(distance, axis=1)
        moved = np.array([points[labels == c].mean(axis=0) if np.any(labels == c)
                          else centres_array[c] for c in range(len(centres_array))])
        if np.allclose(moved, centres_array):
            break
        centres_array = moved
    return labels


def _contiguous(values: np.ndarray, parts: int) -> np.ndarray:
    """Fold per unit: ``parts`` contiguous ranges of ``values`` with equal numbers of
    units (ties broken by order)."""
    rank = np.argsort(np.argsort(values, kind="stable"), kind="stable")
    return (rank * parts) // len(values)


def fold_schemes(problem, folds: int = 5, seed: int = 0) -> list[FoldScheme]:
    """Every fold scheme the problem's data allow (see the module docstring)."""
    units = _units(problem)
    n_units = len(units.joints)
    schemes: list[FoldScheme] = []
    if n_units >= 3:
        count = min(folds, n_units)
        order = np.random.default_rng(seed).permutation(n_units)
        unit_fold = np.empty(n_units, dtype=int)
        unit_fold[order] = np.arange(n_units) % count
        schemes.append(FoldScheme("units", _entry_folds(units, unit_fold), False))
    finite = np.all(np.isfinite(units.joints), axis=1)
    if n_units >= RANGES * MIN_UNITS_PER_FOLD and finite.all():
        for j, joint in enumerate(problem.robot.joints):
            values = units.joints[:, j]
            if np.ptp(values) < MIN_SPAN[joint.revolute]:
                continue
            for parts, word, tolerance in ((RANGES, "ranges", None),
                                           (HALVES, "halves", HALVES_TOLERANCE)):
                unit_fold = _contiguous(values, parts)
                if _enough(unit_fold, parts, _least_units(problem, parts, tolerance)):
                    schemes.append(FoldScheme(f"q{j + 1} {word}",
                                              _entry_folds(units, unit_fold), True,
                                              tolerance=tolerance))
        if n_units >= CLUSTERS * MIN_UNITS_PER_FOLD:
            scale = np.array([1.0 if j.revolute else 10.0 for j in problem.robot.joints])
            labels = _kmeans(units.joints * scale, CLUSTERS, seed)
            if _enough(labels, int(labels.max()) + 1):
                schemes.append(FoldScheme("clusters", _entry_folds(units, labels), True))
    if len(problem.models) > 1 and _enough(units.dataset, len(problem.models)):
        schemes.append(FoldScheme("datasets", _entry_folds(units, units.dataset), True))
    return schemes


SEPARATING_SHARE = 0.2  # of the units: those where two rival effects differ most


def entry_units(problem) -> np.ndarray:
    """The unit (index) each residual entry of ``problem`` belongs to; -1 for none."""
    return _units(problem).entry_unit


def separating_scheme(entry_unit: np.ndarray, score: np.ndarray,
                      share: float = SEPARATING_SHARE) -> FoldScheme | None:
    """One fold holding out the units whose residual entries' ``score`` (>= 0, one per
    entry) sums highest, ``share`` of the units (at least ``MIN_UNITS_PER_FOLD``); every
    other unit is always trained on. None when too few units would be left to train on.

    Sums within 1e-9 of the largest (relative) are ranked by their first unit, so the
    fold does not turn on the last bits of a sum."""
    valid = entry_unit >= 0
    n_units = int(entry_unit[valid].max()) + 1 if valid.any() else 0
    count = max(MIN_UNITS_PER_FOLD, int(round(share * n_units)))
    if n_units - count < MIN_UNITS_PER_FOLD:
        return None
    per_unit = np.bincount(entry_unit[valid], weights=score[valid], minlength=n_units)
    top = float(per_unit.max())
    if not top > 0:
        return None
    order = np.lexsort((np.arange(n_units), -np.round(per_unit / top, 9)))
    unit_fold = np.full(n_units, -1)
    unit_fold[order[:count]] = 0
    fold = np.full(len(entry_unit), -1)
    fold[valid] = unit_fold[entry_unit[valid]]
    return FoldScheme("separating", fold, True)


def _gram(Z: np.ndarray) -> np.ndarray:
    """``Z^T Z`` of one fold's rows (one array on both sides: the symmetric product,
    half the work of a general one)."""
    return Z.T @ Z


LSTSQ_RCOND = 1e-13  # relative singular value below which a fold's normal equations are cut
# A fold's training Gram of the base columns is solved once by its eigenvectors when its
# eigenvalues span less than this ratio; a few added columns are then a bordered solve.
# Beyond it (nearly dependent columns on the training part) every fit is the full
# truncated least-squares solve instead, whose cut-off then matters.
BORDERED_CONDITION = 1e10


@dataclass(frozen=True)
class _BaseFold:
    """One fold's fit of the base columns, reused for every fit that adds a few columns.

    ``shared``/``own``: the base columns with and without weight in the training rows;
    ``solved`` = ``Gt[shared, shared]^-1 Gt[shared, :]`` (None when ill-conditioned);
    ``own_inverse``: pseudo-inverse of the held-out Gram of the ``own`` columns;
    ``held_shared`` = ``Gf[shared, shared]``, ``held_own`` = ``Gf[own, shared]`` (copies
    read by every fit); ``train`` = ``total - Gf``.
    """

    shared: np.ndarray
    own: np.ndarray
    solved: np.ndarray | None
    own_inverse: np.ndarray
    held_shared: np.ndarray
    held_own: np.ndarray
    train: np.ndarray  # the training Gram ``total - Gf``, read row by row for added columns


class FoldGrams:
    """Per-fold Gram matrices of ``Z = [columns, r]`` for linear cross-validation.

    ``fold`` numbers the rows of ``Z`` (-1: always trained on); ``total`` may pass
    ``Z.T @ Z`` when several schemes share one ``Z``. The last column of ``Z`` is the
    residual [m]; the others are the linearised unknowns (any scaling).

    ``base`` (column indices) names columns most fits share: each fold's fit of them is
    factored once, and a fit of ``base`` plus a few more columns adds only their
    bordered (Schur complement) solve. Same numbers as the full solve, to rounding, as
    long as the training Gram is well conditioned; where it is not, the full solve runs.
    """

    def __init__(self, Z: np.ndarray, fold: np.ndarray, total: np.ndarray | None = None,
                 base: Sequence[int] | None = None):
        self.count = int(fold.max()) + 1 if fold.size and fold.max() >= 0 else 0
        self.parts = [_gram(Z[fold == f]) for f in range(self.count)]
        self.total = Z.T @ Z if total is None else total
        self.r = Z.shape[1] - 1
        self.base = None if base is None else np.asarray(base, dtype=int)
        self._base_folds: list[_BaseFold] | None = None

    def _local(self, Gt: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Which of the columns ``S`` have no weight in the training rows ``Gt``."""
        return np.diag(Gt)[S] <= 1e-12 * np.maximum(np.diag(self.total)[S], 1e-300)

    def _fold_sse(self, Gf: np.ndarray, S: np.ndarray) -> float:
        """Held-out squared residual of one fold after fitting ``S``: the full solve.

        Columns with no weight in the fold's training rows (that fold's own placement)
        are fitted on its held-out rows instead.
        """
        r = self.r
        Gt = self.total - Gf
        local = self._local(Gt, S)
        shared, own = S[~local], S[local]
        delta = np.linalg.lstsq(Gt[np.ix_(shared, shared)], Gt[shared, r],
                                rcond=LSTSQ_RCOND)[0]
        sse = Gf[r, r] - 2 * delta @ Gf[shared, r] + delta @ Gf[np.ix_(shared, shared)] @ delta
        if own.size:
            v = Gf[own, r] - Gf[np.ix_(own, shared)] @ delta
            sse -= v @ np.linalg.lstsq(Gf[np.ix_(own, own)], v, rcond=LSTSQ_RCOND)[0]
        return max(float(sse), 0.0)

    def _prepared(self) -> list[_BaseFold]:
        """Each fold's factored fit of ``base`` (computed on first use)."""
        if self._base_folds is None:
            assert self.base is not None
            out = []
            for Gf in self.parts:
                Gt = self.total - Gf
                local = self._local(Gt, self.base)
                shared, own = self.base[~local], self.base[local]
                eigenvalues, vectors = np.linalg.eigh(Gt[np.ix_(shared, shared)])
                solved = None
                if not shared.size or eigenvalues[0] > eigenvalues[-1] / BORDERED_CONDITION:
                    solved = vectors @ ((vectors.T @ Gt[shared, :]) / eigenvalues[:, None])
                own_inverse = np.linalg.pinv(Gf[np.ix_(own, own)], rcond=LSTSQ_RCOND) \
                    if own.size else np.zeros((0, 0))
                out.append(_BaseFold(shared, own, solved, own_inverse,
                                     Gf[np.ix_(shared, shared)], Gf[np.ix_(own, shared)], Gt))
            self._base_folds = out
        return self._base_folds

    def _bordered_sse(self, Gf: np.ndarray, fit: _BaseFold, extra: np.ndarray) -> float | None:
        """Held-out squared residual of one fold after fitting ``base`` + ``extra``, from
        the base's factored fit; None when the full solve must decide.

        The added columns' rows of the training and held-out Grams are taken once and
        sliced (every fit of every candidate passes here: it is the screening's loop)."""
        if fit.solved is None:
            return None
        r = self.r
        if extra.size and self._local_extra(Gf, extra).any():
            return None
        delta_base = fit.solved[:, r]
        delta_extra = np.zeros(0)
        held = Gf[extra]  # the added columns' rows of the held-out Gram
        if extra.size:
            train = fit.train[extra]  # ... and of the training Gram
            train_extra, train_cross, train_r = train[:, extra], train[:, fit.shared], train[:, r]
            coupled = fit.solved[:, extra]  # Gt[shared, shared]^-1 Gt[shared, extra]
            schur = train_extra - train_cross @ coupled
            schur = 0.5 * (schur + schur.T)
            scale = max(float(np.max(np.diag(train_extra))), 1e-300)
            if np.linalg.eigvalsh(schur)[0] <= scale / BORDERED_CONDITION:
                return None
            delta_extra = np.linalg.solve(schur, train_r - train_cross @ delta_base)
            delta_base = delta_base - coupled @ delta_extra
        # |r_f - Z_f delta|^2 on the held-out rows, by blocks (base, extra).
        held_cross = held[:, fit.shared]
        sse = (Gf[r, r] - 2 * (delta_base @ Gf[fit.shared, r] + delta_extra @ Gf[extra, r])
               + delta_base @ fit.held_shared @ delta_base
               + 2 * delta_extra @ held_cross @ delta_base
               + delta_extra @ held[:, extra] @ delta_extra)
        if fit.own.size:
            v = Gf[fit.own, r] - fit.held_own @ delta_base - Gf[np.ix_(fit.own, extra)] \
                @ delta_extra
            sse -= v @ fit.own_inverse @ v
        return max(float(sse), 0.0)

    def _local_extra(self, Gf: np.ndarray, extra: np.ndarray) -> np.ndarray:
        """``_local`` for a few columns, without forming the training Gram."""
        train = np.diag(self.total)[extra] - np.diag(Gf)[extra]
        return train <= 1e-12 * np.maximum(np.diag(self.total)[extra], 1e-300)

    def held_out_sse(self, columns: Sequence[int]) -> float:
        """Sum over folds of the held-out squared residual after fitting ``columns``.

        Columns with no weight in a fold's training rows (that fold's own placement) are
        fitted on its held-out rows instead.
        """
        if not self.count:
            return float("nan")
        S = np.asarray(columns, dtype=int)
        extra = None
        if self.base is not None and len(S) >= len(self.base) \
                and np.array_equal(S[:len(self.base)], self.base):
            extra = S[len(self.base):]
        total = 0.0
        for f, Gf in enumerate(self.parts):
            sse = None if extra is None else self._bordered_sse(Gf, self._prepared()[f], extra)
            total += self._fold_sse(Gf, S) if sse is None else sse
        return total
