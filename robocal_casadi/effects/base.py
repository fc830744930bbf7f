"""The contract every effect model fulfils.

An effect is something the DH model lacks (joint compliance, periodic gear errors, a
gear-ratio error, thermal growth, coupling between joints, backlash). It owns a few
named parameters ``theta`` and, for one row of data, returns corrections to the joint
readings and to the geometric parameters:

    q_effective = q + dq(q, p, extras; theta)        [rad or m], joint space
    p_effective = p + dp(q, p, extras; theta)        [SI], geometric registry order

Forward kinematics is then evaluated at ``(q_effective, p_effective)``; ``q`` are the
readings (what the controller reports), ``p`` the robot's DH parameters (lengths [m],
angles [rad], in the frames of the DH convention), ``extras`` the row's extra columns
(``temperature`` [C], ``time`` [s], ``payload`` [kg]) and the per-row inputs derived from
the table's order (``direction_q{j}``, see ``motion``). ``delta`` is CasADi SX, so
identification gets exact derivatives.

Adding an effect means writing one subclass in one module of this package and listing
it in ``effects/__init__.py``'s registry; everything else reads the class:

* ``name`` (result.json), ``title`` (report heading), ``unit`` (of the parameters),
  ``sentence`` (template of ``describe``), ``plot_variable`` (what to plot it against);
* ``plausible(parameter, drive)`` (the range seen on real robots with that kind of drive,
  ``drives``; for refusing absurd estimates), ``typical`` (a typical size, for judging
  whether data see it); ``drives`` (the drives the effect is looked for on);
* ``candidates`` / ``merged`` (the units diagnosis tests one by one, and one effect
  holding several of them), ``create`` (one effect from a result's joints);
* ``simulation_default`` and ``simulated_dq`` / ``simulated_dp``: the truth for the
  simulator, in numpy, written independently of ``delta``.
"""

from __future__ import annotations

import math
import re
from abc import ABC, abstractmethod
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ..common.units import Units
from ..errors import InputError
from ..model.parameters import ParameterRegistry
from ..model.robot import DEFAULT_DRIVE, DRIVES, Robot


@dataclass(frozen=True)
class RowContext:
    """What an effect may look at for one data row (all CasADi SX).

    ``q`` (dof,) joint readings; ``p`` geometric parameters (registry order, SI);
    ``extras`` maps column names (``temperature`` [C], ``time`` [s], ``payload`` [kg],
    ``direction_q{j}`` [1], ...) to scalar symbols; ``payload_com`` (3,) [m] in the flange
    frame; ``constants`` the effect's own ``Effect.constants`` as symbols (None where the
    caller gives none: the effect then uses its numbers directly).
    """

    robot: Robot
    registry: ParameterRegistry
    q: ca.SX
    p: ca.SX
    extras: dict
    payload_com: ca.SX
    constants: ca.SX | None = None


@dataclass(frozen=True)
class Plausible:
    """The range of one parameter on real robots, in the parameter's unit (SI).

    ``maximum``: the largest plausible magnitude ``|value|``; ``minimum``: the smallest
    plausible nonzero magnitude (0: any small value is plausible); ``sign``: +1 the value
    must not be negative, -1 not positive, 0 either; ``basis``: where the numbers come
    from, in words.
    """

    maximum: float
    minimum: float = 0.0
    sign: int = 0
    basis: str = ""

    def __post_init__(self):
        if not 0.0 <= self.minimum <= self.maximum:
            raise ValueError(f"Plausible: need 0 <= minimum <= maximum, got {self.minimum}, "
                             f"{self.maximum}")
        if self.sign not in (-1, 0, 1):
            raise ValueError(f"Plausible: sign must be -1, 0 or +1, got {self.sign}")


@dataclass(frozen=True)
class Implausible:
    """One estimate outside its ``Plausible`` range: which, by how much, in words.

    ``factor`` is how far outside: ``|value| / maximum`` above the range,
    ``minimum / |value|`` below it, ``inf`` for a wrong sign.
    """

    parameter: str
    value: float
    unit: str
    plausible: Plausible
    factor: float
    message: str


