"""Direction of motion of each joint, from the order of a dataset's rows.

A table lists its rows in the order they were measured. Row i's direction of motion of
joint j is the sign of the change of its reading since the previous row:

    direction_q{j}[i] = sign(q_j[i] - q_j[i-1])          in {-1, 0, +1}

A row with no change keeps the last known direction; the first row of a dataset, and
rows before the first change, have direction 0 (unknown). The directions belong to the
whole table in recorded order: placements of an artifact follow one another in that
order (the robot moves from the last touch of one placement to the first of the next),
and the directions are computed once per dataset from its full table, never from a part
of it. A dataset cut down to some of its rows (data selection) carries the directions of
its full table in ``extras``; cross-validation and the placement refits of validation use
the same per-row values as the fit.

A second derived input, the travel of joint j's reading since its direction of motion
last changed (friction ``hysteresis`` follows it), is ``travel_q{j}`` [rad or m]:

    travel_q{j}[i] = |q_j[i] - q_j[i-1]|                    where the direction changed
                   = travel_q{j}[i-1] + |q_j[i] - q_j[i-1]|  where it did not
                   = travel_q{j}[i-1]                        where the reading did not change

0 on the first row; the first motion counts as a change of direction.

Per-row inputs derived here are named ``direction_q{j}`` and ``travel_q{j}`` (1-based)
and travel with the data columns of ``extras``.

Where joints are driven together (a differential, ``model.transmission``), each motor has
its own direction of motion, the sign of its motion ``M (q[i] - q[i-1])`` over its group's
joints (kept where it did not move, 0 until it first moves): ``direction_m{k}``, motor k
named after the k-th joint of its group. It needs the robot's transmission, so the
functions that derive it take the robot.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import InputError

PREFIX = "direction_q"
TRAVEL = "travel_q"
MOTOR = "direction_m"


def direction_column(joint: int) -> str:
    """The name of joint ``joint``'s (1-based) direction input: ``direction_q{joint}``."""
    return f"{PREFIX}{int(joint)}"


def travel_column(joint: int) -> str:
    """The name of joint ``joint``'s (1-based) travel since its last reversal:
    ``travel_q{joint}``."""
    return f"{TRAVEL}{int(joint)}"


def motor_direction_column(motor: int) -> str:
    """The name of motor ``motor``'s direction input: ``direction_m{motor}`` (a motor is
    named after a joint of its group, ``model.transmission``)."""
    return f"{MOTOR}{int(motor)}"


def is_direction_column(column: str) -> bool:
    return column.startswith(PREFIX) and column[len(PREFIX):].isdigit()


def is_motor_direction_column(column: str) -> bool:
    return column.startswith(MOTOR) and column[len(MOTOR):].isdigit()


def is_derived_column(column: str) -> bool:
    """Whether ``column`` is an input derived from the row order (direction or travel of a
    joint, direction of a motor)."""
    return is_direction_column(column) or is_motor_direction_column(column) or (
        column.startswith(TRAVEL) and column[len(TRAVEL):].isdigit())


def directions_of_motion(Q) -> np.ndarray:
    """Direction of motion (N x dof) in {-1, 0, +1} of readings ``Q`` (N x dof) in row
    order; see the module docstring."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    out = np.zeros(Q.shape)
    if len(Q) < 2:
        return out
    change = np.sign(np.diff(Q, axis=0))  # (N-1) x dof: row i+1 against row i
    last = np.zeros(Q.shape[1])
    for i, step in enumerate(change, start=1):
        last = np.where(step != 0, step, last)
        out[i] = last
    return out


def travel_since_reversal(Q) -> np.ndarray:
    """Travel (N x dof) [rad or m] of readings ``Q`` (N x dof) since each joint's direction
    of motion last changed, in row order; see the module docstring."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    directions = directions_of_motion(Q)
    out = np.zeros(Q.shape)
    for i in range(1, len(Q)):
        step = np.abs(Q[i] - Q[i - 1])
        reversed_ = directions[i] != directions[i - 1]
        out[i] = np.where(step == 0, out[i - 1], np.where(reversed_, step, out[i - 1] + step))
    return out


def motor_directions_of_motion(Q, robot) -> dict[str, np.ndarray]:
    """``direction_m{k}`` (N,) for every motor of ``robot``'s transmission groups at readings
    ``Q`` (N x dof) in row order; empty without a transmission."""
    from ..model.transmission import motor_directions

    out: dict[str, np.ndarray] = {}
    for group in getattr(robot, "transmission", ()):
        directions = motor_directions(Q, group)
        for k, motor in enumerate(group.joints):
            out[motor_direction_column(motor)] = directions[:, k]
    return out


def with_directions(joints, extras: Mapping[str, np.ndarray],
                    robot=None) -> dict[str, np.ndarray]:
    """``extras`` plus ``direction_q1..n`` and ``travel_q1..n`` of the full table ``joints``
    (N x dof), and with ``robot`` the directions of its motors (``direction_m{k}``), where
    ``extras`` does not hold them already (a table cut down keeps its own)."""
    out = dict(extras)
    if joints is None:
        return out
    directions = directions_of_motion(joints)
    travel = travel_since_reversal(joints)
    for j in range(1, directions.shape[1] + 1):
        out.setdefault(direction_column(j), directions[:, j - 1])
        out.setdefault(travel_column(j), travel[:, j - 1])
    if robot is not None:
        for name, values in motor_directions_of_motion(joints, robot).items():
            out.setdefault(name, values)
    return out


def direction_values(dataset, column: str) -> np.ndarray:
    """The per-row values of the derived input ``column`` (direction or travel of a joint,
    direction of a motor of ``dataset.robot``) for ``dataset`` (N,)."""
    if column in dataset.extras:
        return np.asarray(dataset.extras[column], dtype=float)
    if dataset.joints is None:
        return np.zeros(0)
    if is_motor_direction_column(column):
        found = motor_directions_of_motion(dataset.joints, dataset.robot)
        if column not in found:
            raise InputError(f"the effects need {column}, a motor the robot file's "
                             "transmission does not declare", file=dataset.robot_path,
                             where="transmission")
        return found[column]
    if is_direction_column(column):
        return directions_of_motion(dataset.joints)[:, int(column[len(PREFIX):]) - 1]
    return travel_since_reversal(dataset.joints)[:, int(column[len(TRAVEL):]) - 1]
