"""Joint coupling: one joint's angle offset varies with the angle of another joint.

    dq_j = s_jk sin(q_k) + c_jk cos(q_k)          [rad], joint space, k != j

Joint j (the coupled joint) reads off by an amount periodic in the angle of joint k (the
driving joint), as when the wrist's drive shafts pass through the joints before them or
one joint's gear train turns with another. Both joints revolute, 1-based. Parameters
``sin{j}_q{k}`` and ``cos{j}_q{k}`` [rad]: the driving joint is part of each name, and
result.json lists ``joints: [j]`` with these parameters. One effect may hold several
pairs (``joints`` and ``drivers`` side by side).

Plausible on real robots, by the coupled joint's drive: each amplitude below about
0.05 deg (8.7e-4 rad) for gear trains, the size of their periodic errors; 0.2 deg for
belts and 0.5 deg for cables, whose routing over the pulleys of the joints they pass
changes their length with those joints' angles.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from .base import Effect, Plausible, RowContext, TrueWorld, amplitude_check
from .checks import column
from .drives import per_drive

AMPLITUDE = per_drive(
    Plausible(math.radians(0.05), basis="coupling through gear trains stays below about "
              "0.05 deg"),
    belt=Plausible(math.radians(0.2), basis="belts routed through other joints: below about "
                   "0.2 deg"),
    cable=Plausible(math.radians(0.5), basis="cables routed over other joints' pulleys: below "
                    "about 0.5 deg"))


class JointCoupling(Effect):
    """``dq_j = s sin(q_k) + c cos(q_k)`` for each pair (``joints[i]``, ``drivers[i]``)."""

    name = "joint_coupling"
    title = "Joint coupling"
    unit = "rad"
    typical = 1e-4
    sentence = "coupled joints, {values}"
    plot_variable = "driver"
    per = "pair"
    revolute_only = True
    simulation_default: ClassVar[tuple[float, ...]] = (2e-4, 1e-4)
    formula = "q_true_J = q_read_J + s sin q_K + c cos q_K (joint K drives joint J)"
    own_joint = "joint_cyclic"  # what a joint driving itself would be

    def __init__(self, joints: tuple[int, ...], drivers: Sequence[int] = ()):
        super().__init__(joints)
        self.drivers = tuple(int(k) for k in drivers)
        if len(self.drivers) != len(self.joints):
            raise InputError(f"{self.name}: {len(self.joints)} coupled joint(s) but "
                             f"{len(self.drivers)} driving joint(s); give one driver per joint",
                             where="effects")
        pairs = self.pairs
        if len(set(pairs)) != len(pairs):
            raise InputError(f"{self.name}: a pair is listed twice in {list(pairs)}",
                             where="effects")
        for j, k in pairs:
            if j == k:
                raise InputError(f"{self.name}: joint {j} cannot drive itself (that is "
                                 f"{self.own_joint})", where="effects")

    @property
    def pairs(self) -> tuple[tuple[int, int], ...]:
        """(coupled joint, driving joint), 1-based."""
        return tuple(zip(self.joints, self.drivers))

    def __repr__(self) -> str:
        return f"JointCoupling(pairs={[list(p) for p in self.pairs]})"

    @property
    def label(self) -> str:
        return f"{self.name}{[f'{j}<-{k}' for j, k in self.pairs]}"

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"{t}{j}_q{k}" for j, k in self.pairs for t in ("sin", "cos"))

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return AMPLITUDE[drive]

    def _check_amplitudes(self, values, robot=None) -> tuple:
        return amplitude_check(self, [(f"sin{j}_q{k}", f"cos{j}_q{k}") for j, k in self.pairs],
                               values, robot)

    def _check(self, robot: Robot) -> None:
        for j, k in self.pairs:
            for joint in (j, k):
                if not 1 <= joint <= robot.dof:
                    raise InputError(f"{self.name}: joint {joint} does not exist; the robot "
                                     f"{robot.name!r} has joints 1..{robot.dof}", where="effects")
                if not robot.joints[joint - 1].revolute:
                    raise InputError(f"{self.name}: joint {joint} is prismatic; the coupling "
                                     "is between joint angles and needs revolute joints",
                                     where="effects")

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        self._check(row.robot)
        entries: dict = {}
        for i, (j, k) in enumerate(self.pairs):
            q = row.q[k - 1]
            entries[j - 1] = entries.get(j - 1, 0) + theta[2 * i] * ca.sin(q) \
                + theta[2 * i + 1] * ca.cos(q)
        return column(entries, row.robot.dof), None

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """``drivers``: the driving joint of each joint, 1-based."""
        return {"drivers": [int(d) for d in self.drivers]}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> JointCoupling:
        return cls(tuple(int(j) for j in entry["joints"]),
                   drivers=[int(d) for d in entry.get("drivers", ())])

    def truth_settings(self) -> dict[str, Any]:
        """``drivers``: coupled joint -> driving joint, 1-based."""
        return {"drivers": {int(j): int(k) for j, k in self.pairs}} if self.drivers else {}

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> JointCoupling:
        """``options['drivers']``: the driving joint of each joint in ``joints``."""
        return cls(tuple(joints), drivers=tuple(options.get("drivers", ())))

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[JointCoupling, ...]:
        """Every ordered pair of distinct revolute joints: dof (dof - 1) of them, 30 for a
        6-axis arm, each with 2 parameters."""
        revolute = [j for j in range(1, robot.dof + 1) if robot.joints[j - 1].revolute]
        return tuple(cls((j,), (k,)) for j in revolute for k in revolute if j != k)

    @classmethod
    def merged(cls, units, robot: Robot, extras: Mapping[str, Any]) -> JointCoupling:
        pairs = sorted({p for unit in units for p in unit.pairs})
        return cls(tuple(j for j, _ in pairs), tuple(k for _, k in pairs))

    @classmethod
    def simulation_key(cls, text, robot: Robot, where: str = "effects") -> tuple[int, int]:
        """``J@K`` (text) or ``(J, K)``: joint J driven by joint K."""
        if isinstance(text, tuple):
            parts = [str(v) for v in text]
        else:
            parts = str(text).split("@")
        try:
            j, k = (int(v) for v in parts)
        except ValueError:
            raise InputError(f"expected J@K, joint J driven by joint K, got {text!r}",
                             where=where) from None
        for joint in (j, k):
            cls._check_simulated_joint(joint, robot, where)
        if j == k:
            raise InputError(f"joint {j} cannot drive itself (that is {cls.own_joint})",
                             where=where)
        return (j, k)

    @classmethod
    def for_simulation(cls, keys) -> JointCoupling:
        return cls(tuple(j for j, _ in keys), tuple(k for _, k in keys))

    def describe(self, values, units: Units) -> str:
        a = units.angle_scale
        parts = []
        for j, k in self.pairs:
            amplitude = math.hypot(values.get(f"sin{j}_q{k}", 0.0), values.get(f"cos{j}_q{k}", 0.0))
            parts.append(f"joint {j} reads off by up to {amplitude / a:.3g} {units.angle} "
                         f"once per turn of joint {k}")
        return self.sentence.format(values="; ".join(parts))

    def plot_values(self, robot: Robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The angle [rad] of the first joint driving ``joint``."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        driver = next(k for j, k in self.pairs if j == joint)
        return Q[:, driver - 1]

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j, k in self.pairs:
            dq[:, j - 1] += (values[f"sin{j}_q{k}"] * np.sin(Q[:, k - 1])
                             + values[f"cos{j}_q{k}"] * np.cos(Q[:, k - 1]))
        return dq
