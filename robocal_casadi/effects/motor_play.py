"""Play behind the motors of a differential: each motor's lag follows its own direction.

In joints driven together (``model.transmission``, motor angles ``m = M q`` over a group)
the encoders sit on the motors and the controller reports ``q_read = M^-1 m_read``. Play and
friction between a motor and the joints (cable stretch and pulley friction, gear lash) make
the arm side of motor k trail its reading by half its lost motion against the direction
the MOTOR last turned, whichever way each joint moves. With ``N`` the group's ``M`` with
each row divided by its largest magnitude (motor angles as the angles they make at the
joints, ``TransmissionGroup.normalised``):

    N q_true = N q_read - (1/2) b o d          [rad]
    dq_G     = -(1/2) N^-1 (b o d)             [rad], the group's joints

``b_k`` [rad] (parameter ``bm{k}``, >= 0) is motor k's lost motion as an angle at the joints
and ``d_k = direction_m{k}`` in {-1, 0, +1} the sign of the motor's motion ``M (q[i] -
q[i-1])`` since the previous row, from the row order of the dataset (``effects.motion``:
the last known direction where the motor did not move, 0 until it first moves). Motor k is
named after the k-th joint of its group. For a differential ``N = [[1, 1], [1, -1]]``: the
play of motor 2 moves both joints by ``b/4`` when it lags, in the same sense; that of motor
3 in opposite senses; a joint's own direction of motion says nothing of it.

The sharp form (no transition after a reversal): on data whose moves between readings
exceed a degree or so, a cable's friction loop has come over to the new direction.

Plausible on real robots, by the drive of the joint the motor is named after
(``MOTOR_PLAY``): as a joint's own lost motion on that drive, the larger of play
(``backlash``) and friction lag (``hysteresis``): 0.1 deg for gear trains, 0.05 deg for
cycloidal reducers and strain-wave gears, 0.5 deg for belts, 2 deg for cables, 0.02 deg
for direct drives. Diagnosis offers it for each motor of the groups the robot file
declares.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..common import exact
from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from ..model.transmission import TransmissionGroup, group_of
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import column
from .hysteresis import HYSTERESIS
from .motion import motor_direction_column

# A motor's play and friction lag seen at its joints: the sizes of a joint's own, per drive.
MOTOR_PLAY = HYSTERESIS


def _inverse(group: TransmissionGroup) -> np.ndarray:
    """``N^-1`` of the group's normalised transmission, one column at a time."""
    N = group.normalised
    n = len(N)
    return np.column_stack([exact.solve(N, np.eye(n)[:, k]) for k in range(n)])


class MotorPlay(Effect):
    """``dq_G = -(1/2) N^-1 (b o d_motors)`` over each group holding a motor in ``joints``
    (the motors, named after joints); see the module docstring."""

    name = "motor_play"
    title = "Play behind the motors"
    unit = "rad"
    typical = 2e-4
    sentence = "play behind the motors: {values}"
    plot_variable = "direction"
    revolute_only = True
    tracker_only = True
    simulation_default = (1e-3,)
    formula = ("q_true_G = q_read_G - N^-1 (b/2 d_motor), d_motor the direction of motion of "
               "each motor\n      (its motion M dq in the row order), N the group's "
               "transmission, rows scaled to joint angles (tracker data only)")

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"bm{k}" for k in self.joints)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return MOTOR_PLAY[drive]

    def required_columns(self) -> tuple[str, ...]:
        return tuple(motor_direction_column(k) for k in self.joints)

    def moved_joints(self, robot: Robot) -> tuple[int, ...]:
        """Every joint of the groups of the effect's motors."""
        return tuple(sorted({j for k in self.joints for j in self._group(robot, k).joints}))

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[MotorPlay, ...]:
        """One per motor of each declared transmission group."""
        return tuple(cls((k,)) for g in robot.transmission for k in g.joints)

    def _group(self, robot: Robot, motor: int) -> TransmissionGroup:
        group = group_of(robot.transmission, motor)
        if group is None:
            raise InputError(f"motor_play: motor {motor} belongs to no transmission group of "
                             f"the robot {robot.name!r}", where="effects")
        return group

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        entries: dict[int, Any] = {}
        for k, motor in enumerate(self.joints):
            group = self._group(row.robot, motor)
            share = _inverse(group)[:, group.motor_row(motor)]  # joint motion per motor rad
            lag = 0.5 * theta[k] * row.extras[motor_direction_column(motor)]
            for i, joint in enumerate(group.joints):
                if share[i] != 0:
                    entries[joint - 1] = entries.get(joint - 1, 0) - float(share[i]) * lag
        return column(entries, row.robot.dof), None

    def describe(self, values, units: Units) -> str:
        a = units.angle_scale
        parts = "; ".join(f"motor {k[2:]} lags by {values[k] / a:.3g} {units.angle} (at the "
                          "joints) between its two directions of motion"
                          for k in self.parameter_names() if k in values)
        return self.sentence.format(values=parts)

    def plot_values(self, robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The direction of motion (-1, 0, +1) of the motor named after ``joint``."""
        column_name = motor_direction_column(joint)
        if column_name in extras:
            return np.asarray(extras[column_name], dtype=float)
        return np.zeros(len(np.atleast_2d(Q)))

    # ----------------------------------------------------------------- simulation

    @classmethod
    def simulation_key(cls, text, robot: Robot, where: str = "effects"):
        """A motor: the number of a joint in a group of the robot file's transmission."""
        motor = super().simulation_key(text, robot, where)
        if group_of(robot.transmission, motor) is None:
            raise InputError(f"joint {motor} is in no group of the robot file's transmission, "
                             "so it names no motor of a differential", where=where)
        return motor

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """Each motor's lag at the motors' directions of motion in ``extras`` (the
        simulator's own, from the order of the readings it writes), mapped to the joints by
        solving the true robot's normalised transmission."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        groups: list[TransmissionGroup] = []
        for motor in self.joints:
            group = self._group(world.robot, motor)
            if group not in groups:
                groups.append(group)
        for group in groups:
            columns = [j - 1 for j in group.joints]
            lags = np.array([0.5 * values.get(f"bm{k}", 0.0) for k in group.joints])
            directions = np.column_stack([np.asarray(extras[motor_direction_column(k)],
                                                     dtype=float) for k in group.joints])
            for i in range(len(Q)):
                dq[i, columns] = -exact.solve(group.normalised, lags * directions[i])
        return dq

    @classmethod
    def for_simulation(cls, keys: Sequence) -> MotorPlay:
        return cls(tuple(int(k) for k in keys))
