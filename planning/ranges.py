"""Joint ranges a plan may use: the robot file's limits, made realistic where they are
wider than the arm's mechanism allows or missing.

* An elbow (a revolute joint between two long links) folds its forearm onto its upper
  arm at 180 deg: whatever the controller allows (a UR's +-360 deg), a plan keeps it
  within ``ELBOW_LIMIT`` (+-175 deg). A link is long when the distance between the axis
  points it joins is at least ``LONG_LINK`` of the arm's length (the sum of all such
  distances up to the flange).
* A revolute joint without limits gets +-``DEFAULT_LIMIT`` (one turn, 175 deg each way:
  every angle reachable, cables never wound more than half a turn).
* Every limit the file gives is kept at a distance: ``LIMIT_MARGIN`` (5%) of the joint's
  range, at most ``MARGIN_ANGLE`` (5 deg; ``MARGIN_LENGTH``, 5 mm, for a prismatic joint),
  inside each end. A pose on a limit stops the controller at the slightest overshoot, and
  the calibration's own joint offsets move the limits by a fraction of a degree.
* Prismatic joints otherwise keep what the file gives.

Limits narrower than these stay as they are (less their margin).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.robot import Robot

ELBOW_LIMIT = np.radians(175.0)
DEFAULT_LIMIT = np.radians(175.0)
LONG_LINK = 0.2
LIMIT_MARGIN = 0.05  # fraction of a joint's range kept free inside each of its limits
MARGIN_ANGLE = np.radians(5.0)  # [rad] the largest such margin of a revolute joint
MARGIN_LENGTH = 5e-3  # [m] the largest such margin of a prismatic joint


def limit_margin(lower: float, upper: float, revolute: bool) -> float:
    """The margin [rad or m] kept inside each limit of a joint with range [lower, upper]."""
    return min(LIMIT_MARGIN * (upper - lower), MARGIN_ANGLE if revolute else MARGIN_LENGTH)


def axis_points(robot: Robot) -> np.ndarray:
    """A point on each joint axis and the flange origin ((dof + 1) x 3) [m], world frame,
    at zero readings. Standard DH: joint k turns about ``z_{k-1}`` through frame
    ``k-1``'s origin; modified DH: about ``z_k`` through frame ``k``'s origin."""
    kin = Kinematics(robot)
    frames = [np.asarray(T) for T in kin.joint_frames(np.zeros(robot.dof), kin.nominal)]
    origins = np.array([T[:3, 3] for T in frames])  # frames 0..n
    if robot.convention == "mdh":
        return origins[1:] if len(origins) > robot.dof else origins
    return origins


def elbows(robot: Robot) -> list[int]:
    """0-based indices of the revolute joints that sit between two long links."""
    points = axis_points(robot)
    links = np.linalg.norm(np.diff(points, axis=0), axis=1)  # axis k to axis k+1 (or flange)
    total = float(links.sum())
    if total <= 0:
        return []
    out = []
    for k, joint in enumerate(robot.joints):
        if not joint.revolute or k == 0:
            continue
        before, after = links[k - 1], links[k] if k < len(links) else 0.0
        if min(before, after) >= LONG_LINK * total:
            out.append(k)
    return out


def working_ranges(robot: Robot) -> Robot:
    """``robot`` with the limits a plan may use (see the module docstring)."""
    folding = set(elbows(robot))
    joints = []
    for k, joint in enumerate(robot.joints):
        if joint.limits is not None:
            margin = limit_margin(joint.limits[0], joint.limits[1], joint.revolute)
            lo, hi = joint.limits[0] + margin, joint.limits[1] - margin
        if not joint.revolute:
            joints.append(joint if joint.limits is None
                          else replace(joint, limits=(float(lo), float(hi))))
            continue
        if joint.limits is None:
            lo, hi = -DEFAULT_LIMIT, DEFAULT_LIMIT
        if k in folding:
            lo, hi = max(lo, -ELBOW_LIMIT), min(hi, ELBOW_LIMIT)
        joints.append(replace(joint, limits=(float(lo), float(hi))))
    return replace(robot, joints=tuple(joints))
