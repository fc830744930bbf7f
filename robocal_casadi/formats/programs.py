"""What the robot programs share: the pause at each pose and the six-axis check.

Joint values are the robot model's, which is what the controller's axis values are when
its zero positions agree (the robot file's ``theta`` offsets).
"""

from __future__ import annotations

from ..errors import InputError
from ..model.robot import Robot

PAUSE = 0.5  # [s] standstill at each pose before the reading


def six_axes(robot: Robot, language: str, flag: str, *, revolute: bool = False) -> None:
    """Refuse ``robot`` unless it has 6 joints (all revolute with ``revolute``); the error
    names the program's ``flag``."""
    if robot.dof != 6 or (revolute and not all(j.revolute for j in robot.joints)):
        raise InputError(f"{language} programs drive 6 {'revolute ' if revolute else ''}"
                         f"axes; {robot.name!r} has {robot.dof} joints", where=flag)


def numbers(values, digits: int) -> str:
    """``values`` joined by ``", "`` with ``digits`` decimals."""
    return ", ".join(f"{v:.{digits}f}" for v in values)
