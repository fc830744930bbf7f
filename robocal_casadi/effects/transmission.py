"""Transmission coupling: a joint's reading off by a linear share of another joint's motion.

    dq_j = r_jk * q_k          r_jk [1], q_k [rad], joint space, k != j

In differential and cable drives the motors do not turn the joints one by one: the
joint angles are the motor angles times a transmission matrix, and the controller
inverts the matrix it was given. When the true matrix differs from it (pulley radii,
cable stretch, a wrong ratio in a differential pair) joint j moves by a share ``r_jk``
of joint k's motion that its reading does not show. ``r_jk`` is one off-diagonal entry
of the error of the transmission matrix (the diagonal is ``joint_scale``). Both joints
revolute, 1-based; parameter ``r{j}_q{k}`` [1], the driving joint part of the name, and
result.json lists ``joints: [j]``. One effect may hold several pairs.

Unlike ``joint_coupling`` (periodic in the driving joint's angle, the signature of a gear
train's eccentricity) this is linear in the angle: a ratio, not a wobble.

Plausible on real robots, by the coupled joint's drive: below 0.2 % (2e-3) of the driving
joint's motion for gear trains (coupled wrists have exact integer ratios), 0.1 % for
direct drives, 1 % for belts and 5 % for cables (the coupling matrix of a cable-driven
differential is set by pulley radii and cable stretch, known to a few percent).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..common.units import Units
from ..model.robot import Robot
from .base import Plausible, RowContext, TrueWorld
from .checks import column
from .coupling import JointCoupling
from .drives import per_drive

SHARE = per_drive(
    Plausible(2e-3, basis="coupling ratios of gear trains are exact to about 0.2 %"),
    direct=Plausible(1e-3, basis="direct drives couple only through their encoders: 0.1 %"),
    belt=Plausible(1e-2, basis="belts routed through other joints: about 1 %"),
    cable=Plausible(5e-2, basis="the coupling matrix of cable differentials, set by pulley "
                    "radii and cable stretch: a few percent"))


class TransmissionCoupling(JointCoupling):
    """``dq_j = r_jk q_k`` for each pair (``joints[i]``, ``drivers[i]``)."""

    name = "transmission_coupling"
    title = "Transmission coupling"
    unit = "1"
    typical = 1e-4
    sentence = "transmission coupling, {values}"
    plot_variable = "driver"
    per = "pair"
    revolute_only = True
    simulation_default = (2e-3,)
    formula = "q_true_J = q_read_J + r q_read_K (a share r of joint K's motion reaches joint J)"
    own_joint = "joint_scale"

    def __repr__(self) -> str:
        return f"TransmissionCoupling(pairs={[list(p) for p in self.pairs]})"

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"r{j}_q{k}" for j, k in self.pairs)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return SHARE[drive]

    def _check_amplitudes(self, values, robot=None) -> tuple:
        return ()

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        self._check(row.robot)
        entries: dict = {}
        for i, (j, k) in enumerate(self.pairs):
            entries[j - 1] = entries.get(j - 1, 0) + theta[i] * row.q[k - 1]
        return column(entries, row.robot.dof), None

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> TransmissionCoupling:
        """``options['drivers']``: the driving joint of each joint in ``joints``."""
        return cls(tuple(joints), drivers=tuple(options.get("drivers", ())))

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]
                   ) -> tuple[TransmissionCoupling, ...]:
        """Every ordered pair of distinct revolute joints, one parameter each."""
        revolute = [j for j in range(1, robot.dof + 1) if robot.joints[j - 1].revolute]
        return tuple(cls((j,), (k,)) for j in revolute for k in revolute if j != k)

    @classmethod
    def merged(cls, units, robot: Robot, extras: Mapping[str, Any]) -> TransmissionCoupling:
        pairs = sorted({p for unit in units for p in unit.pairs})
        return cls(tuple(j for j, _ in pairs), tuple(k for _, k in pairs))

    @classmethod
    def for_simulation(cls, keys: Sequence) -> TransmissionCoupling:
        return cls(tuple(j for j, _ in keys), tuple(k for _, k in keys))

    def describe(self, values, units: Units) -> str:
        parts = [f"joint {j} turns by {100 * values.get(f'r{j}_q{k}', 0.0):.3g} % of joint "
                 f"{k}'s motion" for j, k in self.pairs]
        return self.sentence.format(values="; ".join(parts))

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j, k in self.pairs:
            dq[:, j - 1] += values[f"r{j}_q{k}"] * Q[:, k - 1]
        return dq
