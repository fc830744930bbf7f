"""A plan as a KUKA KRL program (``robocal plan --krl``), and what a KUKA controller takes.

The program: axes ``A1..A6`` in degrees (prismatic in mm); ``PTP`` to each pose with
``WAIT SEC``; a scan ``PTP`` to its first sample, then ``SPTP`` through every sample inside
one ``SPLINE`` block (its duration is noted; the axis speeds are the controller's
``$VEL_AXIS``).

Profile ``kuka``: what a KUKA controller takes without its optional absolutely-accurate
model: each axis's zero offset (the mastering offset, ``theta_i`` of a revolute joint,
``d_i`` of a prismatic one) and the robot base and tool frames ($ROBROOT, $TOOL). The link
lengths and twists stay nominal. DH robot files only.
"""

from __future__ import annotations

import numpy as np

from ..model.parameters import FRAME_PARAMETERS
from ..model.robot import Robot
from .programs import PAUSE, six_axes
from .registry import Profile, ProgramFormat, register


def _axes(robot: Robot, q: np.ndarray) -> str:
    values = [np.degrees(v) if j.revolute else 1e3 * v for j, v in zip(robot.joints, q)]
    return "{AXIS: " + ", ".join(f"A{i} {v:.4f}" for i, v in enumerate(values, start=1)) + "}"


def krl(robot: Robot, joints: np.ndarray, times: np.ndarray | None = None,
        title: str = "robocal plan") -> str:
    """A KUKA KRL program (the ``.src`` text) for ``joints`` (N x 6) [rad or m], in order;
    with ``times`` (N,) [s] a scan at those instants."""
    six_axes(robot, "KRL", "--krl")
    lines = ["DEF robocal_plan()", f"  ; {title}: {len(joints)} "
             f"{'samples' if times is not None else 'poses'} in run order, axes in deg",
             "  BAS(#INITMOV, 0)", f"  PTP {_axes(robot, joints[0])}"]
    if times is None:
        lines.append(f"  WAIT SEC {PAUSE}")
        for q in joints[1:]:
            lines += [f"  PTP {_axes(robot, q)}", f"  WAIT SEC {PAUSE}"]
    else:
        period = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
        lines += [f"  ; one sample every {period:.6f} s over {times[-1]:.4f} s: set $VEL_AXIS so "
                  f"that the spline takes that long", "  SPLINE"]
        for q in joints[1:]:
            lines.append(f"    SPTP {_axes(robot, q)}")
        lines.append("  ENDSPLINE")
    lines += ["END", ""]
    return "\n".join(lines)


def parameters(robot: Robot) -> tuple[str, ...]:
    offsets = [f"{'theta' if j.revolute else 'd'}{i}"
               for i, j in enumerate(robot.joints, start=1)]
    frames = [f"{frame}_{stem}" for frame in ("base", "tool") for stem, _ in FRAME_PARAMETERS]
    return tuple(offsets + frames)


PROFILE = Profile(name="kuka", phrase="axis zero offsets, base and tool", parameters=parameters)

FORMAT = ProgramFormat(
    name="krl", flag="--krl", metavar="OUT.src",
    help="also write the plan as a KUKA KRL program (6 axes)",
    expresses="axis values [deg, mm] in run order: PTP and a wait per pose, one SPLINE per "
              "scan; its controller takes axis zero offsets, base and tool",
    write=krl, profile=PROFILE)

register(FORMAT)
