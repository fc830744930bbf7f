"""Joint cyclic error: a reading error periodic in the joint angle (gears, encoders).

    dq_j = a1_j sin(q_j) + b1_j cos(q_j) + a2_j sin(2 q_j) + b2_j cos(2 q_j)     [rad]

Parameters ``a1_{j}, b1_{j}, a2_{j}, b2_{j}`` [rad] per revolute joint j (1-based), joint
space. Over a small range of q_j the cosine terms look like a constant, which the joint's
``theta`` offset already holds; diagnosis checks each column against the geometry.

Plausible on real robots, by the joint's drive: each amplitude below about 0.05 deg
(8.7e-4 rad) for gear trains and strain-wave gears (the periodic errors of gears and
encoders of industrial arms are a few arc seconds to a few hundredths of a degree),
0.02 deg for direct drives (the encoder's alone), 0.2 deg for belts and 0.5 deg for
cables (eccentric pulleys and capstans, the cable's lay on its drum).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..common.units import Units
from .base import Effect, Plausible, RowContext, TrueWorld, amplitude_check
from .checks import check_joints, column
from .drives import per_drive

HARMONICS = ("a1", "b1", "a2", "b2")
AMPLITUDE = per_drive(
    Plausible(math.radians(0.05), basis="periodic gear and encoder errors stay below about "
              "0.05 deg"),
    direct=Plausible(math.radians(0.02), basis="a direct drive's periodic error is its "
                     "encoder's: below about 0.02 deg"),
    belt=Plausible(math.radians(0.2), basis="eccentric belt pulleys: below about 0.2 deg"),
    cable=Plausible(math.radians(0.5), basis="eccentric capstans and pulleys, the cable's "
                    "lay: below about 0.5 deg"))


class JointCyclic(Effect):
    """First and second harmonics of the joint angle, per joint in ``joints``."""

    name = "joint_cyclic"
    title = "Periodic joint error"
    unit = "rad"
    typical = 1e-4
    sentence = "periodic reading error, {values}"
    plot_variable = "joint"
    revolute_only = True
    simulation_default = (2e-4, 1e-4, 1e-4, 5e-5)
    formula = "q_true = q_read + a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q"
    view_curve = True

    @classmethod
    def view_caption(cls, torque: bool) -> tuple[str, str]:
        return ("against the joint angle", "the dashed line (right axis) is the fitted reading "
                "error a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q")

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"{h}_{j}" for j in self.joints for h in HARMONICS)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return AMPLITUDE[drive]

    def parameter_joint(self, parameter: str) -> int | None:
        """The joint after the underscore (``a1_3`` -> 3)."""
        return int(parameter.split("/")[0].split("_")[1])

    def _check_amplitudes(self, values, robot=None) -> tuple:
        return amplitude_check(self, [(f"a{h}_{j}", f"b{h}_{j}") for j in self.joints
                                      for h in (1, 2)], values, robot)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot, revolute_only=True)
        entries = {}
        for k, j in enumerate(self.joints):
            q = row.q[j - 1]
            a1, b1, a2, b2 = (theta[4 * k + i] for i in range(4))
            entries[j - 1] = (a1 * ca.sin(q) + b1 * ca.cos(q)
                              + a2 * ca.sin(2 * q) + b2 * ca.cos(2 * q))
        return column(entries, row.robot.dof), None

    def describe(self, values, units: Units) -> str:
        parts = []
        a = units.angle_scale
        for j in self.joints:
            first = math.hypot(values.get(f"a1_{j}", 0.0), values.get(f"b1_{j}", 0.0))
            second = math.hypot(values.get(f"a2_{j}", 0.0), values.get(f"b2_{j}", 0.0))
            parts.append(f"joint {j}: {first / a:.3g} {units.angle} once and {second / a:.3g} "
                         f"{units.angle} twice per turn")
        return self.sentence.format(values="; ".join(parts))

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j in self.joints:
            x = Q[:, j - 1]
            dq[:, j - 1] = (values[f"a1_{j}"] * np.sin(x) + values[f"b1_{j}"] * np.cos(x)
                            + values[f"a2_{j}"] * np.sin(2 * x)
                            + values[f"b2_{j}"] * np.cos(2 * x))
        return dq
