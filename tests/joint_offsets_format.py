"""A controller format written outside the library, to show that one ``register`` line is
all it takes: each axis's zero offset from the nominal robot, as a controller's mastering
table takes it (``theta_i`` of a revolute joint in the robot file's angle unit, ``d_i`` of
a prismatic one in its length unit), one ``A<i>,<offset>`` row per axis.
"""

from __future__ import annotations

from robocal_casadi.errors import InputError
from robocal_casadi.formats import ExportSource, ModelFormat, register


def write(source: ExportSource) -> str:
    robot, nominal = source.calibrated, source.nominal
    if nominal is None:
        raise InputError("axis offsets need a DH robot", where="--joint-offsets")
    angle, length = robot.units.angle_scale, robot.units.length_scale
    rows = ["axis,offset"]
    for i, (joint, start) in enumerate(zip(robot.joints, nominal.joints), start=1):
        offset = ((joint.theta - start.theta) / angle if joint.revolute
                  else (joint.d - start.d) / length)
        rows.append(f"A{i},{offset!r}")
    return "\n".join(rows) + "\n"


FORMAT = ModelFormat(name="joint-offsets", flag="--joint-offsets", metavar="OUT.csv",
                     help="write each axis's zero offset from nominal",
                     expresses="axis zero offsets only", write=write)

register(FORMAT)
