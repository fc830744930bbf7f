"""Which parameters the data can determine, and why the others cannot.

Described in docs/methods.md#identifiability.

Method: take the Jacobian of the residual at a start point, project out the columns of
the placement unknowns (they are always estimated), and measure every remaining column
as a fraction of its own unprojected length (so metres and radians compare, and what
the placement takes away counts). A column-pivoted QR then picks parameters; among
columns nearly as good, the earlier one in a preference order wins. A column is

* "invisible" when its unscaled norm is zero: it changes no residual (the all-zero
  column of the published cross-bar method, docs/methods.md#cross-bar-calibration);
* "absorbed by the placement" when its projection is zero: the placement unknowns make
  the same change (e.g. base parameters against an unknown tracker frame);
* "dependent" when it is a combination of columns already chosen (that method's "keep
  one of linearly dependent columns"); the combination is reported as a base-parameter
  relation.

"Zero" is exact up to ``EXACT_TOLERANCE`` (``tolerance=EXACT_TOLERANCE``: only null
directions are held, the rest is left to the prior, see ``prior``). With the default
``PRACTICAL_TOLERANCE`` a parameter whose own part is below 1% of its effect is treated
the same way, with the fraction in the reason: its standard error would be a hundred
times that of a well-determined one, and without a prior it is better held at its
nominal value than fitted to noise. The condition number is that of the identifiable
columns after projection, each scaled to unit length.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import SolverError
from ..results import Identifiability

RANK_TOLERANCE = 1e-7  # own part of a column below which it is exactly dependent
EXACT_TOLERANCE = 10 * RANK_TOLERANCE  # hold only what is exactly undeterminable
PRACTICAL_TOLERANCE = 1e-2  # own part below which the data cannot determine a parameter
PREFERENCE_BAND = 0.5  # a preferred column may be picked if it has half the best remaining norm


def preference(name: str) -> tuple:
    """Order in which equally informative parameters are kept.

    The mounted instrument first (its offset is the least known and belongs to the set-up,
    not to the robot), then standard DH parameters joint by joint, then the tool, then the
    base, then the Hayati ``beta`` (kept only where DH alone is degenerate).
    """
    if name.startswith(("probe_", "target_", "laser_")):
        return (0, 0, 0, name)
    if name.startswith("base_"):
        return (3, 0, 0, name)
    if name.startswith(("tool_", "flange_")):
        return (2, 0, 0, name)
    stem = name.rstrip("0123456789")
    joint = int(name[len(stem):]) if name[len(stem):] else 0
    if stem == "beta":
        return (4, joint, 0, name)
    if stem in DH_STEMS:
        return (1, joint, DH_STEMS.index(stem), name)
    if stem in URDF_STEMS:
        return (1, joint, URDF_STEMS.index(stem), name)
    return (5, 0, 0, name)


DH_STEMS = ("theta", "d", "a", "alpha")
URDF_STEMS = ("x", "y", "z", "roll", "pitch", "yaw")  # a URDF joint origin


def pivoted_qr_order(columns: np.ndarray, priority: Sequence[int],
                     tolerance: float = RANK_TOLERANCE) -> tuple[list[int], np.ndarray]:
    """Greedy column-pivoted Gram-Schmidt on unit columns.

    At each step, among the columns whose remaining norm is at least ``PREFERENCE_BAND``
    times the largest, picks the one with the smallest ``priority``: natural parameters
    win over equivalent ones while every pick stays well conditioned. Returns the chosen
    column indices and the remaining norms of all columns after the last pick.
    """
    A = columns.copy()
    chosen: list[int] = []
    remaining = np.linalg.norm(A, axis=0)
    available = list(range(A.shape[1]))
    while available:
        norms = remaining[available]
        best = norms.max()
        if not best >= tolerance:  # also stops on NaN: nothing left that can be chosen
            break
        ties = [available[k] for k in np.flatnonzero(norms >= best * PREFERENCE_BAND)]
        pick = min(ties, key=lambda j: priority[j])
        chosen.append(pick)
        available.remove(pick)
        v = A[:, pick] / np.linalg.norm(A[:, pick])
        A -= np.outer(v, v @ A)
        A[:, pick] = 0.0
        remaining = np.linalg.norm(A, axis=0)
    return chosen, remaining


def analyse(jacobian: np.ndarray, names: Sequence[str], candidates: Sequence[int],
            placement: Sequence[int], *, invisible_reason: str, absorbed_reason: str,
            tolerance: float = PRACTICAL_TOLERANCE) -> Identifiability:
    """Identifiability of the ``candidates`` columns of ``jacobian`` (indices into ``names``).

    ``placement`` columns are projected out first. Reasons are worded for the data kind.
    ``tolerance`` is the smallest own part of a column (fraction of its effect) that
    counts as determined.
    """
    J = np.asarray(jacobian, float)
    if not np.all(np.isfinite(J)):
        raise SolverError(f"the Jacobian holds {int(np.sum(~np.isfinite(J)))} non-finite "
                          f"entries: identifiability cannot be judged (degenerate data)")
    candidates = list(candidates)
    raw = J[:, candidates]
    raw_norms = np.linalg.norm(raw, axis=0)
    projected = _without_placement(J, raw, placement)
    projected_norms = np.linalg.norm(projected, axis=0)
    unidentifiable: dict[str, str] = {}
    practical: list[str] = []  # held because the data barely see them, not exactly
    usable = _screen([names[i] for i in candidates], raw_norms, projected_norms, tolerance,
                     invisible_reason, absorbed_reason, unidentifiable, practical)
    # Own part of each column as a fraction of its full effect.
    fraction = projected[:, usable] / raw_norms[usable]
    unit = projected[:, usable] / projected_norms[usable]
    priority = [preference(names[candidates[k]]) for k in usable]
    order = sorted(range(len(usable)), key=lambda j: priority[j])
    rank_of = {j: r for r, j in enumerate(order)}
    chosen, remaining = pivoted_qr_order(fraction, [rank_of[j] for j in range(len(usable))],
                                         tolerance)
    identifiable_local = [usable[j] for j in sorted(chosen, key=lambda j: usable[j])]
    usable_names = [names[candidates[k]] for k in usable]
    combinations = _combinations(unit, chosen, remaining, usable_names,
                                 projected_norms[usable], unidentifiable, practical)
    if identifiable_local:
        s = np.linalg.svd(projected[:, identifiable_local] /
                          projected_norms[identifiable_local], compute_uv=False)
        condition = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    else:
        s, condition = np.zeros(0), float("nan")
    return Identifiability(
        candidates=tuple(names[i] for i in candidates),
        identifiable=tuple(names[candidates[k]] for k in identifiable_local),
        unidentifiable=unidentifiable,
        singular_values=s,
        condition_number=condition,
        combinations=tuple(combinations),
        practical=tuple(practical),
    )


def _without_placement(J: np.ndarray, raw: np.ndarray, placement: Sequence[int]) -> np.ndarray:
    """The columns ``raw`` with what the ``placement`` columns of ``J`` can explain
    projected out (a copy of them without placement columns)."""
    if not len(placement):
        return raw.copy()
    P = J[:, list(placement)]
    U, s, _ = np.linalg.svd(P, full_matrices=False)
    U = U[:, s > s.max() * 1e-10] if s.size and s.max() > 0 else U[:, :0]
    return raw - U @ (U.T @ raw)


def _screen(names: list[str], raw_norms: np.ndarray, projected_norms: np.ndarray,
            tolerance: float, invisible_reason: str, absorbed_reason: str,
            unidentifiable: dict[str, str], practical: list[str]) -> list[int]:
    """The candidate columns (positions in ``names``) worth ranking; the others go into
    ``unidentifiable`` with the reason (and into ``practical`` when the data barely see
    them): no effect at all, or all or nearly all of it absorbed by the placement."""
    scale_reference = raw_norms.max() if raw_norms.size else 1.0
    usable = []
    for k, name in enumerate(names):
        if raw_norms[k] <= 1e-12 * max(scale_reference, 1e-300):
            if name.startswith("tool_"):
                unidentifiable[name] = ("changes no residual: the measured point is fixed to the "
                                        "flange, so the tool frame does not enter these data")
            else:
                unidentifiable[name] = f"changes no residual ({invisible_reason})"
        elif projected_norms[k] <= RANK_TOLERANCE * raw_norms[k] * 10:
            unidentifiable[name] = absorbed_reason
        elif projected_norms[k] < tolerance * raw_norms[k]:
            share = projected_norms[k] / raw_norms[k]
            unidentifiable[name] = (f"{absorbed_reason}, all but {100 * share:.2g}% of its effect:"
                                    f" too little for these data to determine it")
            practical.append(name)
        else:
            usable.append(k)
    return usable


def _combinations(unit: np.ndarray, chosen: list[int], remaining: np.ndarray,
                  names: list[str], norms: np.ndarray, unidentifiable: dict[str, str],
                  practical: list[str]) -> list[str]:
    """``name ~ relation`` for each usable column (``unit``, unit length; ``names``,
    ``norms`` of the unscaled columns) left out of the ``chosen`` ones, which it
    (nearly) is a combination of; its reason goes into ``unidentifiable`` (and
    ``practical`` when only nearly)."""
    combinations: list[str] = []
    if not chosen:
        return combinations
    chosen_set = set(chosen)
    basis = unit[:, chosen]
    for j in range(len(names)):
        if j in chosen_set:
            continue
        name = names[j]
        coefficients, *_ = np.linalg.lstsq(basis, unit[:, j], rcond=None)
        # Back to unscaled columns: col_j = sum c_k (norm_j / norm_k) col_k.
        terms = []
        for c, k in sorted(zip(coefficients, chosen), key=lambda t: -abs(t[0])):
            factor = c * norms[j] / norms[k]
            if abs(c) > 1e-3:
                terms.append(f"{factor:+.4g}*{names[k]}")
        relation = " ".join(terms[:4]) + (" ..." if len(terms) > 4 else "")
        if remaining[j] <= RANK_TOLERANCE * 10:
            unidentifiable[name] = (f"a combination of parameters already identified "
                                    f"({name} acts like {relation})")
        else:
            unidentifiable[name] = (
                f"nearly a combination of parameters already identified ({name} acts "
                f"like {relation}; only {100 * remaining[j]:.2g}% of its effect is its "
                f"own): too little for these data to determine it")
            practical.append(name)
        combinations.append(f"{name} ~ {relation}")
    return combinations
