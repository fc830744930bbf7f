"""Camera mounts and marker conventions, turned into the method's observation.

The method (``tracking.goal``) takes a camera whose axes are parallel to the end frame
and an observation ``(x, y, z, roll, pitch, yaw)`` in which the target frame is
``Trans(x, y, z) R_B rpy(roll, pitch, yaw)`` in camera axes. Two other descriptions are
common and are converted here, once, into that form, so the goal chain and the per-cycle
NLP stay as they are:

* a camera turned on the end frame (hand-eye calibration): ``T_end_camera =
  Trans(camera_xyz) R_camera``, ``R_camera`` [3x3] the camera axes in the end frame;
* a marker pose as OpenCV/ArUco return it (``marker_convention = "opencv"``): ``tvec``
  [m] and the rotation ``R_marker`` (from ``rvec``, a Rodrigues vector [rad], or a
  quaternion) with ``T_camera_marker = [R_marker | tvec]``: marker x right, y up, z out
  of its face towards the camera. Facing the marker squarely from the standoff, upright,
  the marker frame is the end frame turned half about x; the method's target frame is
  then ``R_marker Rx(180 deg) R_B``, so that this facing pose is the goal.

With ``T_end_target`` the target frame in the end frame, the method's observation for a
camera at ``camera_xyz`` with parallel axes is ``xyz = p_end_target - camera_xyz``,
``rpy`` of ``R_B^T R_end_target``.
"""

from __future__ import annotations

import math
from typing import Literal, get_args

import numpy as np

from ..model.transforms import pose_from_xyz_rpy, rot_x, rpy_from_matrix
from .goal import R_B

MarkerConvention = Literal["method", "opencv"]
MARKER_CONVENTIONS: tuple[MarkerConvention, ...] = get_args(MarkerConvention)

#: Method target frame in the OpenCV/ArUco marker frame: ``Rx(180 deg) R_B`` (3x3).
R_MARKER_TARGET = (rot_x(math.pi) @ R_B)[:3, :3]


def rotation_from_rvec(rvec) -> np.ndarray:
    """The rotation (3x3) of a Rodrigues vector [rad]: axis times angle, as OpenCV writes it."""
    rvec = np.asarray(rvec, dtype=float).reshape(3)
    angle = float(np.linalg.norm(rvec))
    if angle < 1e-300:
        return np.eye(3)
    k = rvec / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def target_in_end(camera_xyz, camera_rotation, position, rotation,
                  convention: MarkerConvention = "method") -> np.ndarray:
    """``T_end_target`` (4x4) [m]: the method's target frame in the end frame.

    ``camera_xyz`` [m] and ``camera_rotation`` (3x3) the camera in the end frame;
    ``position`` [m] and ``rotation`` (3x3) the observed target (``method``: its own
    orientation ``C``) or marker (``opencv``) in the camera frame.
    """
    T_camera_target = np.eye(4)
    T_camera_target[:3, 3] = position
    if convention == "opencv":
        T_camera_target[:3, :3] = np.asarray(rotation) @ R_MARKER_TARGET
    else:
        T_camera_target[:3, :3] = R_B[:3, :3] @ np.asarray(rotation)
    T_end_camera = np.eye(4)
    T_end_camera[:3, :3] = camera_rotation
    T_end_camera[:3, 3] = camera_xyz
    return T_end_camera @ T_camera_target


def method_observation(camera_xyz, camera_rotation, position, rotation,
                       convention: MarkerConvention = "method") -> np.ndarray:
    """The method's ``(x, y, z [m], roll, pitch, yaw [rad])`` for a camera at
    ``camera_xyz`` with axes parallel to the end frame that sees what the described camera
    sees (arguments as ``target_in_end``)."""
    T = target_in_end(camera_xyz, camera_rotation, position, rotation, convention)
    xyz = T[:3, 3] - np.asarray(camera_xyz, dtype=float)
    return np.concatenate([xyz, rpy_from_matrix(R_B[:3, :3].T @ T[:3, :3])])


def observation_rotation(observation, convention: MarkerConvention) -> np.ndarray:
    """The rotation (3x3) of a 6-vector observation's last three entries: ``roll, pitch,
    yaw`` [rad] (``method``) or a Rodrigues vector [rad] (``opencv``)."""
    if convention == "opencv":
        return rotation_from_rvec(observation[3:6])
    return pose_from_xyz_rpy([0.0, 0.0, 0.0], observation[3:6])[:3, :3]