def amplitude_check(effect: Effect, pairs, values: Mapping[str, float],
                    robot: Robot | None = None) -> tuple[Implausible, ...]:
    """``Implausible`` for each (sine, cosine) parameter pair whose amplitude
    ``hypot(sine, cosine)`` exceeds the sine's largest plausible magnitude on its joint's
    drive (gear without ``robot``), named ``sine/cosine``."""
    out = []
    for sine, cosine in pairs:
        limits = effect.plausible_on(sine, robot)
        if sine not in values and cosine not in values:
            continue
        amplitude = math.hypot(float(values.get(sine, 0.0)), float(values.get(cosine, 0.0)))
        if amplitude > limits.maximum:
            factor = amplitude / limits.maximum
            out.append(Implausible(f"{sine}/{cosine}", amplitude, effect.unit, limits, factor,
                                   f"the amplitude of {sine} and {cosine}, {amplitude:.3g} "
                                   f"{effect.unit}, is {factor:.3g} times the largest plausible "
                                   f"{limits.maximum:.3g} {effect.unit} ({limits.basis})"))
    return tuple(out)


@dataclass(frozen=True)
class Contribution:
    """An effect evaluated on N rows: ``dq`` (N x dof) [rad or m] and ``dp`` (N x number of
    geometric parameters) [SI], the corrections of ``delta`` at the given ``theta``."""

    dq: np.ndarray
    dp: np.ndarray


@dataclass(frozen=True)
class TrueWorld:
    """What the simulator's truth of an effect may use besides the rows.

    ``robot`` the true robot (its geometry, masses, gravity); ``payload_com`` (3,) [m] in
    the flange frame; ``reference_temperature`` [C], the ``T_ref`` of thermal growth.
    """

    robot: Robot
    payload_com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    reference_temperature: float = 20.0


