"""A plain DH table (``robocal export --dh-table``) and the parameter set it can hold.

Controllers that take a DH table take ``theta, d, a, alpha`` per joint and nothing for
nearly parallel axes. The table is a CSV, one row per joint from the base:
``joint,type,theta,d,a,alpha`` in the robot file's units (lengths in its length unit,
angles in its angle unit), standard DH (``T(i-1,i) = Rz(theta_i) Tz(d_i) Tx(a_i)
Rx(alpha_i)``) or modified DH (Craig's row: ``alpha_{i-1}, a_{i-1}, theta_i, d_i``) as
the robot file is. A model with a non-zero Hayati ``beta``, or a robot read from URDF, is
refused: the table cannot hold it. The base and tool frames are set on the controller
apart from the table; they stay in robot_calibrated.yaml.

Profile ``dh-only``: every DH (or modified DH) ``theta, d, a, alpha`` and the base and tool
frames, no Hayati ``beta``. DH robot files only.
"""

from __future__ import annotations

import csv
import io

from ..common.table import format_number
from ..errors import InputError
from ..model.robot import Robot
from .registry import ExportSource, ModelFormat, Profile, register

COLUMNS = ("joint", "type", "theta", "d", "a", "alpha")


def write(source: ExportSource) -> str:
    """The CSV text of ``source.calibrated``'s DH table (module docstring)."""
    robot = source.calibrated
    if robot.convention == "urdf":
        raise InputError(f"robot {robot.name!r} was read from a URDF: it has no DH table",
                         where="--dh-table")
    tilted = [i for i, j in enumerate(robot.joints, start=1) if j.beta != 0.0]
    if tilted:
        raise InputError(f"joints {tilted} have a non-zero beta, which a DH table cannot hold; "
                         "calibrate with --profile dh-only", where="--dh-table")
    length, angle = robot.units.length_scale, robot.units.angle_scale
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for i, j in enumerate(robot.joints, start=1):
        writer.writerow([str(i), j.type] + [format_number(v) for v in (
            j.theta / angle, j.d / length, j.a / length, j.alpha / angle)])
    return text.getvalue()


def parameters(robot: Robot) -> tuple[str, ...]:
    return tuple(n for n in robot.parameters().names if not n.startswith("beta"))


PROFILE = Profile(name="dh-only", phrase="no beta", parameters=parameters)

FORMAT = ModelFormat(
    name="dh-table", flag="--dh-table", metavar="OUT.csv",
    help="write the calibrated joints as a plain DH table (CSV, robot file units)",
    expresses="geometry only: theta, d, a, alpha per joint; no beta, base or tool",
    write=write, profile=PROFILE)

register(FORMAT)
