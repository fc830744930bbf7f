"""Comparing criterion values so that rounding decides nothing.

An index computed through BLAS and LAPACK (eigenvalues of the trial designs' information,
singular values of a plan's Jacobian) differs between processors in its last digits,
about 1e-12 relative on the plans searched here. The search compares thousands of such
values; where two differ by less than ``RELATIVE`` they count as equal: the first in
index order wins a choice, and a change must gain more than that to be made. Then the
same candidates are chosen on every processor unless a value falls within rounding of
that margin, which a search meets about once in ``RELATIVE / 1e-12`` comparisons of
near-equal values.
"""

from __future__ import annotations

import numpy as np

RELATIVE = 1e-9  # criterion values closer than this (relative) count as equal


def _margin(value: float, relative: float, absolute: float) -> float:
    return relative * abs(value) + absolute


def first_best(scores: np.ndarray, relative: float = RELATIVE, absolute: float = 0.0) -> int:
    """The index of the first of ``scores`` (to maximise; ``-inf`` allowed) within
    ``relative * |best| + absolute`` of the largest."""
    scores = np.asarray(scores, dtype=float)
    best = float(np.max(scores))
    if not np.isfinite(best):
        return int(np.argmax(scores == best))  # all -inf, or the first +inf
    return int(np.argmax(scores >= best - _margin(best, relative, absolute)))


def clearly_greater(a: float, b: float, relative: float = RELATIVE,
                    absolute: float = 0.0) -> bool:
    """True when ``a`` exceeds ``b`` by more than ``relative * max(|a|, |b|) + absolute``
    (any finite value exceeds ``-inf``)."""
    if not np.isfinite(b):
        return b == -np.inf and a > b
    if not np.isfinite(a):
        return a == np.inf
    return a - b > _margin(max(abs(a), abs(b)), relative, absolute)
