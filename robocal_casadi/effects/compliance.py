"""Joint compliance: each joint gives way in proportion to the gravity torque it holds.

With link masses in the robot file (``mass``, ``com`` on every joint):

    dq_j = -c_j * tau_j(q)           c_j [rad/Nm] (revolute) or [m/N] (prismatic)

``tau(q)`` is the generalized gravity torque the motors apply to hold the arm
(``gravity.gravity_torque``: links plus a point payload of the row's ``payload`` [kg],
0 without that column, at ``payload_com`` [m] in the flange frame). Parameters ``c{j}``.

Without masses (lumped unknowns). The gravity torque is linear in the unknown first
moments ``h_k = m_k com_k`` [kg m] and masses ``m_k`` [kg] of the links,
``tau_j = sum_k B_jk(q) pi_k`` (``gravity.first_moment_basis``), so

    dq_j = -c_j * payload * tau1_j(q) - sum_(k, i) w_jki * B_j,(k, i)(q)

with ``tau1`` the torque of 1 kg at ``payload_com`` and ``w_jki = c_j pi_ki`` the products
of the compliance with link k's first moment (``c{j}_h{k}x|y|z`` [rad/Nm x kg m]) or mass
(``c{j}_m{k}`` [rad/Nm x kg]). Taking each product as its own unknown makes the model
linear. Many basis columns are linearly dependent as functions of ``q`` (a link's mass
and the previous link's moment along a parallel axis; terms constant in ``q``, which the
joint's ``theta`` offset already holds), so for each joint only a maximal independent set
is kept: the columns are sampled at random readings within the joint limits (nominal
geometry, fixed seed), a constant column is put first, and pivoted Gram-Schmidt keeps
each column whose part outside the span of the ones before it exceeds 1e-6 of its
norm. ``c{j}`` itself appears only with a ``payload`` column (``payload=True``), where the
known payload mass makes it separable.

Plausible values on real robots: ``c_j`` positive, about 1e-7 .. 1e-4 rad/Nm for gear
trains and cycloidal reducers (large arms are stiff, light collaborative arms soft),
1e-6 .. 1e-3 rad/Nm for strain-wave gears and belts (small strain-wave gears have
torsional stiffnesses of a few thousand Nm/rad), 1e-6 .. 1e-2 rad/Nm for cables and
direct drives (a cable-driven joint holds a few hundred to a few thousand Nm/rad; a
direct drive only what its servo loop gives). A lumped term ``c_j h_k`` or ``c_j m_k``
is the compliance times a first moment [kg m] or a mass [kg] of one link, and either
may have any sign (it depends on where the link's centre of mass lies in its frame).
Its magnitude is at most the largest compliance of the drive times the largest first
moment or mass a link of an industrial arm carries; for gear trains: 1e-4 rad/Nm x
500 kg m = 5e-2 for a moment term, 1e-4 rad/Nm x 1000 kg = 1e-1 for a mass term (a
1000 kg link whose compliance is 1e-4 would be far softer than any real arm; the bound is
deliberately wide, it refuses only what no arm does).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ..common import exact
from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from .base import Effect, Plausible, RowContext, TrueWorld, joint_list
from .checks import check_joints, column
from .drives import per_drive, scaled
from .gravity import (
    FIRST_MOMENT_COMPONENTS,
    first_moment_basis,
    gravity_torque,
    payload_torque_per_kg,
)

SAMPLES = 96
INDEPENDENCE = 1e-6
COMPLIANCE = per_drive(
    Plausible(1e-4, 1e-7, +1, "joint stiffness of industrial and collaborative arms: "
              "1e-7 .. 1e-4 rad/Nm"),
    harmonic=Plausible(1e-3, 1e-6, +1, "strain-wave gears: 1e-6 .. 1e-3 rad/Nm"),
    belt=Plausible(1e-3, 1e-6, +1, "belt drives: 1e-6 .. 1e-3 rad/Nm"),
    cable=Plausible(1e-2, 1e-6, +1, "cable drives: 1e-6 .. 1e-2 rad/Nm"),
    direct=Plausible(1e-2, 1e-6, +1, "direct drives, held by the servo loop: "
                     "1e-6 .. 1e-2 rad/Nm"))
_SOFTER = {drive: COMPLIANCE[drive].maximum / COMPLIANCE["gear"].maximum for drive in COMPLIANCE}
MOMENT_TERM = scaled(per_drive(Plausible(5e-2, basis="compliance 1e-4 rad/Nm times a link "
                                         "first moment of 500 kg m at most")),
                     _SOFTER, "times the drive's larger compliance")
MASS_TERM = scaled(per_drive(Plausible(1e-1, basis="compliance 1e-4 rad/Nm times a link mass "
                                       "of 1000 kg at most")),
                   _SOFTER, "times the drive's larger compliance")


@lru_cache(maxsize=16)
def _torque_function(robot: Robot) -> ca.Function:
    """``(q, p, payload, payload_com) -> tau`` [Nm or N], built once per robot."""
    registry = robot.parameters()
    q = ca.SX.sym("q", robot.dof)
    p = ca.SX.sym("p", len(registry))
    payload = ca.SX.sym("payload")
    com = ca.SX.sym("payload_com", 3)
    return ca.Function("gravity_torque", [q, p, payload, com],
                       [gravity_torque(robot, registry, q, p, payload, com)])


@lru_cache(maxsize=16)
def _lumped_functions(robot: Robot) -> tuple[ca.Function, ca.Function]:
    """``(q, p) -> basis`` (dof x 4 dof) and ``(q, p, payload_com) -> tau per kg``."""
    registry = robot.parameters()
    q = ca.SX.sym("q", robot.dof)
    p = ca.SX.sym("p", len(registry))
    com = ca.SX.sym("payload_com", 3)
    basis = ca.Function("first_moment_basis", [q, p], [first_moment_basis(robot, registry, q, p)])
    per_kg = ca.Function("payload_torque_per_kg", [q, p, com],
                         [payload_torque_per_kg(robot, registry, q, p, com)])
    return basis, per_kg


def sampled_basis(robot: Robot, samples: int, seed: int) -> np.ndarray:
    """``first_moment_basis`` (samples x dof x 4 dof) at ``samples`` configurations drawn
    uniformly within the joint limits (a full turn where there are none) from ``seed``:
    where the lumped terms are judged independent."""
    basis, _ = _lumped_functions(robot)
    rng = np.random.default_rng(seed)
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    Q = rng.uniform(lower, upper, size=(samples, robot.dof))
    p = robot.parameter_vector()
    return np.array([np.asarray(basis(q, p)) for q in Q])


def independent_terms(robot: Robot, joint: int, *, samples: int = SAMPLES,
                      seed: int = 0) -> tuple[int, ...]:
    """Columns of ``first_moment_basis`` row ``joint`` (1-based) kept as lumped unknowns.

    A maximal set independent of each other and of a constant (see the module
    docstring), in the order found.
    """
    rows = sampled_basis(robot, samples, seed)[:, joint - 1]  # samples x 4 dof
    norms = exact.norm(rows, axis=0)
    # a unit first moment (1 kg m) gives torques of order |g|: below that, roundoff
    scale = max(float(norms.max()), exact.norm(robot.gravity) * np.sqrt(samples))
    constant = np.ones((samples, 1)) / np.sqrt(samples)
    kept, _ = exact.independent_columns(rows, constant, INDEPENDENCE * scale, INDEPENDENCE)
    return tuple(kept)


def _term_name(joint: int, term: int) -> str:
    link, component = divmod(term, len(FIRST_MOMENT_COMPONENTS))
    c = FIRST_MOMENT_COMPONENTS[component]
    return f"c{joint}_m{link + 1}" if c == "m" else f"c{joint}_h{link + 1}{c}"



def require_inertia(robot: Robot, effect: str) -> None:
    """Refuse to simulate ``effect`` under gravity on a robot file without masses."""
    if not robot.has_inertia:
        raise InputError(f"{effect} needs 'mass' and 'com' on every joint of the robot file "
                         f"to simulate gravity torques", where=f"effects.{effect}")


class JointCompliance(Effect):
    """``dq_j = -c_j tau_j(q)`` for each joint j in ``joints``; see the module docstring.

    ``robot``: give it to choose the form; a robot without masses selects the lumped
    form (its independent terms are fixed here). Without ``robot`` the link masses are
    required at ``delta``. ``payload``: in the lumped form, whether the data carries a
    ``payload`` column (adds ``c{j}``).
    """

    name = "joint_compliance"
    title = "Joint compliance"
    unit = "rad/Nm"
    typical = 1e-6
    sentence = "{joints} {verb} under gravity ({values})"
    plot_variable = "torque"
    simulation_default = (1e-6,)
    formula = "q_true = q_read - c g(q_read), g the gravity torque (links + payload column)"
    view_quantity = "deflection"

    @classmethod
    def view_caption(cls, torque: bool) -> tuple[str, str]:
        if torque:
            return ("against the gravity torque the joint holds, computed with pinocchio from "
                    "the calibrated robot's link masses and the data's payload column. Without "
                    "compliance the error grows with the torque; with it, it does not",
                    "the dashed line (right axis) is the fitted deflection -c tau")
        return ("against the joint angle: the robot file gives no link masses, so the "
                "gravity torque cannot be computed and the compliance was fitted with "
                "lumped link terms",
                "the black points (right axis) are the fitted deflection at each "
                "measurement, which depends on the whole pose")

    def __init__(self, joints: tuple[int, ...], robot: Robot | None = None,
                 payload: bool = False):
        super().__init__(joints)
        self.lumped = robot is not None and not robot.has_inertia
        self.payload = bool(payload)
        self.terms: dict[int, tuple[int, ...]] = {}
        if robot is not None and self.lumped:
            check_joints(self, robot)
            self.terms = {j: independent_terms(robot, j) for j in self.joints}

    def __repr__(self) -> str:
        form = ", lumped" if self.lumped else ""
        return f"JointCompliance(joints={list(self.joints)}{form})"

    def with_terms_named(self, names, robot: Robot) -> JointCompliance:
        """The lumped form with exactly the terms ``names`` holds (``c{j}_h{k}x`` ...), as
        a calibration chose them: which terms are independent is judged numerically on
        the geometry at hand, so a file written at one geometry is read back by name."""
        if not self.lumped:
            return self
        order = {name: k for k, name in enumerate(names)}
        count = len(FIRST_MOMENT_COMPONENTS) * robot.dof  # the basis's columns
        for joint in self.joints:
            found = [t for t in range(count) if _term_name(joint, t) in order]
            self.terms[joint] = tuple(sorted(found, key=lambda t: order[_term_name(joint, t)]))
        return self

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """``payload``: whether the payload term was (or, with a payload column in the
        data, could have been) identified."""
        return {"payload": bool(self.payload or "payload" in columns)}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> JointCompliance:
        """Lumped terms read back by name (``with_terms_named``)."""
        names = [str(n) for n in entry["parameters"]]
        return cls(tuple(int(j) for j in entry["joints"]), robot=robot,
                   payload=entry.get("payload", False)).with_terms_named(names, robot)

    def reads_payload(self) -> bool:
        return True

    def has_payload_term(self) -> bool:
        return self.payload

    @classmethod
    def compliance_parameter(cls, joint: int) -> str | None:
        return f"c{joint}"

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> JointCompliance:
        """Lumped without link masses; the payload term where the data has ``payload``."""
        return cls(tuple(joints), robot=robot, payload="payload" in (extras or {}))

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        if "_m" in parameter:
            return MASS_TERM[drive]
        if "_h" in parameter:
            return MOMENT_TERM[drive]
        return COMPLIANCE[drive]

    def parameter_unit(self, parameter: str) -> str:
        if "_m" in parameter:
            return "rad kg/Nm"
        if "_h" in parameter:
            return "rad kg m/Nm"
        return self.unit

    def describe(self, values, units: Units) -> str:
        verb = "deflects" if len(self.joints) == 1 else "deflect"
        if self.lumped:
            text = f"lumped link masses: {len(values)} terms"
        else:
            text = ", ".join(f"{k} = {v:.3g}" for k, v in values.items()) + f" {self.unit}"
        return self.sentence.format(joints=joint_list(self.joints), verb=verb, values=text)

    def plot_values(self, robot: Robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The gravity torque [Nm] (force [N]) the joint holds, from pinocchio with the
        ``payload`` column; the joint angle where the robot file has no masses."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if not robot.has_inertia:
            return Q[:, joint - 1]
        from ..model.pinocchio_model import gravity_torques

        return gravity_torques(robot, Q, payload_mass=extras.get("payload", 0.0),
                               payload_com=payload_com)[:, joint - 1]

    def check_simulation(self, robot: Robot, values) -> None:
        super().check_simulation(robot, values)
        require_inertia(robot, self.name)

    def simulated_dq(self, world: TrueWorld, Q, extras, values) -> np.ndarray:
        """``-c_j tau_j(q)`` with pinocchio's gravity torque of the true robot's links and the
        row's payload (needs masses in the robot file)."""
        from ..model.pinocchio_model import gravity_torques

        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        dq = np.zeros(Q.shape)
        payload = np.asarray(extras.get("payload", np.zeros(len(Q))), dtype=float)
        torques = gravity_torques(world.robot, Q, payload, world.payload_com)
        for j in self.joints:
            dq[:, j - 1] = -values[f"c{j}"] * torques[:, j - 1]
        return dq

    def parameter_names(self) -> tuple[str, ...]:
        if not self.lumped:
            return tuple(f"c{j}" for j in self.joints)
        names: list[str] = []
        for j in self.joints:
            if self.payload:
                names.append(f"c{j}")
            names.extend(_term_name(j, t) for t in self.terms[j])
        return tuple(names)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, None]:
        check_joints(self, row.robot)
        payload = row.extras.get("payload", 0.0)
        entries: dict[int, ca.SX | float] = {}
        if not self.lumped:
            tau = _torque_function(row.robot)(row.q, row.p, payload, row.payload_com)
            for k, j in enumerate(self.joints):
                entries[j - 1] = -theta[k] * tau[j - 1]
            return column(entries, row.robot.dof), None
        basis_function, per_kg_function = _lumped_functions(row.robot)
        basis = basis_function(row.q, row.p)
        per_kg = per_kg_function(row.q, row.p, row.payload_com)
        k = 0
        for j in self.joints:
            deflection: ca.SX | float = 0
            if self.payload:
                deflection = deflection - theta[k] * payload * per_kg[j - 1]
                k += 1
            for t in self.terms[j]:
                deflection = deflection - theta[k] * basis[j - 1, t]
                k += 1
            entries[j - 1] = deflection
        return column(entries, row.robot.dof), None
