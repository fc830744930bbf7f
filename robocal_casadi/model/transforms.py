"""Homogeneous transforms, rpy angles and quaternions, in numpy and CasADi.

Conventions (docs/conventions.md#rpy, docs/conventions.md#quaternions): ``rpy = [r, p, y]``
means ``R = Rz(y) Ry(p) Rx(r)``; a quaternion is ``(qw, qx, qy, qz)``. The same builders
work on floats (numpy) and on CasADi symbols, so the kinematics are written once.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..common import exact


def _backend(*values):
    return ca if any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in values) else np


def _matrix(rows, lib):
    if lib is np:
        return np.array(rows, dtype=float)
    return ca.vertcat(*[ca.horzcat(*row) for row in rows])


def product(*matrices):
    """``matrices[0] @ matrices[1] @ ...``: CasADi's product on symbols, ``exact.chain`` on
    numbers (the same bits on every processor; see ``common.exact``)."""
    if _backend(*matrices) is np:
        return exact.chain(*matrices)
    out = matrices[0]
    for m in matrices[1:]:
        out = out @ m
    return out


def rot_x(angle):
    """Rotation about x by ``angle`` [rad], 4x4 homogeneous."""
    lib = _backend(angle)
    c, s = lib.cos(angle), lib.sin(angle)
    return _matrix([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]], lib)


def rot_y(angle):
    """Rotation about y by ``angle`` [rad], 4x4 homogeneous."""
    lib = _backend(angle)
    c, s = lib.cos(angle), lib.sin(angle)
    return _matrix([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]], lib)


def rot_z(angle):
    """Rotation about z by ``angle`` [rad], 4x4 homogeneous."""
    lib = _backend(angle)
    c, s = lib.cos(angle), lib.sin(angle)
    return _matrix([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], lib)


def translation(x, y, z):
    """Pure translation [m], 4x4 homogeneous."""
    lib = _backend(x, y, z)
    return _matrix([[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1]], lib)


def pose_from_xyz_rpy(xyz, rpy):
    """``T = Trans(xyz) Rz(y) Ry(p) Rx(r)`` with ``xyz`` [m], ``rpy`` [rad]."""
    return product(translation(xyz[0], xyz[1], xyz[2]), rot_z(rpy[2]), rot_y(rpy[1]),
                   rot_x(rpy[0]))


def rpy_from_matrix(R: np.ndarray) -> np.ndarray:
    """Inverse of ``Rz(y) Ry(p) Rx(r)`` for a 3x3 rotation: ``[r, p, y]`` [rad]."""
    R = np.asarray(R, dtype=float)
    pitch = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    if np.hypot(R[0, 0], R[1, 0]) < 1e-12:  # gimbal lock: put everything in yaw
        return np.array([0.0, pitch, np.arctan2(-R[0, 1], R[1, 1])])
    return np.array([np.arctan2(R[2, 1], R[2, 2]), pitch, np.arctan2(R[1, 0], R[0, 0])])


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(qw, qx, qy, qz)`` with ``qw >= 0`` of a 3x3 rotation."""
    R = np.asarray(R, dtype=float)
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    quaternion = np.array(q)
    quaternion /= exact.norm(quaternion)
    return quaternion if quaternion[0] >= 0 else -quaternion


def matrix_from_quaternion(q) -> np.ndarray:
    """3x3 rotation of a unit quaternion ``(qw, qx, qy, qz)``."""
    w, x, y, z = np.asarray(q, dtype=float)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 rigid transform."""
    R, p = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -exact.matmul(R.T, p)
    return out
