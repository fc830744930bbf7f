"""Choosing ``count`` candidates: a greedy start, then exchanges (DETMAX-style).

Greedy: add, one at a time, the candidate that most increases ``log det`` of the
(pool-scaled, slightly regularised) information, which is defined even while the design
is still too small to identify everything. Exchange: for each chosen candidate in turn,
try every unchosen one in its place and keep the swap that most improves the user's
index; repeat passes until none improves it. Values that agree within rounding count as
equal (``compare``): the first candidate wins, and a swap must gain more than that.
"""

from __future__ import annotations

import numpy as np

from .compare import clearly_greater, first_best
from .indices import index_value, scaling, score
from .information import Information

GREEDY_RIDGE = 1e-6
LOG_DET_EQUAL = 1e-8  # log det values closer than this count as equal


def greedy(info: Information, count: int, rng: np.random.Generator) -> list[int]:
    """``count`` candidate indices chosen greedily for ``log det``."""
    A = info.matrices
    pool_diag = np.einsum("cii->i", A)[: info.m] / len(A)
    scale = 1.0 / np.sqrt(np.where(pool_diag > 0, pool_diag, 1.0))
    full_scale = np.concatenate([scale, np.ones(info.shared)])
    As = A * full_scale[None, :, None] * full_scale[None, None, :]
    chosen: list[int] = [int(rng.integers(len(A)))]
    current = As[chosen[0]].copy()
    ridge = GREEDY_RIDGE * np.eye(len(full_scale))
    while len(chosen) < count:
        trial = current[None] + As + ridge[None]
        sign, logdet = np.linalg.slogdet(trial)
        logdet = np.where(sign > 0, logdet, -np.inf)
        logdet[chosen] = -np.inf
        best = first_best(logdet, 0.0, LOG_DET_EQUAL)
        chosen.append(best)
        current += As[best]
    return chosen


def values(info: Information, index: str, matrices: np.ndarray) -> np.ndarray:
    """Index ``index`` of each design whose information is in ``matrices``."""
    return np.array([index_value(index, s) for s in info.spectra(matrices, scaling(index))])


def exchange(info: Information, chosen: list[int], index: str, *, max_passes: int = 20,
             progress=None, start: int = 1) -> tuple[list[int], int]:
    """Improve ``chosen`` by one-for-one swaps; returns the design and the swaps made.

    ``progress`` (a ``Progress`` counting starts) is told after every pass which start this
    is (``start``, 1-based), which pass of it and how many swaps it made so far."""
    chosen = list(chosen)
    A = info.matrices
    total = A[chosen].sum(axis=0)
    current = score(index, values(info, index, total[None])[0])
    swaps = 0
    for done in range(max_passes):
        improved = False
        for position in range(len(chosen)):
            base = total - A[chosen[position]]
            others = np.setdiff1d(np.arange(len(A)), chosen)
            trial = np.array([score(index, v)
                              for v in values(info, index, base[None] + A[others])])
            best = first_best(trial)
            if clearly_greater(trial[best], current):
                chosen[position] = int(others[best])
                total = base + A[chosen[position]]
                current = trial[best]
                swaps += 1
                improved = True
        if progress is not None:
            progress.update(start, f"pass {done + 1} ({swaps} swaps)")
        if not improved:
            break
    return chosen, swaps


def random_designs(info: Information, count: int, repeats: int,
                   rng: np.random.Generator) -> list[list[int]]:
    """``repeats`` random designs of ``count`` distinct candidates each."""
    n = len(info.matrices)
    return [list(rng.choice(n, size=count, replace=False)) for _ in range(repeats)]
