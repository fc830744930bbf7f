"""A plan as an ABB RAPID program (``robocal plan --rapid``): a module with one procedure.

Axes ``rax_1..rax_6`` in degrees (a linear axis in mm), the external axes unused
(``9E9``). A pose plan is ``MoveAbsJ`` to each pose in run order, stopping there
(``fine``), with ``WaitTime`` to take the reading; a scan is ``MoveAbsJ`` to its first
sample, then ``MoveAbsJ ... \\T:=dt`` through every sample, each move taking the time to
the next sample, without stopping (zone ``z0``), and a last ``fine`` stop. The speed data
``v100`` between poses is a slow, safe choice the operator may raise; ``tool0`` is the
flange, so the program moves the axes whatever tool the controller has set.
"""

from __future__ import annotations

import numpy as np

from ..model.robot import Robot
from .programs import PAUSE, numbers, six_axes
from .registry import ProgramFormat, register

UNUSED = ", ".join(["9E9"] * 6)  # RAPID's value of an external axis that is not there


def _target(robot: Robot, q: np.ndarray) -> str:
    """``q`` [rad or m] as a RAPID ``jointtarget`` literal [deg or mm]."""
    values = [np.degrees(v) if j.revolute else 1e3 * v for j, v in zip(robot.joints, q)]
    return f"[[{numbers(values, 4)}], [{UNUSED}]]"


def rapid(robot: Robot, joints: np.ndarray, times: np.ndarray | None = None,
          title: str = "robocal plan") -> str:
    """An ABB RAPID module (the ``.mod`` text) for ``joints`` (N x 6) [rad or m], in order;
    with ``times`` (N,) [s] a scan at those instants, else poses with a pause each."""
    six_axes(robot, "RAPID", "--rapid")
    lines = ["MODULE robocal_plan",
             f"  ! {title}: {len(joints)} {'samples' if times is not None else 'poses'} "
             "in run order, axes in deg",
             "  PROC main()",
             f"    MoveAbsJ {_target(robot, joints[0])}, v100, fine, tool0;"]
    if times is None:
        lines.append(f"    WaitTime {PAUSE};")
        for q in joints[1:]:
            lines += [f"    MoveAbsJ {_target(robot, q)}, v100, fine, tool0;",
                      f"    WaitTime {PAUSE};"]
    else:
        steps = np.diff(times)
        for k, (q, dt) in enumerate(zip(joints[1:], steps), start=1):
            zone = "fine" if k == len(steps) else "z0"
            lines.append(f"    MoveAbsJ {_target(robot, q)}, v100 \\T:={dt:.6f}, {zone}, "
                         "tool0;")
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


FORMAT = ProgramFormat(
    name="rapid", flag="--rapid", metavar="OUT.mod",
    help="also write the plan as an ABB RAPID program (6 axes)",
    expresses="axis values [deg, mm] in run order: MoveAbsJ and a wait per pose, a timed "
              "MoveAbsJ per scan sample",
    write=rapid)

register(FORMAT)
