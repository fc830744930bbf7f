"""Joint scale: a joint reading off by a constant factor (e.g. a gear-ratio error).

    dq_j = s_j * q_j            s_j [1] (relative), q_j [rad] or [m], joint space

Parameters ``s{j}``, one per joint in ``joints`` (1-based).

Plausible on real robots, by the joint's drive: ``|s_j|`` below about 0.2 % (2e-3) for
gears (gear ratios and encoder resolutions are known far better, and a larger value
points at a wrong model), 0.1 % for direct drives, 1 % for toothed belts (pulley pitch
diameters and belt stretch) and 3 % for cables (capstan radius tolerances, the cable's
own diameter and its stretch set the effective radius).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..common.units import Units
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import check_joints, column
from .drives import per_drive

RATIO = per_drive(
    Plausible(2e-3, basis="gear-ratio errors stay below about 0.2 %"),
    direct=Plausible(1e-3, basis="a direct drive's ratio is its encoder's: below 0.1 %"),
    belt=Plausible(1e-2, basis="belt pulley diameters and stretch: below about 1 %"),
    cable=Plausible(3e-2, basis="capstan radii, cable diameter and stretch: below about 3 %"))


class JointScale(Effect):
    """``dq_j = s_j q_j`` for each joint j in ``joints``."""

    name = "joint_scale"
    title = "Joint scale error"
    unit = "1"
    typical = 1e-4
    sentence = "gear-ratio error: {values}"
    plot_variable = "joint"
    simulation_default = (5e-4,)
    formula = "q_true = (1 + s) q_read"
    view_curve = True

    @classmethod
    def view_caption(cls, torque: bool) -> tuple[str, str]:
        return ("against the joint angle",
                "the dashed line (right axis) is the fitted reading error s q")

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"s{j}" for j in self.joints)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return RATIO[drive]

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot)
        entries = {j - 1: theta[k] * row.q[j - 1] for k, j in enumerate(self.joints)}
        return column(entries, row.robot.dof), None

    def describe(self, values, units: Units) -> str:
        parts = "; ".join(f"joint {k[1:]} turns (1 + {v:.3g}) times its reading"
                          for k, v in values.items())
        return self.sentence.format(values=parts)

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j in self.joints:
            dq[:, j - 1] = values[f"s{j}"] * Q[:, j - 1]
        return dq
