"""What a controller runs: a plan as a URScript or a KUKA KRL program, and a scan as a
time-stamped table.

* URScript (Universal Robots, 6 joints, radians): a pose plan is ``movej`` to each pose in
  run order with a pause to take the reading; a scan is ``movej`` to its first sample,
  then ``servoj`` through every sample at the laser's period.
* KRL (KUKA, axes ``A1..A6`` in degrees, prismatic in mm): ``PTP`` to each pose with
  ``WAIT SEC``; a scan ``PTP`` to its first sample, then ``SPTP`` through every sample
  inside one ``SPLINE`` block (its duration is noted; the axis speeds are the
  controller's ``$VEL_AXIS``).

Joint readings are the robot model's, which is what the controller's axis values are
when its zero positions agree (the robot file's ``theta`` offsets).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal_casadi.common.output import atomic_file
from robocal_casadi.common.table import write_table
from robocal_casadi.errors import InputError
from robocal_casadi.model.robot import Robot
from robocal_casadi.model.transforms import quaternion_from_matrix

PAUSE = 0.5  # [s] standstill at each pose before the reading
UR_ACCELERATION, UR_SPEED = 0.8, 0.5  # [rad/s^2], [rad/s] of movej between poses
UR_LOOKAHEAD, UR_GAIN = 0.1, 300  # servoj smoothing


def _six_joints(robot: Robot, what: str, option: str) -> None:
    if robot.dof != 6 or (what == "URScript" and not all(j.revolute for j in robot.joints)):
        raise InputError(f"{what} programs drive 6 {'revolute ' if what == 'URScript' else ''}"
                         f"axes; {robot.name!r} has {robot.dof} joints", where=option)


def _numbers(values) -> str:
    return ", ".join(f"{v:.6f}" for v in values)


def urscript(robot: Robot, joints: np.ndarray, times: np.ndarray | None = None,
             title: str = "robocal plan") -> str:
    """A URScript program (text) for ``joints`` (N x 6) [rad], in order; with ``times``
    (N,) [s] a scan at those instants, else poses with a pause each."""
    _six_joints(robot, "URScript", "--urscript")
    lines = ["def robocal_plan():", f"  # {title}: {len(joints)} "
             f"{'samples' if times is not None else 'poses'} in run order, joints in rad"]
    lines.append(f"  movej([{_numbers(joints[0])}], a={UR_ACCELERATION}, v={UR_SPEED})")
    if times is None:
        lines.append(f"  sleep({PAUSE})")
        for q in joints[1:]:
            lines.append(f"  movej([{_numbers(q)}], a={UR_ACCELERATION}, v={UR_SPEED})")
            lines.append(f"  sleep({PAUSE})")
    else:
        steps = np.diff(times)
        for q, dt in zip(joints[1:], steps):
            lines.append(f"  servoj([{_numbers(q)}], t={dt:.6f}, lookahead_time={UR_LOOKAHEAD}, "
                         f"gain={UR_GAIN})")
        lines.append("  stopj(2.0)")
    lines += ["end", "robocal_plan()", ""]
    return "\n".join(lines)


def _axes(robot: Robot, q: np.ndarray) -> str:
    values = [np.degrees(v) if j.revolute else 1e3 * v for j, v in zip(robot.joints, q)]
    return "{AXIS: " + ", ".join(f"A{i} {v:.4f}" for i, v in enumerate(values, start=1)) + "}"


def krl(robot: Robot, joints: np.ndarray, times: np.ndarray | None = None,
        title: str = "robocal plan") -> str:
    """A KUKA KRL program (the ``.src`` text) for ``joints`` (N x 6) [rad or m], in order;
    with ``times`` (N,) [s] a scan at those instants."""
    _six_joints(robot, "KRL", "--krl")
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


def write_text(text: str, path: str | Path) -> None:
    """Write ``text`` to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        Path(staging).write_text(text)


def scan_columns(scan) -> list[str]:
    """``t``, then joints (or the pendant pose columns, sensor only), then ``distance``."""
    if scan.sensor_only:
        return ["t", "x", "y", "z", "qw", "qx", "qy", "qz", "distance"]
    return ["t"] + [f"q{i}" for i in range(1, scan.setup.robot.dof + 1)] + ["distance"]


def scan_rows(scan) -> list[list]:
    """Rows of the scan table in the dataset's units; ``distance`` left empty."""
    setup = scan.setup
    length = setup.units.length_scale
    rows = []
    if scan.sensor_only:
        for t, T in zip(scan.times, scan.flange_poses):
            rows.append([t, *(T[:3, 3] / length), *quaternion_from_matrix(T[:3, :3]), np.nan])
        return rows
    scales = np.array([setup.units.angle_scale if j.revolute else length
                       for j in setup.robot.joints])
    for t, q in zip(scan.times, scan.joints):
        rows.append([t, *(q / scales), np.nan])
    return rows


def write_scan(scan, path: str | Path) -> None:
    """Write the scan table to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        write_table(staging, scan_columns(scan), scan_rows(scan))
