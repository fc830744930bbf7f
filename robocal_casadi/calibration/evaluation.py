"""A calibrated model evaluated on data: the measurement models of datasets and the
problem over them with only the placements of the instrument fitted (validation, the
delivery's candidates, the side of the play a held-out table starts on).

Held-out data taken at an instrument station the calibration data also used (the same
``station:`` in both dataset files) keep that station's placement as the calibration
data give it for the model evaluated (``held_out``): their errors are then measured in
the robot's own frame, and a robot that is wrong where the calibration put the
instrument shows it. Held-out data of other stations, or of none, have their placement
fitted on themselves, which hides any error a rigid motion of the instrument absorbs.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..effects.base import Effect
from ..instruments import model_for
from .problem import Problem, StationFrames
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
    """``x`` with only the placement unknowns re-solved (robot, effects, mounted held;
    the placements of stations the problem holds stay too)."""
    free = problem.free_placement()
    if not free.any():
        return np.asarray(x, dtype=float).copy()
    return solve(problem, x, free, method=method).x


def evaluate(robot, datasets: Sequence, effects: Sequence[Effect], values: dict[str, float],
             label_prefix: str = "", kinematics=None,
             frames: StationFrames | None = None) -> tuple[Problem, np.ndarray]:
    """Problem over ``datasets`` started at ``values`` (by name), placements re-fitted
    except those ``frames`` holds.

    ``kinematics`` of the same robot may be passed to reuse its CasADi functions.
    """
    problem = Problem(robot, models_for(datasets, label_prefix), effects, start=values,
                      kinematics=kinematics, frames=frames)
    return problem, refit_placement(problem, problem.initial())


def station_frames(robot, anchors: Sequence, effects: Sequence[Effect],
                   values: dict[str, float], stations: set[str | None],
                   kinematics=None) -> StationFrames | None:
    """The placements of ``stations`` fitted on the ``anchors`` (the calibration data of
    those stations) with the model ``values`` held; None when no anchor shares one."""
    chosen = [d for d in anchors if d.station is not None and d.station in stations]
    if not chosen:
        return None
    problem, x = evaluate(robot, chosen, effects, values, kinematics=kinematics)
    return StationFrames.of(problem, x)


def held_out(robot, datasets: Sequence, effects: Sequence[Effect], values: dict[str, float],
             anchors: Sequence = (), kinematics=None) -> tuple[Problem, np.ndarray]:
    """``evaluate`` of held-out ``datasets``: the stations they share with the calibration
    data ``anchors`` keep the placement those data give for this model (see the module
    docstring); the other placements are fitted on the held-out data."""
    stations = {d.station for d in datasets if d.station is not None}
    frames = station_frames(robot, anchors, effects, values, stations, kinematics) \
        if stations else None
    return evaluate(robot, datasets, effects, values, label_prefix="validation:",
                    kinematics=kinematics, frames=frames)
