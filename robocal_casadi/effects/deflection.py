"""Link deflection: a link bending under the weight it carries, as a shift of its end.

A link held at its root and loaded at its end by a weight ``m g`` bends like a
cantilever (the elastostatic link model): its end moves along the part of the load
perpendicular to the link, by an amount proportional to the bending moment
``M = m |L| |g_perp|`` at the root. Where the bending also lowers the end along gravity
(a yielding joint housing or bearing under the moment, a link whose sag is measured
vertically) the end moves down in proportion to the same moment. Everything beyond the
link moves with its end:

    delta_i = (f_i payload + f_i_m) |L_i| g_perp_i
            + (v_i payload + v_i_m) |L_i| |g_perp_i| g / |g|      [m], world frame
    g_perp_i = g - (g . L_i) L_i / |L_i|^2                    [m/s^2]

``L_i`` [m] is link i's vector in the world frame, from the axis of joint i to the axis
of joint i + 1 (the link joint i moves; the origins of the frames on those axes, of the
chain at the row's readings and geometry), ``g`` the robot's gravity [m/s^2], ``payload``
the row's payload column [kg] (0 without one), ``f_i`` [m/(N m)] the link's deflection
per unit bending moment (``L^2 / (3 E I)`` for a uniform beam loaded at its end) and
``f_i_m`` [m kg/(N m)] that times the effective mass of the arm beyond the link (its own
weight, lumped, since where the masses sit along the link is not known); ``v_i``,
``v_i_m`` the same for the sag along gravity. ``|g_perp|`` is taken as
``sqrt(|g_perp|^2 + (1e-9 |g|)^2)``, smooth where a link points along gravity. Parameters
``f{i}``, ``v{i}`` (only with a payload column), ``f{i}_m`` and ``v{i}_m``, link i
1-based; a link shorter than
``MIN_LENGTH`` has nothing to bend and is not a candidate (for a modified-DH or URDF
chain the last link ends at the flange, so it is none).

The deflection enters the kinematics as a shift of the base's translation (``base_x``,
``base_y``, ``base_z``), which moves every point of the arm by ``delta`` in the world: the
slope of the bent link is left out (it turns the arm beyond by about ``1.5 delta / |L|``,
second order against the shift for the short tools of light arms).

Unlike joint compliance, which turns the arm about a joint axis by an angle that follows
the joint's gravity torque (and so the whole configuration beyond the joint), the
deflection shifts the arm along the load, and only link i's own elevation sets its size.

Plausible on real robots: ``|f_i|`` and ``|v_i|`` below 1e-4 m/(N m) (a light aluminium
link of 0.4 m and 80 mm diameter has about 1e-6, cast links of industrial arms 1e-8 ..
1e-7), and their sum positive: with the link horizontal the payload's sag is ``(f_i +
v_i) payload |L| |g|`` and a link bends along its load (either part alone, the one the
bend does not have, may come out slightly negative); ``|f_i_m|`` and ``|v_i_m|`` below
1e-3 m kg/(N m) (that compliance times an effective mass of some tens of kilograms beyond
the link), of either sign: the part of the arm's own bend that the geometry can imitate
(a constant, a joint offset) is the geometry's, and what is left of the lumped term may
come out either way, as compliance's lumped terms do. The same for every drive: the link
bends, not the joint.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any

import casadi as ca
import numpy as np

from ..common import exact
from ..common.units import Units
from ..errors import InputError
from ..model.kinematics import Kinematics, symbolic_frames
from ..model.robot import Robot
from .base import Effect, Implausible, Plausible, RowContext, TrueWorld, joint_list
from .checks import column

MIN_LENGTH = 0.1  # [m] links shorter than this are not candidates
SMOOTH = 1e-9  # of |g|: keeps |g_perp| smooth where a link points along gravity
PER_MOMENT = Plausible(1e-4, basis="link bending of robot arms: below 1e-4 m/(N m)")
SAG = Plausible(1e-4, sign=+1, basis="a link bends along its load: under a payload at "
                "horizontal its end goes down")
OWN_WEIGHT = Plausible(1e-3, basis="link bending times the arm's weight beyond the link: "
                       "below 1e-3 m kg/(N m)")
SHIFT = ("base_x", "base_y", "base_z")


def link_ends(robot: Robot, frames: list) -> list[tuple[Any, Any]]:
    """(root, end) origins [m] of each link i = 1..n from the chain's world ``frames``
    (``symbolic_frames`` layout, CasADi or numpy 4x4): the points where joint i's and
    joint i + 1's axes cross their frames; the last link ends at the flange."""
    n = robot.dof
    if robot.convention == "dh":  # joint k turns about z of frame k - 1
        axes = [frames[k - 1] for k in range(1, n + 1)] + [frames[n]]
    else:  # mdh and urdf: joint k turns about its own frame k
        axes = [frames[k] for k in range(1, n + 1)] + [frames[n]]
    return [(axes[i][:3, 3], axes[i + 1][:3, 3]) for i in range(n)]


