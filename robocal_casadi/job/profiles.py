"""Controller profiles: the geometric parameters a robot controller can take.

A calibration is only as useful as the parameters the controller accepts. ``--profile``
restricts the identified robot parameters to one controller's set (the rest are held at
their nominal values) and reports what the restriction costs in accuracy:

* ``dh-only``: every DH (or modified DH) ``theta, d, a, alpha`` and the base and tool
  frames, no Hayati ``beta`` (controllers that take a plain DH table). DH robot files only.
* ``ur``: UR's own calibration, a ``theta, a, d, alpha`` correction per joint and no
  ``beta``; the base (the mounting) and the tool (the TCP) are set apart from it and are
  not fitted. For a robot read from a URDF file, the UR ROS drivers' kinematics set: each
  joint's ``x, y, z, roll, pitch, yaw`` (no flange, base or tool).
* ``kuka``: what a KUKA controller takes without its optional absolutely-accurate model:
  each axis's zero offset (the mastering offset, ``theta_i`` of a revolute joint, ``d_i``
  of a prismatic one) and the robot base and tool frames ($ROBROOT, $TOOL). The link
  lengths and twists stay nominal. DH robot files only.

The mounted instrument (probe, target, laser) and any effects are not the controller's
and stay free under every profile.
"""

from __future__ import annotations

from ..errors import InputError
from ..model.parameters import FRAME_PARAMETERS
from ..model.robot import Robot
from ..results import ProfileCost  # noqa: F401 (the record, re-exported)

PROFILES = ("dh-only", "ur", "kuka")


def profile_parameters(profile: str, robot: Robot) -> tuple[str, ...]:
    """The robot parameter names ``profile`` leaves free for ``robot`` (module docstring)."""
    if profile not in PROFILES:
        raise InputError(f"unknown profile {profile!r}; expected one of {list(PROFILES)}",
                         where="--profile")
    names = robot.parameters().names
    frames = [f"{frame}_{stem}" for frame in ("base", "tool") for stem, _ in FRAME_PARAMETERS]
    joints = range(1, robot.dof + 1)
    if robot.convention == "urdf":
        if profile != "ur":
            raise InputError(f"profile {profile} needs a DH or modified-DH robot file; a URDF "
                             "robot's controller-ready set is --profile ur (the joint origins "
                             "UR's drivers read)", where="--profile")
        return tuple(n for n in names if not n.startswith(("base_", "tool_", "flange_")))
    if profile == "dh-only":
        return tuple(n for n in names if not n.startswith("beta"))
    if profile == "ur":
        return tuple(f"{stem}{i}" for i in joints for stem in ("theta", "d", "a", "alpha"))
    return tuple([f"{'theta' if j.revolute else 'd'}{i}" for i, j in zip(joints, robot.joints)]
                 + frames)


