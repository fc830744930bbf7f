"""The configuration (inverse-kinematics branch) a joint vector belongs to.

A pose that a six-joint arm reaches is reached by several joint vectors: shoulder left or
right, elbow up or down, wrist flipped or not. These branches are separated by the
singular joint vectors, where the tool Jacobian loses rank: for a six-joint arm its
determinant is the product of a shoulder, an elbow and a wrist factor (times positive
terms), and each flag is the sign of its factor. Two joint vectors joined by a path on
which the Jacobian never loses rank therefore share every flag; a path between two
branches must cross a singularity.

``same_configuration`` walks the straight joint-space segment between two joint vectors
in steps of at most ``SAMPLE_ANGLE`` (revolute) / ``SAMPLE_LENGTH`` (prismatic) and asks:

* six joints (square Jacobian): the determinant keeps one sign (samples where it is
  numerically zero, e.g. a taught pose on the wrist singularity, take no side);
* other joint counts (redundant or fewer joints: no determinant): the smallest singular
  value never falls below ``RANK_FRACTION`` of the smaller of its two end values.

The test is sufficient for "same branch", not necessary: two joint vectors far apart on
one branch may be joined only by a curved path. For the small moves a calibration asks of
a taught program, the segment is short and the test exact.
"""

from __future__ import annotations

import math

import numpy as np

from .kinematics import Kinematics

SAMPLE_ANGLE = math.radians(1.0)  # [rad] largest revolute step between two checks
SAMPLE_LENGTH = 1e-3  # [m] largest prismatic step between two checks
RANK_FRACTION = 1e-3  # smallest singular value kept along a segment, of its end values
ZERO_DETERMINANT = 1e-12  # |det J| below this fraction of the largest seen takes no side
CHUNK = 32  # Jacobians evaluated per call


def tool_jacobians(kinematics: Kinematics, Q: np.ndarray, p: np.ndarray | None = None
                   ) -> np.ndarray:
    """Geometric tool Jacobians (N, 6, dof) at joint vectors ``Q`` (N, dof), world frame."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    p = kinematics.nominal if p is None else np.asarray(p, dtype=float)
    function = kinematics.mapped(kinematics.tool_jacobian, CHUNK)  # one size: built once
    parts = []
    for start in range(0, len(Q), CHUNK):
        block = Q[start:start + CHUNK]
        padded = np.vstack([block, np.repeat(block[-1:], CHUNK - len(block), axis=0)])
        out = np.asarray(function(padded.T, p)).reshape(6, CHUNK, kinematics.dof)
        parts.append(out.transpose(1, 0, 2)[:len(block)])
    return np.concatenate(parts)


def segment(kinematics: Kinematics, q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
    """Joint vectors (M, dof) on the straight segment from ``q_from`` to ``q_to`` (both
    ends included), no two neighbours more than one sample step apart."""
    q_from, q_to = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    steps = np.array([SAMPLE_ANGLE if j.revolute else SAMPLE_LENGTH
                      for j in kinematics.robot.joints])
    count = int(np.ceil(np.max(np.abs(q_to - q_from) / steps))) + 1
    s = np.linspace(0.0, 1.0, max(count, 2))[:, None]
    return q_from + s * (q_to - q_from)


def same_configuration(kinematics: Kinematics, q_from, q_to, p=None) -> bool:
    """True when no singularity lies on the joint segment from ``q_from`` to ``q_to``
    [rad or m] of the geometry ``p`` (default the robot's own): both are on one branch
    (module docstring)."""
    J = tool_jacobians(kinematics, segment(kinematics, q_from, q_to), p)
    if J.shape[1] == J.shape[2]:
        determinant = np.linalg.det(J)
        scale = float(np.max(np.abs(determinant)))
        if scale == 0.0:
            return True
        signs = np.sign(determinant[np.abs(determinant) > ZERO_DETERMINANT * scale])
        return bool(np.all(signs == signs[0]))
    smallest = np.linalg.svd(J, compute_uv=False)[:, -1]
    return bool(np.all(smallest >= RANK_FRACTION * min(smallest[0], smallest[-1])))


__all__ = ["same_configuration", "segment", "tool_jacobians"]
