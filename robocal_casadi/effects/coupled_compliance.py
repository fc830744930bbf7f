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

Without masses (lumped unknowns), as ``joint_compliance`` does it: the torque is linear in
the links' unknown first moments and masses ``pi_k``, ``tau_b = sum_k B_bk(q) pi_k``
(``gravity.first_moment_basis``), so

    dq_a = -sum_b sum_k w_abk B_bk(q),        w_abk = C_ab pi_k = w_bak

and each product ``w_abk`` (a <= b) is one unknown, ``cc{a}_{b}_h{k}x|y|z`` [rad/Nm x
kg m] or ``cc{a}_{b}_m{k}`` [rad/Nm x kg]: a diagonal product moves joint a by ``B_ak``, a
cross product moves joint a by ``B_bk`` and joint b by ``B_ak``. Of these only a maximal
set independent of each other and of a constant per joint (what the joints' ``theta``
offsets already hold) is kept, judged over the whole group's deflections at random
readings within the joint limits (nominal geometry, fixed seed; pivoted Gram-Schmidt,
the diagonal products first, each kept whose part outside the span before it exceeds 1e-6
of its norm). ``cc{a}_{b}`` itself appears only with a ``payload`` column, whose known mass
makes it separable (``payload=True``).

Plausible on real robots, by the joint's drive: the diagonal positive and as large as
``joint_compliance`` allows on that drive (``compliance.COMPLIANCE``: 1e-4 rad/Nm for gear
trains, 1e-2 rad/Nm for cables); an off-diagonal term of either sign, at most that
largest magnitude; a lumped product of either sign, within the bounds of
``joint_compliance``'s lumped terms on that drive. Diagnosis offers it on each group the
robot file declares.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from functools import lru_cache
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
from .compliance import (
    COMPLIANCE,
    INDEPENDENCE,
    MASS_TERM,
    MOMENT_TERM,
    SAMPLES,
    _lumped_functions,
    _torque_function,
    require_inertia,
    sampled_basis,
)
from .gravity import FIRST_MOMENT_COMPONENTS

CROSS = {drive: Plausible(limits.maximum, basis=f"cross compliance of joints driven together, "
                          f"at most the largest own compliance ({limits.basis})")
         for drive, limits in COMPLIANCE.items()}
NAME = re.compile(r"cc(\d+)_(\d+)(?:_([hm])(\d+)([xyz]?))?")

Term = tuple[int, int, int]  # (a, b, basis column) of a lumped product w_abk, a <= b


def _pairs(group: Sequence[int]) -> tuple[tuple[int, int], ...]:
    """(a, b) with a before or equal to b in the group's order: the entries of ``C``."""
    return tuple((a, b) for i, a in enumerate(group) for b in group[i:])


def _term_name(term: Term) -> str:
    a, b, t = term
    link, component = divmod(t, len(FIRST_MOMENT_COMPONENTS))
    c = FIRST_MOMENT_COMPONENTS[component]
    return f"cc{a}_{b}_m{link + 1}" if c == "m" else f"cc{a}_{b}_h{link + 1}{c}"


def _term_of(name: str) -> Term | None:
    """The lumped product a name holds, None for an entry of ``C`` itself."""
    found = NAME.fullmatch(name)
    if found is None or found.group(3) is None:
        return None
    a, b, kind, link, axis = found.groups()
    component = FIRST_MOMENT_COMPONENTS.index("m" if kind == "m" else axis)
    return int(a), int(b), (int(link) - 1) * len(FIRST_MOMENT_COMPONENTS) + component


def _deflection(group: tuple[int, ...], term: Term, rows: np.ndarray) -> np.ndarray:
    """The group's joints' deflection per unit ``w_abk`` (samples x n) from the basis rows
    (samples x dof x columns)."""
    a, b, t = term
    out = np.zeros((rows.shape[0], len(group)))
    out[:, group.index(a)] = rows[:, b - 1, t]
    if a != b:
        out[:, group.index(b)] = rows[:, a - 1, t]
    return out


@lru_cache(maxsize=16)
def independent_products(robot: Robot, group: tuple[int, ...], *, samples: int = SAMPLES,
                         seed: int = 0) -> tuple[Term, ...]:
    """The lumped products of ``group`` kept as unknowns (see the module docstring): a
    maximal set independent of each other and of a constant per joint, diagonal products
    first, in the order found."""
    rows = sampled_basis(robot, samples, seed)  # samples x dof x 4 dof
    n, count = len(group), rows.shape[2]
    constants = [np.kron(np.ones(samples), np.eye(n)[i]) / np.sqrt(samples) for i in range(n)]
    span = np.array(constants).T  # (samples n) x n, orthonormal
    # a unit first moment (1 kg m) gives torques of order |g|: below that, roundoff
    scale = exact.norm(robot.gravity) * np.sqrt(samples)
    kept: list[Term] = []
    for diagonal in (True, False):
        terms = [(a, b, t) for a, b in _pairs(group) if (a == b) == diagonal
                 for t in range(count)]
        columns = np.array([_deflection(group, term, rows).ravel() for term in terms]).T
        # sums in a fixed order (``exact``): which products are kept must not turn on the
        # BLAS kernel
        scale = max(scale, float(exact.norm(columns, axis=0).max()))
        found, span = exact.independent_columns(columns, span, INDEPENDENCE * scale,
                                                INDEPENDENCE)
        kept += [terms[k] for k in found]
    return tuple(kept)


