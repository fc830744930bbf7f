"""Hysteresis: a direction-dependent offset that builds up smoothly after each reversal.

    z_j    = d_j (1 - 2 exp(-s_j / w_j))          [1], in [-1, 1]
    dq_j   = -(h_j / 2) z_j                        [rad], joint space

``h_j`` [rad] (parameter ``h{j}``, >= 0) is the width of joint j's hysteresis loop: the
difference, at one reading, between the arm side's angle approached from below and from
above. ``d_j = direction_q{j}`` in {-1, 0, +1} is the direction of motion of the reading
and ``s_j = travel_q{j}`` [rad] how far the reading has moved since that direction last
changed, both from the row order of the dataset (``motion``). Friction and the stretch
of cables or belts hold the arm side back while the motor turns on: just after a
reversal it still lags the other way (``z = -d``), and over a travel of a few
``w_j`` it comes over to lag by ``h/2`` against the new direction (``z -> d``).
``w_j`` [rad] is the stated transition angle of the joint's drive (``TRANSITION``), not
fitted, so the model stays linear in ``h``. Backlash is the sharp limit ``w -> 0``.
Rows of unknown direction (before the joint first moves) sit in the middle of the loop.
The state just after a reversal is taken as fully saturated the other way, as it is
whenever the moves between rows exceed a few ``w``.

Plausible on real robots, by the joint's drive (``HYSTERESIS``): a loop below 0.1 deg
for gear trains, 0.05 deg for cycloidal reducers and strain-wave gears (whose catalogues
give a hysteresis loss of an arc minute or two), 0.5 deg for belts, 2 deg for cables
(friction on the pulleys and cable stretch), 0.02 deg for direct drives. Diagnosis
looks for it on joints whose drive is not a gear train (``drives``); on geared joints
the same signature is ``backlash``.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..common.units import Units
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import check_joints, column
from .drives import per_drive
from .motion import direction_column, travel_column

DEG = math.pi / 180.0
HYSTERESIS = per_drive(
    Plausible(0.1 * DEG, sign=+1, basis="lost motion of gear trains: below 0.1 deg"),
    cycloid=Plausible(0.05 * DEG, sign=+1, basis="cycloidal reducers: a few arc minutes"),
    harmonic=Plausible(0.05 * DEG, sign=+1, basis="strain-wave gears: a hysteresis loss of "
                       "an arc minute or two"),
    belt=Plausible(0.5 * DEG, sign=+1, basis="belt drives: friction and stretch, below "
                   "about 0.5 deg"),
    cable=Plausible(2.0 * DEG, sign=+1, basis="cable drives: friction on the pulleys and "
                    "cable stretch, up to about 2 deg"),
    direct=Plausible(0.02 * DEG, sign=+1, basis="a direct drive has only its bearings' "
                     "friction: below 0.02 deg"))
# Travel [rad] over which the offset comes over to the new direction, per drive.
TRANSITION = {"gear": 0.02 * DEG, "cycloid": 0.02 * DEG, "harmonic": 0.1 * DEG,
              "belt": 0.5 * DEG, "cable": 1.0 * DEG, "direct": 0.05 * DEG}


class Hysteresis(Effect):
    """``dq_j = -(h_j / 2) d_j (1 - 2 exp(-s_j / w_j))`` for each joint j in ``joints``."""

    name = "hysteresis"
    title = "Hysteresis"
    unit = "rad"
    typical = 2e-4
    sentence = "hysteresis: {values}"
    plot_variable = "direction"
    revolute_only = True
    drives = ("cable", "belt", "harmonic", "direct")
    simulation_default = (1e-3,)
    tracker_only = True
    formula = ("q_true = q_read - (h / 2) d (1 - 2 exp(-s / w)), d the direction of motion and\n"
               "      s the travel since it last changed (row order), w the drive's transition "
               "angle (tracker data only)")

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"h{j}" for j in self.joints)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return HYSTERESIS[drive]

    def required_columns(self) -> tuple[str, ...]:
        return tuple(c for j in self.joints for c in (direction_column(j), travel_column(j)))

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot, revolute_only=True)
        entries = {}
        for k, j in enumerate(self.joints):
            w = TRANSITION[row.robot.drive(j)]
            state = row.extras[direction_column(j)] * (
                1 - 2 * ca.exp(-row.extras[travel_column(j)] / w))
            entries[j - 1] = -0.5 * theta[k] * state
        return column(entries, row.robot.dof), None

    def describe(self, values, units: Units) -> str:
        a = units.angle_scale
        parts = "; ".join(f"joint {k[1:]} lags by {v / a:.3g} {units.angle} between its two "
                          "directions of motion" for k, v in values.items())
        return self.sentence.format(values=parts)

    def plot_values(self, robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The joint's direction of motion (-1, 0, +1)."""
        return np.asarray(extras[direction_column(joint)], dtype=float)

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """The loop's offset at the direction and travel in ``extras`` (the simulator's own,
        from the order of the readings it writes), the true robot's drives' transitions."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j in self.joints:
            d = np.asarray(extras[direction_column(j)], dtype=float)
            s = np.asarray(extras[travel_column(j)], dtype=float)
            w = TRANSITION[world.robot.drive(j)]
            dq[:, j - 1] = -0.5 * values[f"h{j}"] * (d - 2.0 * d * np.exp(-s / w))
        return dq
