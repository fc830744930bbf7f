"""Joint cyclic error: a reading error periodic in the joint angle (gears, encoders).

    dq_j = sum over the orders h of joint j:  ah_j sin(h q_j) + bh_j cos(h q_j)     [rad]

Parameters ``a{h}_{j}, b{h}_{j}`` [rad] per revolute joint j (1-based) and harmonic
order h (h times per turn), joint space. The orders default to once and twice per turn
(``a1_j, b1_j, a2_j, b2_j``); strain-wave, cycloidal and multi-stage gears show higher
orders, which an effect carries as its ``orders`` (written to the effects file). Over a
small range of q_j the cosine terms look like a constant, which the joint's ``theta``
offset already holds; diagnosis checks each column against the geometry.

Diagnosis offers, per revolute joint, the first two orders together (as always) and each
higher order ``h`` up to ``MAX_ORDER`` on its own, chosen like every other candidate by
the held-out rules. A higher order is offered only where the data can resolve it
(``sampled_well``): the joint's readings span at least ``PERIODS_SPANNED`` of its periods
(over a single period a sinusoid of that order passes for a smooth trend, a gear-ratio
error or a compliance, and stands in for them), and no gap between consecutive readings
exceeds a quarter period (``SAMPLES_PER_PERIOD``).

Plausible on real robots, by the joint's drive: each amplitude below about 0.05 deg
(8.7e-4 rad) for gear trains and strain-wave gears (the periodic errors of gears and
encoders of industrial arms are a few arc seconds to a few hundredths of a degree),
0.02 deg for direct drives (the encoder's alone), 0.2 deg for belts and 0.5 deg for
cables (eccentric pulleys and capstans, the cable's lay on its drum); the same for every
order.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from .base import Effect, Plausible, RowContext, TrueWorld, amplitude_check
from .checks import check_joints, column
from .drives import per_drive

BASE_ORDERS = (1, 2)  # offered together, and what an effect without ``orders`` carries
MAX_ORDER = 6  # the highest harmonic diagnosis offers
SAMPLES_PER_PERIOD = 4  # readings per period, at the sparsest, to resolve an order
PERIODS_SPANNED = 2  # periods of an order the readings must span for it to be offered
AMPLITUDE = per_drive(
    Plausible(math.radians(0.05), basis="periodic gear and encoder errors stay below about "
              "0.05 deg"),
    direct=Plausible(math.radians(0.02), basis="a direct drive's periodic error is its "
                     "encoder's: below about 0.02 deg"),
    belt=Plausible(math.radians(0.2), basis="eccentric belt pulleys: below about 0.2 deg"),
    cable=Plausible(math.radians(0.5), basis="eccentric capstans and pulleys, the cable's "
                    "lay: below about 0.5 deg"))


def per_turn(order: int) -> str:
    """``once``, ``twice``, ``3 times`` per turn."""
    return {1: "once", 2: "twice"}.get(order, f"{order} times")


class JointCyclic(Effect):
    """Harmonics of the joint angle, per joint in ``joints``: the ``orders`` of each
    (``BASE_ORDERS`` by default)."""

    name = "joint_cyclic"
    title = "Periodic joint error"
    unit = "rad"
    typical = 1e-4
    sentence = "periodic reading error, {values}"
    plot_variable = "joint"
    revolute_only = True
    simulation_default = (2e-4, 1e-4, 1e-4, 5e-5)
    formula = "q_true = q_read + sum_h (ah sin hq + bh cos hq), h = 1, 2 unless given"
    view_curve = True

    def __init__(self, joints: tuple[int, ...],
                 orders: Sequence[Sequence[int]] | None = None):
        super().__init__(joints)
        if orders is None:
            orders = [BASE_ORDERS] * len(self.joints)
        self.orders = tuple(tuple(sorted({int(h) for h in hs})) for hs in orders)
        if len(self.orders) != len(self.joints) or any(
                not hs or min(hs) < 1 for hs in self.orders):
            raise ValueError(f"joint_cyclic: one non-empty list of orders >= 1 per joint, got "
                             f"{list(orders)} for joints {list(self.joints)}")

    def __repr__(self) -> str:
        return f"JointCyclic(joints={list(self.joints)}, orders={[list(h) for h in self.orders]})"

    @property
    def label(self) -> str:
        parts = [str(j) if hs == BASE_ORDERS else
                 f"{j}: order {'/'.join(str(h) for h in hs)}"
                 for j, hs in zip(self.joints, self.orders)]
        return f"{self.name}[{', '.join(parts)}]"

    @classmethod
    def view_caption(cls, torque: bool) -> tuple[str, str]:
        return ("against the joint angle", "the dashed line (right axis) is the fitted reading "
                "error a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q, or where other orders h "
                "were found the sum of ah sin hq + bh cos hq over them")

    def _terms(self) -> list[tuple[int, int]]:
        """(joint, order) of each sine/cosine pair, in parameter order."""
        return [(j, h) for j, hs in zip(self.joints, self.orders) for h in hs]

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"{t}{h}_{j}" for j, h in self._terms() for t in ("a", "b"))

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return AMPLITUDE[drive]

    def parameter_joint(self, parameter: str) -> int | None:
        """The joint after the underscore (``a1_3`` -> 3)."""
        return int(parameter.split("/")[0].split("_")[1])

    def _check_amplitudes(self, values, robot=None) -> tuple:
        return amplitude_check(self, [(f"a{h}_{j}", f"b{h}_{j}") for j, h in self._terms()],
                               values, robot)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot, revolute_only=True)
        entries: dict[int, Any] = {}
        for k, (j, h) in enumerate(self._terms()):
            q = row.q[j - 1]
            term = theta[2 * k] * ca.sin(h * q) + theta[2 * k + 1] * ca.cos(h * q)
            entries[j - 1] = term if j - 1 not in entries else entries[j - 1] + term
        return column(entries, row.robot.dof), None

    @staticmethod
    def amplitude(values: Mapping[str, float], joint: int, order: int) -> float:
        """The amplitude [rad] of ``joint``'s harmonic ``order`` in ``values``."""
        return math.hypot(values.get(f"a{order}_{joint}", 0.0),
                          values.get(f"b{order}_{joint}", 0.0))

    def describe(self, values, units: Units) -> str:
        parts = []
        a = units.angle_scale
        for j, hs in zip(self.joints, self.orders):
            sizes = [f"{self.amplitude(values, j, h) / a:.3g} {units.angle} {per_turn(h)}"
                     for h in hs]
            parts.append(f"joint {j}: {' and '.join(sizes)} per turn")
        return self.sentence.format(values="; ".join(parts))

    # ----------------------------------------------------------------- files

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """``orders``: the harmonic orders of each joint, in ``joints`` order."""
        return {"orders": [list(hs) for hs in self.orders]}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> JointCyclic:
        joints = tuple(int(j) for j in entry["joints"])
        orders = entry.get("orders")
        if orders is None:
            return cls(joints)
        if not isinstance(orders, list) or not all(isinstance(h, list) for h in orders):
            raise ValueError(f"orders: expected one list of whole numbers per joint, got "
                             f"{orders!r}")
        if any(isinstance(h, bool) or int(h) != h for hs in orders for h in hs):
            raise ValueError(f"orders: expected whole numbers, got {orders!r}")
        return cls(joints, orders)

    def truth_settings(self) -> dict[str, Any]:
        """``orders`` per joint where any differs from the first two."""
        if all(hs == BASE_ORDERS for hs in self.orders):
            return {}
        return {"orders": {int(j): list(hs) for j, hs in zip(self.joints, self.orders)}}

    # ----------------------------------------------------------------- diagnosis

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[Effect, ...]:
        """Per revolute joint: the first two orders together, then each higher order up to
        ``MAX_ORDER`` alone (diagnosis keeps those the data resolve, ``sampled_well``)."""
        out: list[Effect] = []
        for j in range(1, robot.dof + 1):
            if not robot.joints[j - 1].revolute or robot.drive(j) not in cls.drives:
                continue
            out.append(cls((j,)))
            out += [cls((j,), ((h,),)) for h in range(BASE_ORDERS[-1] + 1, MAX_ORDER + 1)]
        return tuple(out)

    def sampled_well(self, Q: np.ndarray) -> bool:
        """Whether readings ``Q`` (N x dof) [rad] resolve every order above the first two:
        they span ``PERIODS_SPANNED`` periods of it, with no gap over a
        ``SAMPLES_PER_PERIOD``-th of one."""
        for j, hs in zip(self.joints, self.orders):
            top = max(hs)
            if top <= BASE_ORDERS[-1]:
                continue
            values = np.unique(np.asarray(Q, dtype=float)[:, j - 1])
            if len(values) < 2:
                return False
            period = 2 * math.pi / top
            if (np.ptp(values) < PERIODS_SPANNED * period
                    or np.max(np.diff(values)) > period / SAMPLES_PER_PERIOD):
                return False
        return True

    @classmethod
    def merged(cls, units: Sequence[Effect], robot: Robot,
               extras: Mapping[str, Any]) -> Effect:
        """One effect over the joints of ``units``, each joint with every order any unit
        gives it."""
        orders: dict[int, set[int]] = {}
        for unit in units:
            assert isinstance(unit, JointCyclic)
            for j, hs in zip(unit.joints, unit.orders):
                orders.setdefault(j, set()).update(hs)
        joints = tuple(sorted(orders))
        return cls(joints, [sorted(orders[j]) for j in joints])

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> JointCyclic:
        return cls(tuple(joints), options.get("orders"))

    # ----------------------------------------------------------------- simulation

    @classmethod
    def accepts_simulation_values(cls, count: int) -> bool:
        """Any number of sine/cosine pairs: ``a1/b1/a2/b2/a3/b3...`` for orders 1, 2, 3 ..."""
        return count >= 2 and count % 2 == 0

    @classmethod
    def for_simulated_values(cls, keys: Sequence, widths: Sequence[int]) -> Effect:
        """The true effect on joints ``keys``, orders 1 .. width/2 of each."""
        return cls(tuple(int(k) for k in keys), [tuple(range(1, w // 2 + 1)) for w in widths])

    @classmethod
    def simulation_syntax(cls) -> str:
        return (super().simulation_syntax()
                + "\n      more pairs add orders: a1/b1/a2/b2/a3/b3 ... (h times per turn)")

    def simulation_values(self, entries: Sequence[float] | None = None) -> dict[str, float]:
        if entries is not None and not self.accepts_simulation_values(len(entries)):
            raise InputError(f"{self.name}: expected sine/cosine pairs (a1/b1, a1/b1/a2/b2, "
                             f"...), got {len(entries)} value(s)", where="effects")
        return super().simulation_values(entries)

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        for j, h in self._terms():
            x = Q[:, j - 1]
            dq[:, j - 1] += (values[f"a{h}_{j}"] * np.sin(h * x)
                             + values[f"b{h}_{j}"] * np.cos(h * x))
        return dq
