"""A plan as a URScript program (``robocal plan --urscript``): Universal Robots, 6 revolute
joints, radians.

A pose plan is ``movej`` to each pose in run order with a pause to take the reading; a
scan is ``movej`` to its first sample, then ``servoj`` through every sample at the laser's
period.
"""

from __future__ import annotations

import numpy as np

from ..model.robot import Robot
from .programs import PAUSE, numbers, six_axes
from .registry import ProgramFormat, register

UR_ACCELERATION, UR_SPEED = 0.8, 0.5  # [rad/s^2], [rad/s] of movej between poses
UR_LOOKAHEAD, UR_GAIN = 0.1, 300  # servoj smoothing


def urscript(robot: Robot, joints: np.ndarray, times: np.ndarray | None = None,
             title: str = "robocal plan") -> str:
    """A URScript program (text) for ``joints`` (N x 6) [rad], in order; with ``times``
    (N,) [s] a scan at those instants, else poses with a pause each."""
    six_axes(robot, "URScript", "--urscript", revolute=True)
    lines = ["def robocal_plan():", f"  # {title}: {len(joints)} "
             f"{'samples' if times is not None else 'poses'} in run order, joints in rad"]
    lines.append(f"  movej([{numbers(joints[0], 6)}], a={UR_ACCELERATION}, v={UR_SPEED})")
    if times is None:
        lines.append(f"  sleep({PAUSE})")
        for q in joints[1:]:
            lines.append(f"  movej([{numbers(q, 6)}], a={UR_ACCELERATION}, v={UR_SPEED})")
            lines.append(f"  sleep({PAUSE})")
    else:
        steps = np.diff(times)
        for q, dt in zip(joints[1:], steps):
            lines.append(f"  servoj([{numbers(q, 6)}], t={dt:.6f}, "
                         f"lookahead_time={UR_LOOKAHEAD}, gain={UR_GAIN})")
        lines.append("  stopj(2.0)")
    lines += ["end", "robocal_plan()", ""]
    return "\n".join(lines)


FORMAT = ProgramFormat(
    name="urscript", flag="--urscript", metavar="OUT.script",
    help="also write the plan as a URScript program (6 revolute joints)",
    expresses="joint values [rad] in run order: movej and a pause per pose, servoj per "
              "scan sample",
    write=urscript)

register(FORMAT)
