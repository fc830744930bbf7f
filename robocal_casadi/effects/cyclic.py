"""Joint cyclic error: a reading error periodic in the joint angle (gears, encoders).

    dq_j = a1_j sin(q_j) + b1_j cos(q_j) + a2_j sin(2 q_j) + b2_j cos(2 q_j)     [rad]

Parameters ``a1_{j}, b1_{j}, a2_{j}, b2_{j}`` [rad] per revolute joint j (1-based). Over a
small range of q_j the cosine terms look like a constant, which the joint's ``theta``
offset already holds; diagnosis checks each column against the geometry.
"""

from __future__ import annotations

import casadi as ca

from .base import Effect, RowContext
from .checks import check_joints, column

HARMONICS = ("a1", "b1", "a2", "b2")


class JointCyclic(Effect):
    """First and second harmonics of the joint angle, per joint in ``joints``."""

    name = "joint_cyclic"
    unit = "rad"
    typical = 1e-4  # a typical parameter size, for judging whether the data see it

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"{h}_{j}" for j in self.joints for h in HARMONICS)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot, revolute_only=True)
        entries = {}
        for k, j in enumerate(self.joints):
            q = row.q[j - 1]
            a1, b1, a2, b2 = (theta[4 * k + i] for i in range(4))
            entries[j - 1] = (a1 * ca.sin(q) + b1 * ca.cos(q)
                              + a2 * ca.sin(2 * q) + b2 * ca.cos(2 * q))
        return column(entries, row.robot.dof), None