class CoupledCompliance(Effect):
    """``dq_G = -C_G tau_G(q)`` for each coupled group G in ``groups``; see the module.

    ``robot``: give it to choose the form; a robot without masses selects the lumped
    form (its independent products are fixed here). ``payload``: in the lumped form,
    whether the data carries a ``payload`` column (adds the entries of ``C`` themselves).
    """

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

    def __init__(self, groups: Sequence[Sequence[int]], robot: Robot | None = None,
                 payload: bool = False):
        self.groups = tuple(tuple(int(j) for j in g) for g in groups)
        super().__init__(tuple(j for g in self.groups for j in g))
        self.lumped = robot is not None and not robot.has_inertia
        self.payload = bool(payload)
        self.terms: dict[tuple[int, ...], tuple[Term, ...]] = {}
        if robot is not None and self.lumped:
            self._check(robot)
            self.terms = {g: independent_products(robot, g) for g in self.groups}

    def __repr__(self) -> str:
        form = ", lumped" if self.lumped else ""
        return f"CoupledCompliance(groups={[list(g) for g in self.groups]}{form})"

    def parameter_names(self) -> tuple[str, ...]:
        names: list[str] = []
        for g in self.groups:
            if not self.lumped or self.payload:
                names.extend(f"cc{a}_{b}" for a, b in _pairs(g))
            names.extend(_term_name(term) for term in self.terms.get(g, ()))
        return tuple(names)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        found = NAME.fullmatch(parameter)
        if found is None:
            raise KeyError(f"coupled_compliance has no parameter {parameter!r}")
        a, b, kind = found.group(1), found.group(2), found.group(3)
        if kind == "m":
            return MASS_TERM[drive]
        if kind == "h":
            return MOMENT_TERM[drive]
        return COMPLIANCE[drive] if a == b else CROSS[drive]

    def parameter_unit(self, parameter: str) -> str:
        found = NAME.fullmatch(parameter)
        kind = None if found is None else found.group(3)
        return {"m": "rad kg/Nm", "h": "rad kg m/Nm"}.get(kind or "", self.unit)

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        return {"groups": [list(g) for g in self.groups],
                "payload": bool(self.payload or "payload" in columns)}

    def truth_settings(self) -> dict[str, Any]:
        return {"groups": [list(g) for g in self.groups]}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> CoupledCompliance:
        """The groups as written (or the robot's holding ``joints``); lumped products read
        back by name: which are independent is judged numerically on the geometry at hand,
        so a file written at one geometry is read back as it was fitted."""
        groups = entry.get("groups")
        if groups is None:
            groups = cls.create(tuple(int(j) for j in entry["joints"]), robot).groups
        effect = cls([[int(j) for j in g] for g in groups], robot=robot,
                     payload=bool(entry.get("payload", False)))
        if effect.lumped:
            terms = [t for t in (_term_of(str(n)) for n in entry["parameters"]) if t]
            effect.terms = {g: tuple(t for t in terms if t[0] in g) for g in effect.groups}
        return effect

    def reads_payload(self) -> bool:
        return True

    def has_payload_term(self) -> bool:
        return self.payload

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> CoupledCompliance:
        """The groups of ``robot``'s transmission that hold ``joints``; lumped without link
        masses, the payload terms where the data has ``payload``."""
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
        return cls(groups, robot=robot, payload="payload" in (extras or {}))

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[CoupledCompliance, ...]:
        """One per declared transmission group."""
        return tuple(cls([g.joints], robot=robot, payload="payload" in extras)
                     for g in robot.transmission)

    @classmethod
    def merged(cls, units, robot: Robot, extras: Mapping[str, Any]) -> CoupledCompliance:
        groups = sorted({g for unit in units for g in unit.groups})
        return cls(groups, robot=robot, payload="payload" in extras)

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
        named = {n: theta[k] for k, n in enumerate(self.parameter_names())}
        entries: dict[int, Any] = {}

        def add(a: int, b: int, value, torque) -> None:
            # w_ab moves joint a by the torque term of joint b, and b by that of a
            entries[a - 1] = entries.get(a - 1, 0) - value * torque(b)
            if a != b:
                entries[b - 1] = entries.get(b - 1, 0) - value * torque(a)

        if not self.lumped:
            tau = _torque_function(row.robot)(row.q, row.p, payload, row.payload_com)
            for group in self.groups:
                for a, b in _pairs(group):
                    add(a, b, named[f"cc{a}_{b}"], lambda j: tau[j - 1])
            return column(entries, row.robot.dof), None
        basis_function, per_kg_function = _lumped_functions(row.robot)
        basis = basis_function(row.q, row.p)
        per_kg = per_kg_function(row.q, row.p, row.payload_com)
        for group in self.groups:
            if self.payload:
                for a, b in _pairs(group):
                    add(a, b, named[f"cc{a}_{b}"], lambda j: payload * per_kg[j - 1])
            for term in self.terms[group]:
                add(term[0], term[1], named[_term_name(term)],
                    lambda j, t=term[2]: basis[j - 1, t])
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
            joints = "-".join(map(str, group))
            if self.lumped:
                found = [NAME.fullmatch(n) for n in values]
                count = sum(1 for m in found if m is not None and int(m.group(1)) in group)
                parts.append(f"joints {joints} deflect together under gravity (lumped link "
                             f"masses: {count} terms)")
                continue
            own = ", ".join(f"{values.get(f'cc{a}_{a}', 0.0):.3g}" for a in group)
            cross = ", ".join(f"{a}-{b}: {values.get(f'cc{a}_{b}', 0.0):.3g}"
                              for a, b in _pairs(group) if a != b)
            parts.append(f"joints {joints} deflect together under gravity "
                         f"(own {own}; cross {cross} {self.unit})")
        return "; ".join(parts)

    def plot_values(self, robot: Robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The gravity torque [Nm] the joint holds (pinocchio, with the payload column); the
        joint angle where the robot file has no masses."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if not robot.has_inertia:
            return Q[:, joint - 1]
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
        require_inertia(robot, self.name)

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
