"""A calibrated model evaluated on data: the measurement models of datasets and the
problem over them with only the placements of the instrument fitted (validation, the
delivery's candidates, the side of the play a held-out table starts on)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..effects.base import Effect
from ..measurement import model_for
from .problem import Problem
from .solver import Method, solve


def models_for(datasets: Sequence, prefix: str = "") -> list:
    """One measurement model per dataset, labelled by file stem (made unique)."""
    models = []
    seen: dict[str, int] = {}
    for dataset in datasets:
        label = prefix + Path(dataset.path).stem
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:
            label = f"{label}#{seen[label]}"
        models.append(model_for(dataset, label))
    return models



def refit_placement(problem: Problem, x: np.ndarray, *, method: Method = "lm") -> np.ndarray:
    """``x`` with only the placement unknowns re-solved (robot, effects, mounted held)."""
    return solve(problem, x, problem.mask("placement"), method=method).x


def evaluate(robot, datasets: Sequence, effects: Sequence[Effect], values: dict[str, float],
             label_prefix: str = "", kinematics=None) -> tuple[Problem, np.ndarray]:
    """Problem over ``datasets`` started at ``values`` (by name), placements re-fitted.

    ``kinematics`` of the same robot may be passed to reuse its CasADi functions.
    """
    problem = Problem(robot, models_for(datasets, label_prefix), effects, start=values,
                      kinematics=kinematics)
    return problem, refit_placement(problem, problem.initial())