def link_lengths(robot: Robot) -> list[float]:
    """Each link's length [m] (nominal geometry; it does not depend on the readings)."""
    frames = Kinematics(robot).joint_frames(np.zeros(robot.dof), robot.parameter_vector())
    ends = link_ends(robot, [np.asarray(T) for T in frames])
    return [exact.norm(end - root) for root, end in ends]


class LinkDeflection(Effect):
    """The end of each link in ``joints`` (link i, the one joint i moves) sags along the
    load perpendicular to it; see the module docstring."""

    name = "link_deflection"
    title = "Link deflection"
    unit = "m/(N m)"
    typical = 1e-6
    sentence = "{joints} bend under the weight they carry ({values})"
    plot_variable = "joint"
    simulation_default = (2e-6, 2e-5, 1e-6, 1e-5)
    tracker_only = True
    formula = ("the arm beyond link i shifts by (f payload + f_m) |L| g_perp + (v payload + v_m)"
               "\n      |L| |g_perp| g/|g|, g_perp the part of gravity perpendicular to the link "
               "(tracker data only)")

    def __init__(self, joints: tuple[int, ...], payload: bool = True):
        super().__init__(joints)
        self.payload = bool(payload)

    def __repr__(self) -> str:
        return f"LinkDeflection(links={list(self.joints)}, payload={self.payload})"

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """``payload``: whether the sag under the payload is a term of its own."""
        return {"payload": self.payload}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> LinkDeflection:
        return cls(tuple(int(j) for j in entry["joints"]),
                   payload=bool(entry.get("payload", True)))

    def reads_payload(self) -> bool:
        return self.payload

    def has_payload_term(self) -> bool:
        return self.payload

    @property
    def label(self) -> str:
        return f"{self.name}[link {', '.join(str(j) for j in self.joints)}]"

    def parameter_names(self) -> tuple[str, ...]:
        names: list[str] = []
        for i in self.joints:
            for stem in ("f", "v"):
                names += ([f"{stem}{i}"] if self.payload else []) + [f"{stem}{i}_m"]
        return tuple(names)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return OWN_WEIGHT if parameter.endswith("_m") else PER_MOMENT

    def parameter_joint(self, parameter: str) -> int | None:
        return None  # the link bends, whatever drives its joint

    def _check_amplitudes(self, values, robot=None) -> tuple[Implausible, ...]:
        """The payload's sag at a horizontal link, ``f_i + v_i``, must be positive."""
        out = []
        for i in self.joints:
            if f"f{i}" not in values and f"v{i}" not in values:
                continue
            sag = float(values.get(f"f{i}", 0.0)) + float(values.get(f"v{i}", 0.0))
            if sag < 0:
                out.append(Implausible(f"f{i}+v{i}", sag, self.unit, SAG, math.inf,
                                       f"f{i} + v{i} = {sag:.3g} {self.unit} is negative: link "
                                       f"{i} would rise under a payload ({SAG.basis})"))
        return tuple(out)

    def parameter_unit(self, parameter: str) -> str:
        return "m kg/(N m)" if parameter.endswith("_m") else self.unit

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> LinkDeflection:
        """The payload term where the data have a ``payload`` column."""
        return cls(tuple(joints), payload="payload" in (extras or {}))

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[LinkDeflection, ...]:
        """One per link at least ``MIN_LENGTH`` long (nominal geometry)."""
        return tuple(cls.create((i,), robot, extras)
                     for i, length in enumerate(link_lengths(robot), 1) if length >= MIN_LENGTH)

    def _check(self, robot: Robot) -> None:
        lengths = link_lengths(robot)
        for i in self.joints:
            if not 1 <= i <= robot.dof:
                raise InputError(f"{self.name}: link {i} does not exist; the robot "
                                 f"{robot.name!r} has links 1..{robot.dof}", where="effects")
            if lengths[i - 1] < 1e-6:
                raise InputError(f"{self.name}: link {i} has no length (its joint axes cross); "
                                 "it has nothing to bend", where="effects")

    @classmethod
    def for_simulation(cls, keys) -> LinkDeflection:
        return cls(tuple(int(k) for k in keys), payload=True)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, ca.SX]:
        robot = row.robot
        self._check(robot)
        ends = link_ends(robot, symbolic_frames(robot, row.registry, row.q, row.p))
        g = ca.DM(robot.gravity)
        down = g / float(np.linalg.norm(robot.gravity))
        smooth2 = float(SMOOTH * np.linalg.norm(robot.gravity)) ** 2
        payload = row.extras.get("payload", 0.0)
        shift = ca.SX.zeros(3)
        k = 0
        for i in self.joints:
            root, end = ends[i - 1]
            link = end - root
            length2 = ca.dot(link, link)
            perpendicular = g - ca.dot(g, link) * link / length2
            moment_arm = ca.sqrt(length2)  # bending moment per unit load [m]
            for direction in (perpendicular,
                              ca.sqrt(ca.dot(perpendicular, perpendicular) + smooth2) * down):
                load: ca.SX | float = 0
                if self.payload:
                    load = theta[k] * payload
                    k += 1
                load = load + theta[k]
                k += 1
                shift += load * moment_arm * direction
        entries = {row.registry.index(name): shift[c] for c, name in enumerate(SHIFT)}
        return ca.SX.zeros(robot.dof), column(entries, len(row.registry))

    def describe(self, values, units: Units) -> str:
        parts = ", ".join(f"{k} = {v:.3g} {self.parameter_unit(k)}" for k, v in values.items())
        links = joint_list(self.joints).replace("joint", "link")
        return self.sentence.format(joints=links, values=parts)

    def check_simulation(self, robot: Robot, values) -> None:
        super().check_simulation(robot, values)
        self._check(robot)

    def simulated_shift(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """The true shift (N x 3) [m], world frame, of everything beyond the links at true
        joints ``Q`` (N x dof), from the true robot's frames and the rows' ``payload``."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        kinematics = Kinematics(world.robot)
        payload = np.asarray(extras.get("payload", np.zeros(len(Q))), dtype=float)
        g = np.asarray(world.robot.gravity, dtype=float)
        size = exact.norm(g)
        out = np.zeros((len(Q), 3))
        for r, q in enumerate(Q):
            frames = [np.asarray(T) for T in kinematics.joint_frames(q, kinematics.nominal)]
            ends = link_ends(world.robot, frames)
            for i in self.joints:
                root, end = ends[i - 1]
                length = exact.norm(end - root)
                u = (end - root) / length
                across = g - exact.dot(g, u) * u
                sag = np.hypot(exact.norm(across), SMOOTH * size) * g / size
                bend = values.get(f"f{i}", 0.0) * payload[r] + values[f"f{i}_m"]
                drop = values.get(f"v{i}", 0.0) * payload[r] + values[f"v{i}_m"]
                out[r] += length * (bend * across + drop * sag)
        return out
