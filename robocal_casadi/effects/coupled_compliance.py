"""Compliance of coupled joints: a group driven together gives way as one, with cross terms.

When two joints share their motors through a differential (``model.transmission``), the
cables or gears that hold one joint's torque also carry the other's, so a torque at one
joint deflects both. For each declared group G the joint-space compliance is a symmetric
matrix ``C_G`` [rad/Nm], and

    dq_G = -C_G tau_G(q)                 [rad], the group's joints

``tau(q)`` the generalized gravity torque the motors apply to hold the arm (links plus a
point payload of the row's ``payload`` [kg] at ``payload_com`` [m] in the flange frame, as
``joint_compliance`` computes it; the robot file must give every link's ``mass`` and
``com``). Parameters ``cc{a}_{b}`` (a <= b joints of one group, ``C_ab = C_ba``): the
diagonal ``cc{a}_{a}`` is joint a's own compliance, the off-diagonal ``cc{a}_{b}`` how far
joint a turns per unit torque at joint b. With motor stiffnesses ``K_m`` (diagonal,
[Nm/rad] at the motors' cables) ``C = M^T K_m^-1 M`` for the group's transmission ``M``
normalised to joint angles, which is why a differential's ``C`` has cross terms as large
as its diagonal.

Plausible on real robots, by the joint's drive: the diagonal positive and as large as
``joint_compliance`` allows on that drive (``compliance.COMPLIANCE``: 1e-4 rad/Nm for gear
trains, 1e-2 rad/Nm for cables); an off-diagonal term of either sign, at most that
largest magnitude. Diagnosis offers it on each group the robot file declares, only where
the links' masses are given (the lumped form of ``joint_compliance`` has no coupled
counterpart yet).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..common import exact
from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from ..model.transmission import group_of
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import column
from .compliance import COMPLIANCE, _torque_function

CROSS = {drive: Plausible(limits.maximum, basis=f"cross compliance of joints driven together, "
                          f"at most the largest own compliance ({limits.basis})")
         for drive, limits in COMPLIANCE.items()}


def _pairs(group: Sequence[int]) -> tuple[tuple[int, int], ...]:
    """(a, b) with a before or equal to b in the group's order: the entries of ``C``."""
    return tuple((a, b) for i, a in enumerate(group) for b in group[i:])


