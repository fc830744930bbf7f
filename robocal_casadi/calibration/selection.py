"""Data selection by condition number, as the published cross-bar method does it
(docs/methods.md#cross-bar-calibration).

Units of data (a bar or artifact placement, a tracker or laser reading) are taken in
the order recorded. Once the identifiable parameters are determined by what has been
taken, a unit is dropped when it makes the condition number of the column-scaled
identification Jacobian grow by more than ``growth`` (relative). The placement unknowns
are eliminated through the Schur complement of the information matrix, accumulated unit
by unit, so each step costs a small eigenvalue problem, not a new Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .problem import Problem


@dataclass(frozen=True)
class Selection:
    """Which units were kept and dropped, per dataset label, and the final condition number."""

    kept: dict[str, tuple[int, ...]]
    dropped: dict[str, tuple[int, ...]]
    condition_number: float

    def __repr__(self) -> str:
        dropped = sum(len(v) for v in self.dropped.values())
        kept = sum(len(v) for v in self.kept.values())
        return (f"Selection(kept {kept} units, dropped {dropped}, condition number "
                f"{self.condition_number:.4g})")


def _condition(information: np.ndarray) -> float:
    scale = np.sqrt(np.clip(np.diag(information), 1e-300, None))
    values = np.linalg.eigvalsh(information / np.outer(scale, scale))
    if values[0] <= values[-1] * 1e-14:
        return float("inf")
    return float(np.sqrt(values[-1] / values[0]))


def select_by_condition(problem: Problem, x: np.ndarray, identifiable, *,
                        growth: float = 0.05) -> Selection:
    """Keep units of data in order unless they grow the condition number by > ``growth``."""
    J = problem.jacobian(x)
    parameters = problem.unknowns.indices(list(identifiable))
    placement = np.flatnonzero(problem.mask("placement"))
    A_all, P_all = J[:, parameters], J[:, placement]
    AA = np.zeros((len(parameters), len(parameters)))
    AP = np.zeros((len(parameters), len(placement)))
    PP = np.zeros((len(placement), len(placement)))
    kept: dict[str, list[int]] = {}
    dropped: dict[str, list[int]] = {}
    current = float("inf")
    start = 0
    for model in problem.models:
        groups = model.residual_groups()
        entries = np.arange(start, start + len(groups))
        start += len(groups)
        kept[model.label], dropped[model.label] = [], []
        for group in dict.fromkeys(int(g) for g in groups if g >= 0):
            rows = entries[groups == group]
            A, P = A_all[rows], P_all[rows]
            trial = (AA + A.T @ A, AP + A.T @ P, PP + P.T @ P)
            schur = trial[0] - trial[1] @ np.linalg.pinv(trial[2], rcond=1e-12) @ trial[1].T
            condition = _condition(schur)
            if np.isfinite(current) and condition > current * (1 + growth):
                dropped[model.label].append(group)
                continue
            AA, AP, PP = trial
            current = condition
            kept[model.label].append(group)
    return Selection({k: tuple(v) for k, v in kept.items()},
                     {k: tuple(v) for k, v in dropped.items()}, current)
