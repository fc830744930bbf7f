"""Checks shared by the effects: joint numbers and joint types against the robot."""

from __future__ import annotations

from collections.abc import Mapping

import casadi as ca

from ..errors import InputError
from ..model.robot import Robot


def check_joints(effect, robot: Robot, *, revolute_only: bool = False) -> None:
    """Raise ``InputError`` when ``effect.joints`` (1-based) do not fit ``robot``."""
    if len(set(effect.joints)) != len(effect.joints):
        raise InputError(f"{effect.name}: joint listed twice in {list(effect.joints)}",
                         where="effects")
    for j in effect.joints:
        if not 1 <= j <= robot.dof:
            raise InputError(f"{effect.name}: joint {j} does not exist; the robot "
                             f"{robot.name!r} has joints 1..{robot.dof}", where="effects")
        if revolute_only and not robot.joints[j - 1].revolute:
            raise InputError(f"{effect.name}: joint {j} is prismatic; this effect is periodic "
                             "in a joint angle and needs a revolute joint", where="effects")



def column(entries: Mapping[int, ca.SX | float], size: int) -> ca.SX:
    """A CasADi column of ``size`` with ``entries`` {0-based index: expression}, zero elsewhere."""
    return ca.vertcat(*[entries.get(i, 0) for i in range(size)])
