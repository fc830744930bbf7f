"""UR's kinematics file (``robocal export --ur-calibration``) and UR's parameter set.

The file holds ``x, y, z, roll, pitch, yaw`` per joint [m, rad] as ur_description and the
UR ROS drivers read it, for arms with UR's structure (another arm is refused,
``urdf.writer.ur_structure_problem``).

Profile ``ur``: UR's own calibration, a ``theta, d, a, alpha`` correction per joint and no
``beta``; the base (the mounting) and the tool (the TCP) are set apart from it and are not
fitted. For a robot read from a URDF file, the UR ROS drivers' kinematics set: each joint's
``x, y, z, roll, pitch, yaw`` (no flange, base or tool).
"""

from __future__ import annotations

from ..model.robot import Robot, dump_yaml
from .registry import ExportSource, ModelFormat, Profile, register


def write(source: ExportSource) -> str:
    """The YAML text of UR's kinematics file for ``source.calibrated``."""
    from ..urdf.writer import ur_calibration

    return dump_yaml(ur_calibration(source.calibrated, source.like, nominal=source.nominal,
                                    base_link=source.base_link, tip_link=source.tip_link))


def dh_parameters(robot: Robot) -> tuple[str, ...]:
    return tuple(f"{stem}{i}" for i in range(1, robot.dof + 1)
                 for stem in ("theta", "d", "a", "alpha"))


def urdf_parameters(robot: Robot) -> tuple[str, ...]:
    return tuple(n for n in robot.parameters().names
                 if not n.startswith(("base_", "tool_", "flange_")))


PROFILE = Profile(name="ur", phrase="UR's calibration set", parameters=dh_parameters,
                  urdf=urdf_parameters, urdf_phrase="the joint origins UR's drivers read")

FORMAT = ModelFormat(
    name="ur-calibration", flag="--ur-calibration", metavar="OUT.yaml",
    help="write UR's kinematics file (six-joint UR arms)",
    expresses="geometry only: each joint's origin (x, y, z, roll, pitch, yaw); no base, "
              "tool or beta",
    write=write, profile=PROFILE)

register(FORMAT)