class Effect(ABC):
    """One effect with named parameters ``theta``; see the module docstring.

    Class attributes every subclass sets:

    ``name``: the name in result.json (``joint_compliance``); ``title``: the
    name in words (``Joint compliance``); ``unit``: of the parameters in result.json
    (``rad/Nm``); ``typical``: a typical parameter magnitude [unit], for judging whether
    the data see the effect; ``sentence``: a ``str.format`` template of one sentence
    saying what the fitted values mean, filled by ``describe``; ``plot_variable``: what the
    error is plotted against (``PLOT_VARIABLES``); ``per``: what one candidate (and one
    simulated entry) is: ``joint``, ``pair`` (a joint and the joint driving it) or
    ``column`` (one data column, no joints); ``revolute_only``: whether the joints must be
    revolute; ``drives``: the drives of the joints diagnosis looks for it on (backlash on
    geared joints, friction hysteresis on the others); ``tracker_only``: whether the
    simulator injects it only into data taken at any configuration (its truth needs the
    whole table in order, or shifts the measured point); ``simulation_default``: the true
    values of one entry [unit] the simulator uses when none are given, in
    ``parameter_names`` order; ``formula``: the relation in one line, as the terminal
    shows it (``q_true = (1 + s) q_read``); ``data_columns``: the data columns (besides
    ``payload``) diagnosis gathers for its candidates (``temperature`` [C], ``time`` [s]);
    ``view_quantity``: what the report calls the fitted ``dq``; ``view_curve``: whether that
    ``dq`` at a joint is a function of the plotted variable alone (drawn as a line).
    """

    PLOT_VARIABLES: ClassVar[tuple[str, ...]] = ("joint", "torque", "driver", "direction",
                                                  "column")

    name: ClassVar[str]
    title: ClassVar[str]
    unit: ClassVar[str]
    typical: ClassVar[float]
    sentence: ClassVar[str]
    plot_variable: ClassVar[str]
    per: ClassVar[str] = "joint"
    revolute_only: ClassVar[bool] = False
    drives: ClassVar[tuple[str, ...]] = DRIVES
    tracker_only: ClassVar[bool] = False
    simulation_default: ClassVar[tuple[float, ...]]
    formula: ClassVar[str]
    data_columns: ClassVar[tuple[str, ...]] = ()
    view_quantity: ClassVar[str] = "reading error"
    view_curve: ClassVar[bool] = False

    def __init__(self, joints: tuple[int, ...]):
        self.joints = tuple(int(j) for j in joints)  # 1-based

    def __repr__(self) -> str:
        return f"{type(self).__name__}(joints={list(self.joints)})"

    def moved_joints(self, robot: Robot) -> tuple[int, ...]:
        """The joints (1-based) whose ``dq`` the effect may change on ``robot``: its own
        ``joints`` unless it acts through a transmission (``motor_play``)."""
        return self.joints

    @property
    def label(self) -> str:
        return f"{self.name}{list(self.joints)}"

    # ----------------------------------------------------------------- parameters

    @abstractmethod
    def parameter_names(self) -> tuple[str, ...]:
        """Names of ``theta``, unique across effects (e.g. ``("c2", "c3")``)."""

    def registry(self) -> ParameterRegistry:
        names = self.parameter_names()
        return ParameterRegistry(names, ("none",) * len(names))

    @abstractmethod
    def plausible(self, parameter: str, drive: str = DEFAULT_DRIVE) -> Plausible:
        """The range of ``parameter`` (one of ``parameter_names``) on real robots whose
        joint has a ``drive`` (``robot.DRIVES``; effects.drives)."""

    def parameter_joint(self, parameter: str) -> int | None:
        """The joint (1-based) whose drive sets ``parameter``'s range, None for none: by
        default the first number in the name (``b2``, ``c3_h4x``, ``sin2_q5``)."""
        found = re.match(r"[A-Za-z]+(\d+)", parameter)
        return int(found.group(1)) if found else None

    def plausible_on(self, parameter: str, robot: Robot | None = None) -> Plausible:
        """``plausible`` for the drive of ``parameter``'s joint on ``robot`` (gear without)."""
        joint = self.parameter_joint(parameter)
        drive = DEFAULT_DRIVE
        if robot is not None and joint is not None and 1 <= joint <= robot.dof:
            drive = robot.drive(joint)
        return self.plausible(parameter, drive)

    def check_plausible(self, values: Mapping[str, float],
                        robot: Robot | None = None) -> tuple[Implausible, ...]:
        """Every estimate in ``values`` (name -> value, SI) outside its plausible range on
        ``robot``'s drives (gear drives without ``robot``).

        Empty when all are plausible; each entry says in words which parameter is
        outside, its value, the range and by what factor.
        """
        out = []
        for parameter, value in values.items():
            value = float(value)
            limits = self.plausible_on(parameter, robot)
            unit = self.parameter_unit(parameter)
            magnitude = abs(value)
            if not math.isfinite(value):
                out.append(Implausible(parameter, value, unit, limits, math.inf,
                                       f"{parameter} = {value} is not a finite number"))
            elif limits.sign and value * limits.sign < 0:
                found, expected = ("negative", "positive") if limits.sign > 0 else \
                    ("positive", "negative")
                out.append(Implausible(parameter, value, unit, limits, math.inf,
                                       f"{parameter} = {value:.3g} {unit} is {found}; on real "
                                       f"robots it is {expected} ({limits.basis})"))
            elif magnitude > limits.maximum:
                factor = magnitude / limits.maximum
                out.append(Implausible(parameter, value, unit, limits, factor,
                                       f"{parameter} = {value:.3g} {unit} is {factor:.3g} times "
                                       f"the largest plausible magnitude {limits.maximum:.3g} "
                                       f"{unit} ({limits.basis})"))
            elif 0 < magnitude < limits.minimum:
                factor = limits.minimum / magnitude
                out.append(Implausible(parameter, value, unit, limits, factor,
                                       f"{parameter} = {value:.3g} {unit} is {factor:.3g} times "
                                       f"smaller than the smallest seen on real robots, "
                                       f"{limits.minimum:.3g} {unit} ({limits.basis})"))
        return tuple(out) + self._check_amplitudes(values, robot)

    def _check_amplitudes(self, values: Mapping[str, float],
                          robot: Robot | None = None) -> tuple[Implausible, ...]:
        """Ranges on combinations of parameters (e.g. the amplitude of a sine and cosine
        pair); none by default."""
        return ()

    def implausibility(self, values: Mapping[str, float], robot: Robot | None = None) -> str:
        """'' when no estimate in ``values`` is absurd on ``robot``'s drives, else why, in
        words.

        Absurd means beyond the largest magnitude or of the wrong sign; a value smaller
        than real robots show is weak, not absurd, and is left to the evidence tests
        (``check_plausible`` reports it too).
        """
        return "; ".join(f.message for f in self.check_plausible(values, robot)
                         if f.value == 0 or abs(f.value) > f.plausible.minimum)

    def parameter_unit(self, parameter: str) -> str:
        """The unit of one parameter (``unit`` unless a subclass mixes units)."""
        return self.unit

    # ----------------------------------------------------------------- description

    def to_dict(self, values: Mapping[str, float],
                columns: Collection[str] = ()) -> dict[str, Any]:
        """One entry of ``effects_calibrated.yaml``: ``name``, ``joints`` (1-based),
        ``parameters`` (``values``, name -> SI, in ``parameter_names`` order) and the
        ``settings`` ``from_dict`` rebuilds the effect from; ``columns``: the extra columns of
        the data the values were fitted on."""
        return {"name": self.name, "joints": list(self.joints),
                "parameters": {n: float(values[n]) for n in self.parameter_names()},
                **self.settings(columns)}

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """What besides its joints and parameter names ``from_dict`` needs (none by
        default); ``columns`` as in ``to_dict``."""
        return {}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> Effect:
        """The effect an entry written by ``to_dict`` describes, for the calibrated
        ``robot``. A malformed entry raises ``KeyError``, ``TypeError`` or ``ValueError``
        (the reader names the file and entry)."""
        return cls(tuple(int(j) for j in entry["joints"]))

    def truth_dict(self, values: Mapping[str, float]) -> dict[str, Any]:
        """The entry of the simulator's ``truth.yaml``: ``joints``, ``unit``, the
        ``truth_settings`` and the true ``parameters`` (name -> SI)."""
        return {"joints": sorted(set(self.joints)), "unit": self.unit, **self.truth_settings(),
                "parameters": {n: float(values[n]) for n in self.parameter_names()}}

    def truth_settings(self) -> dict[str, Any]:
        """What a reader of ``truth.yaml`` needs besides joints and values (none by default)."""
        return {}

    def reads_payload(self) -> bool:
        """Whether ``delta`` reads the row's ``payload`` [kg]."""
        return False

    def has_payload_term(self) -> bool:
        """Whether the parameters include a term proportional to the payload, i.e. were
        identified with a payload in the data."""
        return False

    @classmethod
    def compliance_parameter(cls, joint: int) -> str | None:
        """The parameter holding ``joint``'s (1-based) compliance under gravity [rad/Nm],
        the figure a fleet compares across robots; None when the effect holds none."""
        return None

    # ----------------------------------------------------------------- data

    def required_columns(self) -> tuple[str, ...]:
        """Per-row inputs this effect reads from ``RowContext.extras`` besides ``payload``:
        data columns (``temperature``) or inputs derived from the table (``direction_q2``)."""
        return ()

    def reference(self, extras: dict) -> dict:
        """Constants fixed from the data when the effect is created (e.g. mean temperature)."""
        return {}

    def constants(self) -> tuple[float, ...]:
        """Numbers fixed from the data that ``delta`` reads through ``row.constants``.

        They reach compiled code as inputs, so code built for one dataset serves the next.
        """
        return ()

    # ----------------------------------------------------------------- the model

    @abstractmethod
    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, ca.SX | None]:
        """``(dq, dp)`` for one row; ``dp`` may be ``None`` for no geometric change."""

    def contribution(self, robot: Robot, theta, Q, extras: Mapping[str, Any] | None = None,
                     payload_com=None, p=None) -> Contribution:
        """``delta`` evaluated at N rows: readings ``Q`` (N x dof) [rad or m], ``extras``
        column -> N values (``payload`` 0 and directions 0 where absent), ``payload_com``
        (3,) [m] flange frame, geometry ``p`` (default ``robot``'s), ``theta`` (SI).

        The CasADi function is built once per effect and robot and kept.
        """
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        n = len(Q)
        extras = dict(extras or {})
        columns = tuple(sorted(set(self.required_columns()) | {"payload"}))
        cache = self.__dict__.setdefault("_contribution_functions", {})
        key = (robot, columns)
        if key not in cache:
            registry = robot.parameters()
            q = ca.SX.sym("q", robot.dof)
            e = ca.SX.sym("extras", len(columns))
            p_sym = ca.SX.sym("p", len(registry))
            t = ca.SX.sym("theta", len(self.parameter_names()))
            com_sym = ca.SX.sym("payload_com", 3)
            row = RowContext(robot, registry, q, p_sym, {c: e[i] for i, c in enumerate(columns)},
                             com_sym)
            dq, dp = self.delta(row, t)
            dp = ca.SX.zeros(len(registry)) if dp is None else dp
            cache[key] = ca.Function(f"{self.name}_contribution", [q, e, p_sym, t, com_sym],
                                     [dq, dp])
        function = cache[key]
        values = []
        for c in columns:
            if c in extras:
                values.append(np.broadcast_to(np.asarray(extras[c], dtype=float), (n,)))
            elif c == "payload" or c.startswith(("direction_", "travel_")):
                values.append(np.zeros(n))
            else:
                raise InputError(f"{self.name} needs a {c!r} column", where=c)
        E = np.array(values).reshape(len(columns), n)
        p = robot.parameter_vector() if p is None else np.asarray(p, dtype=float)
        com = np.zeros(3) if payload_com is None else np.asarray(payload_com, dtype=float)
        mapped = function.map(n) if n > 1 else function
        dq_values, dp_values = mapped(
            Q.T, E, np.tile(p[:, None], (1, n)),
            np.tile(np.asarray(theta, dtype=float).reshape(-1, 1), (1, n)),
            np.tile(com.reshape(3, 1), (1, n)))
        return Contribution(np.asarray(dq_values).T.reshape(n, robot.dof),
                            np.asarray(dp_values).T.reshape(n, -1))

    # ----------------------------------------------------------------- words and plots

    def describe(self, values: Mapping[str, float], units: Units) -> str:
        """One sentence of what the fitted ``values`` (name -> SI) say, in ``units``."""
        parts = ", ".join(f"{k} = {v:.3g}" for k, v in values.items())
        return self.sentence.format(joints=joint_list(self.joints), values=parts,
                                    unit=self.unit)

    def plot_values(self, robot: Robot, joint: int, Q, extras: Mapping[str, Any],
                    payload_com=None) -> np.ndarray:
        """The variable the error at ``joint`` (1-based) is plotted against, per row [SI].

        ``joint``: the joint angle; ``driver``: the driving joint's angle; ``direction``:
        the joint's direction of motion (-1, 0, +1); ``torque`` and ``column`` are
        computed by the subclass.
        """
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if self.plot_variable == "joint":
            return Q[:, joint - 1]
        raise NotImplementedError(f"{self.name}: plot variable {self.plot_variable!r}")

    @classmethod
    def view_caption(cls, torque: bool) -> tuple[str, str] | None:
        """The report's words for a joint panel: against what the error is plotted and
        what the fitted curve shows (``torque``: plotted against the gravity torque); None
        for the generic words built from ``plot_variable`` and ``formula``."""
        return None

    @classmethod
    def column_of(cls, parameters: Collection[str]) -> str | None:
        """The data column fitted ``parameters`` were fitted against, None for none."""
        return None

    @classmethod
    def column_label(cls, column: str) -> str | None:
        """A plot axis label of data column ``column`` with its unit, None for none."""
        return None

    # ----------------------------------------------------------------- diagnosis

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[Effect, ...]:
        """The units diagnosis tests one at a time: by default one effect per joint
        (revolute joints only where ``revolute_only``) whose drive is one of ``drives``."""
        return tuple(cls.create((j,), robot, extras) for j in range(1, robot.dof + 1)
                     if (robot.joints[j - 1].revolute or not cls.revolute_only)
                     and robot.drive(j) in cls.drives)

    def sampled_well(self, Q: np.ndarray) -> bool:
        """Whether joint readings ``Q`` (N x dof) [rad or m] sample the joints densely
        enough for this candidate to be told from others (all do by default)."""
        return True

    @classmethod
    def merged(cls, units: Sequence[Effect], robot: Robot,
               extras: Mapping[str, Any]) -> Effect:
        """One effect holding the parameters of several ``candidates`` units."""
        joints = tuple(sorted({j for unit in units for j in unit.joints}))
        return cls.create(joints, robot, extras)

    @classmethod
    def create(cls, joints, robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> Effect:
        """The effect on ``joints`` (1-based) set up for ``robot`` and the fit data."""
        return cls(tuple(joints), **options)

    # ----------------------------------------------------------------- simulation

    def simulated_dq(self, world: TrueWorld, Q, extras: Mapping[str, np.ndarray],
                     values: Mapping[str, float]) -> np.ndarray:
        """The true ``dq`` (N x dof) [rad or m] at readings ``Q`` (N x dof) in numpy, for
        the simulator; ``extras`` column -> N values; ``values`` name -> true value (SI).

        Written from the definition, not from ``delta``, so that a calibration that
        recovers the simulated truth checks ``delta``.
        """
        return np.zeros(np.atleast_2d(Q).shape)

    def simulated_shift(self, world: TrueWorld, Q, extras: Mapping[str, np.ndarray],
                        values: Mapping[str, float]) -> np.ndarray:
        """The true shift (N x 3) [m], world frame, of the whole arm at true joints ``Q``
        (N x dof), for the simulator; zero unless the effect moves points directly (link
        deflection). The estimator's ``delta`` writes it as ``dp`` on ``base_x..z``."""
        return np.zeros((len(np.atleast_2d(Q)), 3))

    def simulated_dp(self, world: TrueWorld, p: np.ndarray,
                     extras: Mapping[str, float | None],
                     values: Mapping[str, float]) -> np.ndarray | None:
        """The true ``dp`` [SI] at geometry ``p`` for one row's ``extras``, or None."""
        return None

    @classmethod
    def simulation_key(cls, text: str, robot: Robot, where: str = "effects"):
        """One simulated entry's key from text: a joint number (``per`` joint), checked
        against ``robot``; ``JointCoupling`` reads ``J@K``."""
        try:
            joint = int(str(text).strip())
        except ValueError:
            raise InputError(f"expected a joint number, got {text!r}", where=where) from None
        cls._check_simulated_joint(joint, robot, where)
        return joint

    @classmethod
    def _check_simulated_joint(cls, joint: int, robot: Robot, where: str) -> None:
        if not 1 <= joint <= robot.dof:
            raise InputError(f"joint {joint} out of range 1..{robot.dof}", where=where)
        if cls.revolute_only and not robot.joints[joint - 1].revolute:
            raise InputError(f"joint {joint} is prismatic; {cls.name} needs a revolute joint",
                             where=where)

    @classmethod
    def for_simulation(cls, keys: Sequence) -> Effect:
        """The effect holding the simulated entries ``keys`` (see ``simulation_key``)."""
        return cls(tuple(int(k) for k in keys))

    @classmethod
    def accepts_simulation_values(cls, count: int) -> bool:
        """Whether one simulated entry may give ``count`` values (``simulation_default``'s
        number, unless the effect takes more)."""
        return count == len(cls.simulation_default)

    @classmethod
    def for_simulated_values(cls, keys: Sequence, widths: Sequence[int]) -> Effect:
        """The effect holding the simulated entries ``keys`` with ``widths`` values each
        (``for_simulation`` unless the number of values changes the effect)."""
        return cls.for_simulation(keys)

    @classmethod
    def simulation_syntax(cls) -> str:
        """How ``robocal simulate --effect`` names this effect, for the help text."""
        # placeholder joints 8 (J) and 9 (K) name the parameters the way a user writes them
        unit = cls.for_simulation((8,) if cls.per == "joint" else ((8, 9),) if cls.per == "pair"
                                  else ())
        names = "/".join(unit.parameter_names()).replace("8", "J").replace("9", "K")
        default = "/".join(f"{v:g}" for v in cls.simulation_default)
        key = {"joint": "J", "pair": "J@K", "column": ""}[cls.per]
        spec = f"{cls.name}:{key}[={names}]" if key else f"{cls.name}[:{names}]"
        return f"{spec}  [{unit.unit}]  (default {default})\n      {cls.formula}"

    def check_simulation(self, robot: Robot, values: Mapping[str, float]) -> None:
        """Refuse simulated values the effect cannot have (a wrong sign) or a robot it cannot
        act on; ``InputError`` naming the effect."""
        for parameter, value in values.items():
            sign = self.plausible_on(parameter, robot).sign
            if sign and value * sign < 0:
                raise InputError(f"{parameter} must not be {'negative' if sign > 0 else 'positive'}"
                                 f", got {value:g}", where=f"effects.{self.name}")

    def simulation_values(self, entries: Sequence[float] | None = None) -> dict[str, float]:
        """Name -> true value for a one-unit effect, ``simulation_default`` when None."""
        entries = self.simulation_default if entries is None else tuple(entries)
        names = self.parameter_names()
        if len(entries) != len(names):
            raise InputError(f"{self.name}: expected {len(names)} value(s) "
                             f"({', '.join(names)}), got {len(entries)}", where="effects")
        return {n: float(v) for n, v in zip(names, entries)}


def joint_list(joints: Sequence[int]) -> str:
    """``joint 2`` or ``joints 2, 3 and 5``."""
    joints = list(joints)
    if not joints:
        return "the arm"
    if len(joints) == 1:
        return f"joint {joints[0]}"
    return "joints " + ", ".join(str(j) for j in joints[:-1]) + f" and {joints[-1]}"
