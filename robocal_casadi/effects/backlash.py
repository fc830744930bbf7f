"""Backlash: a joint lags by its play against the direction it last moved in.

    dq_j = -(b_j / 2) * direction_q{j}          [rad], joint space

``b_j`` [rad] (parameter ``b{j}``, >= 0) is the play of revolute joint j's gear train,
``direction_q{j}`` in {-1, 0, +1} the direction of motion of its reading, from the row
order of the dataset (``motion``): the sign of the change since the previous row, the
last known direction where the reading did not change, 0 on the first row and until
the joint first moves. The motor side is read; the arm side, driven through the play,
trails it by half the play in the direction of motion, so moving up it stands ``b/2``
below the reading and moving down ``b/2`` above. Rows of unknown direction sit in the
middle of the play.

Plausible on real robots, by the joint's drive: ``0 <= b_j <= 0.1 deg`` (1.7e-3 rad) for
gear trains, 0.05 deg for cycloidal reducers (a few arc minutes of lost motion), 0.2 deg
for toothed belts; strain-wave gears, preloaded cables and direct drives have no play to
speak of (0.02 deg). Diagnosis looks for backlash on geared joints (gear, cycloid) only;
on the others a direction-dependent error is friction ``hysteresis``.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..common.units import Units
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import check_joints, column
from .drives import per_drive
from .motion import direction_column

PLAY = per_drive(
    Plausible(math.radians(0.1), sign=+1, basis="gear play of robot joints: 0 .. 0.1 deg"),
    cycloid=Plausible(math.radians(0.05), sign=+1,
                      basis="lost motion of cycloidal reducers: a few arc minutes"),
    belt=Plausible(math.radians(0.2), sign=+1, basis="toothed belts: up to about 0.2 deg"),
    harmonic=Plausible(math.radians(0.02), sign=+1,
                       basis="strain-wave gears have no play, about 1 arc minute at most"),
    cable=Plausible(math.radians(0.02), sign=+1, basis="preloaded cables have no play"),
    direct=Plausible(math.radians(0.02), sign=+1, basis="a direct drive has no gear play"))


class Backlash(Effect):
    """``dq_j = -(b_j / 2) direction_q{j}`` for each joint j in ``joints``."""

    name = "backlash"
    title = "Backlash"
    unit = "rad"
    typical = 2e-4
    sentence = "backlash: {values}"
    plot_variable = "direction"
    revolute_only = True
    drives = ("gear", "cycloid")
    simulation_default = (5e-4,)
    formula = "q_true = q_read - (b / 2) direction, the direction of motion from the row order"

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"b{j}" for j in self.joints)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return PLAY[drive]

    def required_columns(self) -> tuple[str, ...]:
        return tuple(direction_column(j) for j in self.joints)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot, revolute_only=True)
        entries = {j - 1: -0.5 * theta[k] * row.extras[direction_column(j)]
                   for k, j in enumerate(self.joints)}
        return column(entries, row.robot.dof), None

    def describe(self, values, units: Units) -> str:
        a = units.angle_scale
        parts = "; ".join(f"joint {k[1:]} has {v / a:.3g} {units.angle} of play"
                          for k, v in values.items())
        return self.sentence.format(values=parts)

    def plot_values(self, robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The joint's direction of motion (-1, 0, +1)."""
        return np.asarray(extras[direction_column(joint)], dtype=float)

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """Half the play against the direction in ``extras`` (the simulator's own, from the
        order of the readings it writes)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j in self.joints:
            dq[:, j - 1] = -0.5 * values[f"b{j}"] * np.asarray(extras[direction_column(j)])
        return dq
