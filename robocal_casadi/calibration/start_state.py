"""The side of the play a joint starts a table on, fitted on held-out data.

Backlash and hysteresis read the direction of motion from the row order
(``effects.motion``): from the second row on it is known, but before a joint first moves
in a table nobody knows from which side the robot came to it, and the rows there are
given direction 0, the middle of the play. A real joint is never in the middle: it rests
against one side. On held-out data that are a table of their own (a later run, the rest
of a session measured after the fit data) the first row then misses by half the play
times the arm's reach, which at a tracker's noise is tens of times the noise and holds
the whole table's RMS well above the floor.

So, like the placement of the instrument, this unknown of the held-out table is fitted:
for each joint (or motor of a differential, ``direction_m{k}``) an effect reads the
direction of, the rows of unknown direction get the
value among -1, 0 and +1 (came from below, unknown, came from above) that fits them best
under the calibrated model, the other joints' values kept. 0 stays where the data do
not favour a side (a table that starts where the simulator starts, at rest in the
middle). The fit data are left as they are: their few such rows weigh little against
hundreds, and the effect's size is estimated from the rows where the direction is
known.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..effects.base import Effect
from ..effects.motion import is_direction_column, is_motor_direction_column, with_directions
from .evaluation import evaluate

SIDES = (0.0, -1.0, 1.0)  # tried in this order: a side must fit better than the middle


def settle_start(robot, datasets: Sequence, effects: Sequence[Effect], values: dict,
                 kinematics=None) -> tuple:
    """``datasets`` with the direction of motion of their rows before each joint's first
    move chosen to fit best (see the module docstring), as explicit ``direction_q{j}``
    extras; datasets without such rows, or effects that read no direction, unchanged.

    ``values`` the calibrated unknowns by name (robot, effects, mounted instrument); the
    placements are fitted on each dataset first, at the middle of the play.
    """
    columns = sorted({c for e in effects for c in e.required_columns()
                      if is_direction_column(c) or is_motor_direction_column(c)})
    if not columns:
        return tuple(datasets)
    out = []
    for dataset in datasets:
        if dataset.joints is None:
            out.append(dataset)
            continue
        derived = with_directions(dataset.joints, dataset.extras, dataset.robot)
        extras = dict(dataset.extras)
        extras.update({c: np.array(derived[c], dtype=float) for c in columns})
        unknown = {c: np.flatnonzero(extras[c] == 0) for c in columns}
        unknown = {c: rows for c, rows in unknown.items() if rows.size}
        if not unknown:
            out.append(dataset)
            continue
        for column, rows in unknown.items():
            extras[column][rows] = _best_side(robot, dataset, extras, column, rows, effects,
                                              values, kinematics)
        out.append(replace(dataset, extras=extras))
    return tuple(out)


def _best_side(robot, dataset, extras: dict, column: str, rows: np.ndarray,
               effects: Sequence[Effect], values: dict, kinematics) -> float:
    """The value of ``column`` at ``rows`` among ``SIDES`` with the smallest squared error
    of those rows, each side tried on its own copy of the data (a problem holds its data
    as built), the placement fitted for each."""
    best, best_sse = SIDES[0], np.inf
    for side in SIDES:
        trial = dict(extras)
        trial[column] = np.array(extras[column], dtype=float)
        trial[column][rows] = side
        problem, x = evaluate(robot, [replace(dataset, extras=trial)], effects, values,
                              kinematics=kinematics)
        errors = problem.errors(x)[0]
        chosen = np.isin(problem.models[0].error_rows(), rows)
        sse = float(np.sum(errors[chosen] ** 2))
        if sse < best_sse:
            best, best_sse = side, sse
    return best
