"""An effect written outside the library, to show that one ``register`` line is all it
takes: a joint reading error growing with the square of the angle,

    dq_j = e_j q_j^2          [rad], e_j [1/rad]

Its numpy truth (``simulated_dq``) is written from the formula, apart from ``delta``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from robocal_casadi.effects import Effect, Plausible, RowContext


class QuadraticReading(Effect):
    """``dq_j = e_j q_j^2`` for each revolute joint j in ``joints``."""

    name = "joint_quadratic"
    title = "Quadratic joint error"
    unit = "1/rad"
    typical = 1e-4
    sentence = "{joints} read off by a term in the squared angle ({values})"
    plot_variable = "joint"
    revolute_only = True
    simulation_default = (1e-4,)
    formula = "q_true = q_read + e q_read^2"

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"e{j}_sq" for j in self.joints)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return Plausible(1e-2, basis="a made-up range for a test effect")

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        entries = {j - 1: theta[k] * row.q[j - 1] ** 2 for k, j in enumerate(self.joints)}
        return ca.vertcat(*[entries.get(i, 0) for i in range(row.robot.dof)]), None

    def simulated_dq(self, world, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j in self.joints:
            dq[:, j - 1] = values[f"e{j}_sq"] * Q[:, j - 1] ** 2
        return dq
