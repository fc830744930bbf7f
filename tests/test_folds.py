"""Cross-validation from per-fold Gram matrices against fits on the rows themselves."""

from __future__ import annotations

import numpy as np

from robocal_casadi.calibration.folds import FoldGrams

EPS = np.finfo(float).eps


def _rows_sse(Z: np.ndarray, fold: np.ndarray, columns: list[int]) -> float:
    """Held-out SSE by least squares on the rows: fit the columns with weight in the
    training rows there, then the held-out fold's own columns on its own rows."""
    r = Z[:, -1]
    total = 0.0
    for f in range(int(fold.max()) + 1):
        train, held = fold != f, fold == f
        weight = np.linalg.norm(Z[train][:, columns], axis=0)
        shared = [c for c, w in zip(columns, weight) if w > 0]
        own = [c for c, w in zip(columns, weight) if w == 0]
        delta = np.linalg.lstsq(Z[train][:, shared], r[train], rcond=None)[0]
        error = r[held] - Z[held][:, shared] @ delta
        if own:
            block = Z[held][:, own]
            error = error - block @ np.linalg.lstsq(block, error, rcond=None)[0]
        total += float(error @ error)
    return total


def _case(seed: int):
    """Rows in 5 folds (some always trained on), 6 shared columns, one column per fold
    that only that fold's rows carry (a placement of its own), 4 candidate columns."""
    rng = np.random.default_rng(seed)
    n, folds = 200, 5
    fold = np.repeat(np.arange(folds), n // folds)
    fold[:7] = -1
    shared = rng.normal(size=(n, 6))
    own = np.zeros((n, folds))
    for f in range(folds):
        own[fold == f, f] = rng.normal(size=int(np.sum(fold == f)))
    candidates = rng.normal(size=(n, 4))
    r = shared @ rng.normal(size=6) + candidates[:, :2] @ [0.3, -0.2] + rng.normal(size=n)
    return np.column_stack([shared, own, candidates, r]), fold


def test_base_plus_candidates_matches_fits_on_the_rows() -> None:
    for seed in range(3):
        Z, fold = _case(seed)
        base = list(range(11))
        grams = FoldGrams(Z, fold, base=base)
        plain = FoldGrams(Z, fold)
        for extra in ([], [11], [12, 13], [11, 12, 13, 14]):
            columns = base + extra
            expected = _rows_sse(Z, fold, columns)
            # Both from normal equations of a well-conditioned Gram: rounding only.
            assert abs(grams.held_out_sse(columns) - expected) <= 1e-10 * expected
            assert abs(plain.held_out_sse(columns) - expected) <= 1e-10 * expected


def test_columns_the_base_already_holds_fall_back_to_the_full_solve() -> None:
    Z, fold = _case(4)
    base = list(range(11))
    grams = FoldGrams(Z, fold, base=base)
    # A repeated column makes the bordered system singular; the truncated full solve
    # gives the fit of the base alone.
    repeated = grams.held_out_sse(base + [3])
    alone = _rows_sse(Z, fold, base)
    assert abs(repeated - alone) <= 1e-8 * alone
    # Columns not starting with the base take the full solve too.
    other = [0, 1, 2, 11, 12]
    assert abs(grams.held_out_sse(other) - _rows_sse(Z, fold, other)) \
        <= 1e-10 * _rows_sse(Z, fold, other)