class CoupledCompliance(Effect):
    """``dq_G = -C_G tau_G(q)`` for each coupled group G in ``groups``; see the module."""

    name = "coupled_compliance"
    title = "Compliance of coupled joints"
    unit = "rad/Nm"
    typical = 1e-6
    sentence = "{values}"
    plot_variable = "torque"
    per = "group"
    revolute_only = True
    simulation_default = (1e-5, 5e-6, 1e-5)  # a pair: C22, C23, C33
    formula = ("q_true_G = q_read_G - C g_G(q_read), C symmetric over a coupled group G, "
               "g the gravity torque")
    view_quantity = "deflection"

    def __init__(self, groups: Sequence[Sequence[int]]):
        self.groups = tuple(tuple(int(j) for j in g) for g in groups)
        super().__init__(tuple(j for g in self.groups for j in g))

    def __repr__(self) -> str:
        return f"CoupledCompliance(groups={[list(g) for g in self.groups]})"

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"cc{a}_{b}" for g in self.groups for a, b in _pairs(g))

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        a, b = parameter[2:].split("_")
        return COMPLIANCE[drive] if a == b else CROSS[drive]

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        return {"groups": [list(g) for g in self.groups]}

    def truth_settings(self) -> dict[str, Any]:
        return {"groups": [list(g) for g in self.groups]}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> CoupledCompliance:
        groups = entry.get("groups")
        if groups is None:
            return cls.create(tuple(int(j) for j in entry["joints"]), robot)
        return cls([[int(j) for j in g] for g in groups])

    def reads_payload(self) -> bool:
        return True

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> CoupledCompliance:
        """The groups of ``robot``'s transmission that hold ``joints``."""
        if robot is None:
            raise ValueError("coupled_compliance needs the robot's transmission")
        groups = []
        for j in joints:
            group = group_of(robot.transmission, int(j))
            if group is None:
                raise InputError(f"coupled_compliance: joint {j} is in no transmission group "
                                 "of the robot file", where="effects")
            if group.joints not in groups:
                groups.append(group.joints)
        return cls(groups)

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[CoupledCompliance, ...]:
        """One per declared transmission group, where the links' masses are known."""
        if not robot.has_inertia:
            return ()
        return tuple(cls([g.joints]) for g in robot.transmission)

    @classmethod
    def merged(cls, units, robot: Robot, extras: Mapping[str, Any]) -> CoupledCompliance:
        groups = sorted({g for unit in units for g in unit.groups})
        return cls(groups)

    def _matrix(self, group: tuple[int, ...], values) -> list[list]:
        """``C`` of ``group`` from ``values`` (name -> value or symbol), symmetric."""
        n = len(group)
        C: list[list] = [[0] * n for _ in range(n)]
        for a, b in _pairs(group):
            i, k = group.index(a), group.index(b)
            C[i][k] = C[k][i] = values[f"cc{a}_{b}"]
        return C

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        self._check(row.robot)
        payload = row.extras.get("payload", 0.0)
        tau = _torque_function(row.robot)(row.q, row.p, payload, row.payload_com)
        named = {n: theta[k] for k, n in enumerate(self.parameter_names())}
        entries: dict[int, Any] = {}
        for group in self.groups:
            C = self._matrix(group, named)
            for i, a in enumerate(group):
                entries[a - 1] = -sum(C[i][k] * tau[b - 1] for k, b in enumerate(group))
        return column(entries, row.robot.dof), None

    def _check(self, robot: Robot) -> None:
        for group in self.groups:
            for j in group:
                if not 1 <= j <= robot.dof or not robot.joints[j - 1].revolute:
                    raise InputError(f"coupled_compliance: joint {j} is no revolute joint of "
                                     f"the robot {robot.name!r}", where="effects")

    def describe(self, values, units: Units) -> str:
        parts = []
        for group in self.groups:
            own = ", ".join(f"{values.get(f'cc{a}_{a}', 0.0):.3g}" for a in group)
            cross = ", ".join(f"{a}-{b}: {values.get(f'cc{a}_{b}', 0.0):.3g}"
                              for a, b in _pairs(group) if a != b)
            parts.append(f"joints {'-'.join(map(str, group))} deflect together under gravity "
                         f"(own {own}; cross {cross} {self.unit})")
        return "; ".join(parts)

    def plot_values(self, robot: Robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The gravity torque [Nm] the joint holds (pinocchio, with the payload column)."""
        from ..model.pinocchio_model import gravity_torques

        return gravity_torques(robot, Q, payload_mass=extras.get("payload", 0.0),
                               payload_com=payload_com)[:, joint - 1]

    # ----------------------------------------------------------------- simulation

    @classmethod
    def simulation_key(cls, text, robot: Robot, where: str = "effects"):
        """A group from ``J-K`` text (or a tuple of joints, or one joint of a group): the
        robot file's transmission group holding those joints."""
        try:
            if isinstance(text, (tuple, list)):
                joints = [int(j) for j in text]
            else:
                joints = [int(t) for t in str(text).strip().split("-")]
        except ValueError:
            raise InputError(f"expected the joints of a coupled group (e.g. 2-3), got {text!r}",
                             where=where) from None
        group = group_of(robot.transmission, joints[0])
        if group is None or not set(joints) <= set(group.joints):
            raise InputError(f"joints {joints} are no group of the robot file's transmission "
                             f"(declared: {[list(g.joints) for g in robot.transmission]})",
                             where=where)
        return group.joints

    @classmethod
    def for_simulation(cls, keys: Sequence) -> CoupledCompliance:
        return cls([tuple(k) for k in keys])

    @classmethod
    def accepts_simulation_values(cls, count: int) -> bool:
        # n (n + 1) / 2 entries of a symmetric n x n matrix, n >= 2
        n = int(round((np.sqrt(8 * count + 1) - 1) / 2))
        return n >= 2 and n * (n + 1) // 2 == count

    @classmethod
    def simulation_syntax(cls) -> str:
        default = "/".join(f"{v:g}" for v in cls.simulation_default)
        return (f"{cls.name}:J-K[=ccJ_J/ccJ_K/ccK_K]  [{cls.unit}]  (default {default}; a group "
                f"the robot file's transmission declares)\n      {cls.formula}")

    def check_simulation(self, robot: Robot, values) -> None:
        super().check_simulation(robot, values)
        if not robot.has_inertia:
            raise InputError("coupled_compliance needs 'mass' and 'com' on every joint of the "
                             "robot file to simulate gravity torques",
                             where="effects.coupled_compliance")

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """``-C tau_G`` with pinocchio's gravity torque of the true robot and the rows'
        payload (needs masses in the robot file)."""
        from ..model.pinocchio_model import gravity_torques

        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        payload = np.asarray(extras.get("payload", np.zeros(len(Q))), dtype=float)
        torques = gravity_torques(world.robot, Q, payload, world.payload_com)
        dq = np.zeros(Q.shape)
        for group in self.groups:
            C = np.array(self._matrix(group, values), dtype=float)
            columns = [j - 1 for j in group]
            dq[:, columns] = -exact.matmul(torques[:, columns], C.T)
        return dq
