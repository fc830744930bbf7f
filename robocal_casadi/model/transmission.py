"""Coupled joints: which motors drive which joints, and by what ratios.

In a differential drive (a cable-driven shoulder or wrist, a bevel-gear wrist) two or more
motors turn two or more joints together. A robot file declares each such group
(docs/formats.md#robot-file):

    transmission:
      - {joints: [2, 3], motors: [[1, 1], [1, -1]]}

``joints`` the coupled joints (1-based, revolute, each in at most one group) and
``motors`` a square matrix ``M`` [motor rad per joint rad] with

    m = M q_group                  motor angles from the group's joint angles [rad]

so a differential of ratio r is ``r [[1, 1], [1, -1]]``. ``M`` must be invertible (the
controller reads the joints as ``M^-1 m``). Motor k of a group is named after the group's
k-th joint: in the group above, motor 2 is the row ``[1, 1]`` and motor 3 the row
``[1, -1]``. Joints in no group are driven one motor each and are their own motor.

A motor's play or lag is stated as the angle it makes at the joints: its row of ``M``
divided by the row's largest magnitude (``normalised``), so a motor turning a joint
through a 50:1 reduction and one turning it directly give the same figure for the same
lost motion at the joint.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common import exact
from ..common.fields import check_keys, cut, mapping, number, require
from ..errors import InputError

GROUP_KEYS = ("joints", "motors")
# A transmission matrix whose condition number exceeds this maps a joint motion to no motor
# motion within the precision of the ratios: it is no transmission a controller can invert.
MAX_CONDITION = 1e8


@dataclass(frozen=True)
class TransmissionGroup:
    """One group of coupled joints: ``joints`` (1-based), ``motors`` the square matrix
    ``M`` [motor rad per joint rad] (rows: motors, columns: ``joints``), ``m = M q``."""

    joints: tuple[int, ...]
    motors: tuple[tuple[float, ...], ...]

    @property
    def matrix(self) -> np.ndarray:
        """``M`` (n x n) [1]."""
        return np.array(self.motors, dtype=float)

    @property
    def normalised(self) -> np.ndarray:
        """``M`` with each row divided by its largest magnitude: motor angles as the angles
        they make at the joints [rad] (see the module docstring)."""
        M = self.matrix
        return M / np.abs(M).max(axis=1, keepdims=True)

    def motor_row(self, motor: int) -> int:
        """The row of ``M`` of motor ``motor`` (named after a joint of the group)."""
        return self.joints.index(motor)


def group_of(groups: Sequence[TransmissionGroup], joint: int) -> TransmissionGroup | None:
    """The group holding ``joint`` (1-based), None where the joint is driven alone."""
    return next((g for g in groups if joint in g.joints), None)


def transmission_from_dict(raw: Any, joints: Sequence, *, file: str | Path | None
                           ) -> tuple[TransmissionGroup, ...]:
    """The ``transmission:`` list of a robot file, checked against its ``joints`` (the
    robot's joint entries, each with ``revolute``). ``InputError`` naming the key."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise InputError(f"expected a list of groups {{joints: [...], motors: [[...]]}}, got "
                         f"{cut(raw)}", file=file, where="transmission")
    groups: list[TransmissionGroup] = []
    seen: dict[int, int] = {}
    for g, entry in enumerate(raw):
        where = f"transmission[{g}]"
        mapping(entry, file=file, where=where, hint="{joints: [...], motors: [[...]]}")
        check_keys(entry, GROUP_KEYS, file=file, where=where)
        members = _joints(require(entry, "joints", file=file, where=where), joints, file=file,
                          where=f"{where}.joints")
        for j in members:
            if j in seen:
                raise InputError(f"joint {j} is already in transmission[{seen[j]}]; a joint "
                                 "belongs to one group at most", file=file,
                                 where=f"{where}.joints")
            seen[j] = g
        motors = _matrix(require(entry, "motors", file=file, where=where), len(members),
                         file=file, where=f"{where}.motors")
        groups.append(TransmissionGroup(members, motors))
    return tuple(groups)


def _joints(raw: Any, joints: Sequence, *, file, where: str) -> tuple[int, ...]:
    if not isinstance(raw, list) or len(raw) < 2:
        raise InputError(f"expected a list of two or more joint numbers, got {cut(raw)}",
                         file=file, where=where)
    out = []
    for value in raw:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"expected joint numbers, got {cut(value)}", file=file,
                             where=where)
        if not 1 <= value <= len(joints):
            raise InputError(f"joint {value} does not exist; the robot has joints "
                             f"1..{len(joints)}", file=file, where=where)
        if not joints[value - 1].revolute:
            raise InputError(f"joint {value} is prismatic; a transmission couples revolute "
                             "joints", file=file, where=where)
        if value in out:
            raise InputError(f"joint {value} is listed twice", file=file, where=where)
        out.append(int(value))
    return tuple(out)


def _matrix(raw: Any, n: int, *, file, where: str) -> tuple[tuple[float, ...], ...]:
    if not isinstance(raw, list) or len(raw) != n or \
            not all(isinstance(row, list) and len(row) == n for row in raw):
        raise InputError(f"expected a square {n} x {n} matrix (one row per motor, one column "
                         f"per joint of the group), got {cut(raw)}", file=file, where=where)
    rows = tuple(tuple(number(v, file=file, where=f"{where}[{i}][{k}]")
                       for k, v in enumerate(row)) for i, row in enumerate(raw))
    M = np.array(rows, dtype=float)
    for i, row in enumerate(M):
        if not np.any(row != 0):
            raise InputError(f"row {i} drives no joint", file=file, where=f"{where}[{i}]")
    singular = np.linalg.svd(M, compute_uv=False)
    if not singular[-1] > singular[0] / MAX_CONDITION:
        raise InputError("the matrix is not invertible: some motion of the joints turns no "
                         "motor", file=file, where=where)
    return rows


def transmission_to_dict(groups: Sequence[TransmissionGroup]) -> list[dict[str, Any]]:
    """The ``transmission:`` list of a robot file (ratios are unitless: no conversion)."""
    return [{"joints": list(g.joints), "motors": [[float(v) for v in row] for row in g.motors]}
            for g in groups]


def motor_directions(Q, group: TransmissionGroup) -> np.ndarray:
    """Direction of motion (N x n) in {-1, 0, +1} of the group's motors at readings ``Q``
    (N x dof) [rad] in row order: the sign of ``M (q[i] - q[i-1])`` restricted to the group,
    the last known direction where a motor did not move, 0 on the first row and until the
    motor first moves (as ``effects.motion`` does for joints)."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    columns = [j - 1 for j in group.joints]
    out = np.zeros((len(Q), len(columns)))
    if len(Q) < 2:
        return out
    steps = np.diff(Q[:, columns], axis=0)
    motion = exact.matmul(steps, group.matrix.T)  # (N-1) x n motor steps
    last = np.zeros(len(columns))
    for i, step in enumerate(np.sign(motion), start=1):
        last = np.where(step != 0, step, last)
        out[i] = last
    return out

