"""Joint scale: a joint reading off by a constant factor (e.g. a gear-ratio error).

    dq_j = s_j * q_j            s_j [1] (relative), q_j [rad] or [m]

Parameters ``s{j}``, one per joint in ``joints`` (1-based).
"""

from __future__ import annotations

import casadi as ca

from .base import Effect, RowContext
from .checks import check_joints, column


class JointScale(Effect):
    """``dq_j = s_j q_j`` for each joint j in ``joints``."""

    name = "joint_scale"
    unit = "1"
    typical = 1e-4  # a typical parameter size, for judging whether the data see it

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"s{j}" for j in self.joints)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot)
        entries = {j - 1: theta[k] * row.q[j - 1] for k, j in enumerate(self.joints)}
        return column(entries, row.robot.dof), None
