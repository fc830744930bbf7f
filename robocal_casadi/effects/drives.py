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


def _absurd(limits: Plausible, value: float) -> bool:
    """Whether ``value`` (SI) is absurd for ``limits``: not finite, of the wrong sign, or
    beyond the largest magnitude (smaller than real robots show is weak, not absurd)."""
    if not math.isfinite(value):
        return True
    if limits.sign and value * limits.sign < 0:
        return True
    return abs(value) > limits.maximum


def drives_allowing(effect, values: Mapping[str, float], robot
                    ) -> tuple[tuple[int, tuple[str, ...]], ...]:
    """Where ``values`` (name -> SI) of ``effect`` are refused only for their size on the
    drives ``robot`` has: per joint whose drive makes one of them absurd, the other drives
    under which every value of that joint is plausible, the nearest (smallest largest
    plausible magnitude) first. Empty when some absurd value has no joint, or no drive
    would allow it: then it is no matter of the drive."""
    failing: dict[int, list[str]] = {}
    for parameter, value in values.items():
        if not _absurd(effect.plausible_on(parameter, robot), float(value)):
            continue
        joint = effect.parameter_joint(parameter)
        if joint is None or robot is None or not 1 <= joint <= robot.dof:
            return ()
        failing.setdefault(joint, []).append(parameter)
    out = []
    for joint, absurd in sorted(failing.items()):
        own = [p for p in values if effect.parameter_joint(p) == joint]
        allowing = [d for d in DRIVES if d != robot.drive(joint)
                    and not any(_absurd(effect.plausible(p, d), float(values[p])) for p in own)]
        if not allowing:
            return ()
        allowing.sort(key=lambda d: max(effect.plausible(p, d).maximum for p in absurd))
        out.append((joint, tuple(allowing)))
    return tuple(out)
