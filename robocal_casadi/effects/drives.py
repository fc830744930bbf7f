"""Plausible sizes of the effects per kind of drive.

A joint's ``drive`` (robot file, ``Robot.drive``) says how its motor turns it: a gear train
(``gear``, the default), a strain-wave gear (``harmonic``), a cycloidal reducer
(``cycloid``), a toothed belt (``belt``), cables over pulleys (``cable``) or the motor
itself (``direct``). Stiffness, play, friction hysteresis and the error of a transmission
ratio differ by orders of magnitude between them: a cable-driven joint yields a hundred
times more under load than a geared industrial joint, and its friction hysteresis is a
degree where a gearbox's play is a tenth of one. Each effect states its ranges per drive
with ``per_drive``; docs/methods.md#drives gives the numbers and where they come from.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

from ..model.robot import DEFAULT_DRIVE, DRIVES
from .base import Plausible

DEG = math.pi / 180.0


def per_drive(gear: Plausible, **others: Plausible) -> dict[str, Plausible]:
    """A complete table drive -> range: ``gear`` for every drive not given in ``others``."""
    unknown = set(others) - set(DRIVES)
    if unknown:
        raise ValueError(f"per_drive: unknown drive(s) {sorted(unknown)}")
    return {drive: others.get(drive, gear) for drive in DRIVES}


def scaled(table: Mapping[str, Plausible], factors: Mapping[str, float],
           basis: str) -> dict[str, Plausible]:
    """``table`` with each drive's maximum (and minimum) times ``factors[drive]`` (1 where
    not given), ``basis`` appended to the words."""
    out = {}
    for drive, limits in table.items():
        f = float(factors.get(drive, 1.0))
        out[drive] = replace(limits, maximum=limits.maximum * f, minimum=limits.minimum * f,
                             basis=f"{limits.basis}; {basis}" if f != 1.0 else limits.basis)
    return out


def drive_of(robot, joint: int | None) -> str:
    """The drive of ``joint`` (1-based) on ``robot``; ``gear`` without a robot or a joint."""
    if robot is None or joint is None or not 1 <= joint <= robot.dof:
        return DEFAULT_DRIVE
    return robot.drive(joint)


def _absurd_joints(effect, values: Mapping[str, float], robot) -> set[int | None]:
    """The joints of the estimates ``effect.implausibility`` refuses on ``robot``."""
    return {effect.parameter_joint(f.parameter) for f in effect.check_plausible(values, robot)
            if f.value == 0 or abs(f.value) > f.plausible.minimum}


def with_drive(robot, joint: int, drive: str):
    """``robot`` with joint ``joint``'s (1-based) drive set to ``drive``."""
    joints = list(robot.joints)
    joints[joint - 1] = replace(joints[joint - 1], drive=drive)
    return replace(robot, joints=tuple(joints))


def drives_allowing(effect, values: Mapping[str, float], robot
                    ) -> tuple[tuple[int, tuple[str, ...]], ...]:
    """Where ``values`` (name -> SI) of ``effect`` are refused only for their size on the
    drives ``robot`` has: per joint whose drive makes one of them absurd, the other drives
    under which every value of that joint is plausible, the nearest (smallest largest
    plausible magnitude) first. Empty when some absurd value has no joint, or no drive
    would allow it: then it is no matter of the drive."""
    if robot is None:
        return ()
    failing = _absurd_joints(effect, values, robot)
    if not failing or None in failing:
        return ()
    out = []
    for joint in sorted(j for j in failing if j is not None):
        if not 1 <= joint <= robot.dof:
            return ()
        own = [p for p in values if effect.parameter_joint(p) == joint]
        allowing = [d for d in DRIVES if d != robot.drive(joint)
                    and joint not in _absurd_joints(effect, values,
                                                    with_drive(robot, joint, d))]
        if not allowing:
            return ()
        allowing.sort(key=lambda d: max(effect.plausible(p, d).maximum for p in own))
        out.append((joint, tuple(allowing)))
    return tuple(out)
