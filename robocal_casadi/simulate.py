"""Synthetic datasets from a known truth, for tests, benchmarks and trying the toolkit.

``simulate(robot, kind, ...)`` builds a TRUE robot (the nominal robot plus chosen
geometric errors), mounts an instrument with its own small errors, places the artifact
or instrument in the room, optionally adds effects the DH model lacks, and writes a
complete dataset: ``robot.yaml`` (the nominal robot), ``dataset.yaml``, its table, and
``truth.yaml`` with everything that was true, all at once (nothing on failure).

The simulator is independent of the estimator: its only model is the forward
kinematics of the true robot (``Kinematics``), inverse kinematics of the true robot for
the set-ups where the robot has to reach something (``ik``), pinocchio's gravity torques
for compliance, and each registered effect's numpy truth (``Effect.simulated_dq`` and
``Effect.simulated_dp``, written from the definition, never the estimator's CasADi
``delta``).

Joint readings written are the READ values (what the controller reports); the
measurements come from the true robot at the true joint values

    q_true = q_read + sum of the effects' dq(q_read)

with, per joint j (1-based) named in an effect:

* ``joint_compliance``: ``dq_j = -c_j g_j(q_read)``, ``g`` the generalized gravity
  torque [Nm] (``pinocchio_model.gravity_torques``) of the true robot's links plus the
  row's ``payload`` [kg] at ``payload_com`` [m] (flange frame), ``c_j`` [rad/Nm] >= 0;
* ``joint_cyclic``: ``dq_j = a1 sin q_j + b1 cos q_j + a2 sin 2q_j + b2 cos 2q_j`` [rad];
* ``joint_scale``: ``dq_j = s_j q_j``;
* ``joint_coupling`` (joint j driven by joint k): ``dq_j = s sin q_k + c cos q_k`` [rad];
* ``backlash``: ``dq_j = -(b_j / 2) direction_j`` [rad], ``direction_j`` the sign of the
  change of joint j's reading from the previous row written (the last direction where it
  did not change, 0 on the first row);
* ``thermal_drift``: every DH length ``d_i``, ``a_i`` of the true robot becomes
  ``L (1 + k (T - T_ref))``, ``k`` [1/K], ``T`` the row's ``temperature`` [C], ``T_ref``
  the simulator's ``reference_temperature`` (written to the truth file).

Where the robot must reach a point (touches, laser poses), inverse kinematics of the
true robot gives ``q_true`` and the reading is found by solving the relation above for
``q_read`` (fixed-point iteration, to 1e-14 rad). With backlash the readings are then
found again in the order written, each row's direction from its own reading and the
previous row's (``TrueRobot.readings_in_order``).

``noise`` [m] is, per kind: tracker_points, the standard deviation of each measured
coordinate; cross_bar and artifact_touches, of each coordinate of the probe's seat in
its socket; sphere_laser, of the laser distance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .checks import choice, count, positive
from .datasets import KINDS, Dataset, load_dataset
from .effects import EFFECTS, Effect, TrueWorld
from .effects.motion import direction_column, is_direction_column
from .errors import InputError
from .ik import inverse_kinematics, random_joints
from .kinematics import Kinematics
from .output import atomic_directory, written_by_robocal
from .parameters import perturbed_stems
from .progress import Progress
from .robot import Robot, dump_yaml, load_robot, save_robot
from .table import write_table
from .transforms import (
    invert,
    matrix_from_quaternion,
    pose_from_xyz_rpy,
    quaternion_from_matrix,
    rot_z,
    rpy_from_matrix,
)
from .units import Units

TABLES = {"cross_bar": "touches.csv", "artifact_touches": "touches.csv",
          "sphere_laser": "scan.csv", "tracker_points": "points.csv"}
READINGS = ("joints", "pendant")
LIMIT_MARGIN = 0.03  # fraction of each joint range kept free at both ends for configurations
DEFAULT_PROBE = (0.0, 0.0, 0.15)  # [m] flange frame
DEFAULT_TARGET = (0.0, 0.0, 0.10)  # [m]
DEFAULT_LASER_ORIGIN = (0.06, -0.015, 0.14)  # [m]
DEFAULT_LASER_DIRECTION = (0.0, 0.0, 1.0)


# ----------------------------------------------------------------------------- the truth


@dataclass(frozen=True)
class TrueEffects:
    """Effects of the true robot: ``entries`` of (effect, true values by parameter name, SI),
    one per registered effect type, in the registry's order (see the module docstring)."""

    entries: tuple[tuple[Effect, Mapping[str, float]], ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(effect.name for effect, _ in self.entries)

    def get(self, name: str) -> tuple[Effect, Mapping[str, float]] | None:
        return next(((e, v) for e, v in self.entries if e.name == name), None)

    @property
    def any_joint_effect(self) -> bool:
        return any(effect.per != "column" for effect, _ in self.entries)

    @property
    def sequential(self) -> bool:
        """Whether an effect depends on the order of the readings (backlash)."""
        return any(is_direction_column(c) for effect, _ in self.entries
                   for c in effect.required_columns())

    def as_dict(self) -> dict:
        """The effect names of ``result.json`` with estimator-style parameter names (SI)."""
        out: dict[str, Any] = {}
        for effect, values in self.entries:
            entry: dict[str, Any] = {"joints": sorted(set(effect.joints)), "unit": effect.unit}
            if getattr(effect, "column", None):
                entry["column"] = effect.column  # type: ignore[attr-defined]
            if getattr(effect, "drivers", None):
                entry["drivers"] = {int(j): int(k) for j, k in effect.pairs}  # type: ignore
            entry["parameters"] = {n: float(values[n]) for n in effect.parameter_names()}
            out[effect.name] = entry
        return out




@dataclass(frozen=True)
class Truth:
    """Everything that was true when a dataset was simulated (SI inside).

    ``robot`` the true robot; ``nominal`` the robot written as ``robot.yaml``;
    ``parameter_errors`` true minus nominal by parameter name [m or rad], nonzero only;
    ``mounted`` the true instrument on the flange (``probe`` / ``target`` /
    ``laser_origin`` [m], ``laser_direction`` unit, flange frame); ``placement`` what
    sits in the room (``T_world_instrument`` 4x4, ``sphere_centre`` [m], or ``sockets``
    {pose: {socket: position [m]}}, world frame); ``noise`` [m] (see the module
    docstring); ``reference_temperature`` [C].
    """

    kind: str
    robot: Robot
    nominal: Robot
    parameter_errors: Mapping[str, float]
    mounted: Mapping[str, np.ndarray]
    placement: Mapping[str, Any]
    effects: TrueEffects
    noise: float
    seed: int
    reference_temperature: float

    def __repr__(self) -> str:
        effects = ", ".join(self.effects.as_dict()) or "none"
        return (f"Truth({self.kind}, robot={self.robot.name!r}, "
                f"{len(self.parameter_errors)} parameter errors, effects: {effects}, "
                f"noise={self.noise:g} m, seed={self.seed})")


@dataclass(frozen=True)
class SimulatedDataset:
    """Paths of the written files and the truth behind them."""

    dataset_path: Path
    robot_path: Path
    table_path: Path
    truth_path: Path
    truth: Truth
    rows: int
    joints: np.ndarray = field(repr=False)  # (N, dof) readings as written [rad or m]
    measured: Mapping[str, np.ndarray] = field(repr=False)  # 'x','y','z' | 'distance' [m]
    extras: Mapping[str, np.ndarray] = field(repr=False)  # 'temperature' [C], 'payload' [kg]
    pose: np.ndarray | None = field(repr=False, default=None)  # touches: placement ids
    point: tuple[str, ...] = field(repr=False, default=())  # touches: socket names
    pendant: np.ndarray | None = field(repr=False, default=None)  # (N, 7) x,y,z [m], quaternion

    def load(self, **options) -> Dataset:
        """The dataset as ``load_dataset`` reads it (``options`` passed on)."""
        return load_dataset(self.dataset_path, **options)

    def __repr__(self) -> str:
        return (f"SimulatedDataset({self.truth.kind}, rows={self.rows}, "
                f"dataset={str(self.dataset_path)!r})")


# ----------------------------------------------------------------------------- inputs


def true_parameters(robot: Robot, geometric_errors, rng: np.random.Generator
                    ) -> tuple[np.ndarray, dict[str, float]]:
    """The true geometric vector [SI] and the errors by name.

    ``geometric_errors``: None (none); ``(length_std [m], angle_std [rad])`` random on
    ``theta, d, a, alpha`` of every joint (and ``beta`` where the robot file has one);
    or ``{name: error [m or rad]}`` explicit by parameter name.
    """
    registry = robot.parameters()
    nominal = registry.vector_of(robot)
    errors = np.zeros(len(registry))
    if geometric_errors is None:
        pass
    elif isinstance(geometric_errors, Mapping):
        for name, value in geometric_errors.items():
            if name not in registry:
                raise InputError(f"unknown parameter {name!r}; valid names: "
                                 f"{', '.join(registry.names)}", where="geometric_errors")
            errors[registry.index(name)] = float(value)
    else:
        length_std, angle_std = (float(v) for v in geometric_errors)
        if length_std < 0 or angle_std < 0:
            raise InputError("standard deviations must not be negative",
                             where="geometric_errors")
        for i, joint in enumerate(robot.joints, start=1):
            for stem in perturbed_stems(robot, joint):
                std = length_std if registry.quantity(f"{stem}{i}") == "length" else angle_std
                errors[registry.index(f"{stem}{i}")] = rng.normal(0.0, std)
    named = {n: float(e) for n, e in zip(registry.names, errors) if e != 0.0}
    return nominal + errors, named


def _entry_values(spec, cls, where: str) -> tuple[float, ...]:
    width = len(cls.simulation_default)
    try:
        values = None if isinstance(spec, Mapping) else np.atleast_1d(np.asarray(spec,
                                                                              dtype=float))
    except (TypeError, ValueError):
        values = None
    if values is None or values.shape != (width,) or not np.all(np.isfinite(values)):
        raise InputError(f"expected {width} finite number(s), got {spec!r}", where=where)
    return tuple(float(v) for v in values)


def parse_effects(effects: Mapping | None, robot: Robot) -> TrueEffects:
    """The true effects from ``{name: spec}`` (SI), names from the effect registry.

    ``spec`` per joint effect: ``{joint: value(s)}`` with as many values as the effect's
    ``simulation_default`` (``joint_compliance`` ``{j: c}``, ``joint_cyclic``
    ``{j: (a1, b1, a2, b2)}``, ``joint_scale`` ``{j: s}``, ``backlash`` ``{j: b}``);
    ``joint_coupling`` ``{(j, k): (s, c)}`` or ``{"j@k": (s, c)}`` (joint j driven by k);
    ``thermal_drift`` a coefficient ``k`` [1/K] (or ``{"k_T": k}``).
    """
    entries = []
    for name, spec in dict(effects or {}).items():
        if name not in EFFECTS:
            raise InputError(f"unknown effect(s) [{name!r}]; expected some of "
                             f"{list(EFFECTS)}", where="effects")
        cls = EFFECTS[name]
        where = f"effects.{name}"
        if cls.per == "column":
            value = spec
            if isinstance(spec, Mapping):
                value = next(iter(spec.values()), None) if len(spec) == 1 else spec
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise InputError(f"expected a coefficient k [1/K], got {spec!r}",
                                 where=where) from None
            effect = cls.for_simulation(())
            values = effect.simulation_values((value,))
        else:
            if not isinstance(spec, Mapping):
                raise InputError(f"expected a mapping joint -> value, got {spec!r}", where=where)
            keys, values = [], {}
            for key, value in spec.items():
                key = cls.simulation_key(key, robot, where)
                unit = cls.for_simulation((key,))
                values.update(unit.simulation_values(_entry_values(value, cls, where)))
                keys.append(key)
            if not keys:
                continue
            effect = cls.for_simulation(keys)
        effect.check_simulation(robot, values)
        entries.append((effect, values))
    order = list(EFFECTS)
    entries.sort(key=lambda entry: order.index(entry[0].name))
    return TrueEffects(tuple(entries))


def directions_in_order(Q_read: np.ndarray) -> np.ndarray:
    """The simulator's directions of motion (N x dof) of readings in written order: the sign
    of each row's change from the row before, the previous direction where nothing
    changed, 0 at the start."""
    Q_read = np.atleast_2d(Q_read)
    out = np.zeros(Q_read.shape)
    for i in range(1, len(Q_read)):
        for j in range(Q_read.shape[1]):
            change = Q_read[i, j] - Q_read[i - 1, j]
            out[i, j] = out[i - 1, j] if change == 0 else math.copysign(1.0, change)
    return out


# ----------------------------------------------------------------------------- the true robot


class TrueRobot:
    """The true robot with its effects: readings -> true joints, and its kinematics."""

    def __init__(self, robot: Robot, effects: TrueEffects, reference_temperature: float,
                 payload_com: np.ndarray):
        self.robot = robot
        self.effects = effects
        self.reference_temperature = reference_temperature
        self.payload_com = payload_com
        self.kinematics = Kinematics(robot)
        self.world = TrueWorld(robot, np.asarray(payload_com, dtype=float),
                               float(reference_temperature))

    def parameters(self, temperature: float | None) -> np.ndarray:
        """True geometric vector [SI] at ``temperature`` [C] (thermal drift on d_i, a_i)."""
        p = self.kinematics.nominal.copy()
        row = {"temperature": temperature}
        change = np.zeros_like(p)
        for effect, values in self.effects.entries:
            dp = effect.simulated_dp(self.world, p, row, values)
            if dp is not None:
                change += dp
        return p + change

    def play(self) -> np.ndarray:
        """Per joint, how far the order of the readings may move them (backlash) [rad]."""
        out = np.zeros(self.robot.dof)
        for effect, values in self.effects.entries:
            if any(is_direction_column(c) for c in effect.required_columns()):
                for name, value in values.items():
                    out[effect.joints[effect.parameter_names().index(name)] - 1] += abs(value)
        return out

    def joint_delta(self, Q_read: np.ndarray, payload: np.ndarray,
                    directions: np.ndarray | None = None) -> np.ndarray:
        """``sum dq(q_read)`` (N x dof) [rad or m] of the joint effects; ``directions``
        (N x dof) of motion for backlash (0 where None)."""
        Q_read = np.atleast_2d(Q_read)
        directions = np.zeros(Q_read.shape) if directions is None else np.atleast_2d(directions)
        extras = {"payload": np.broadcast_to(np.asarray(payload, dtype=float), (len(Q_read),))}
        for j in range(1, self.robot.dof + 1):
            extras[direction_column(j)] = directions[:, j - 1]
        dq = np.zeros_like(Q_read)
        for effect, values in self.effects.entries:
            dq += effect.simulated_dq(self.world, Q_read, extras, values)
        return dq

    def true_joints(self, Q_read: np.ndarray, payload: np.ndarray) -> np.ndarray:
        """``q_true = q_read + dq(q_read)`` (N x dof), ``Q_read`` in the order written."""
        Q_read = np.atleast_2d(np.asarray(Q_read, dtype=float))
        return Q_read + self.joint_delta(Q_read, payload, directions_in_order(Q_read))

    def readings(self, q_true: np.ndarray, payload: float,
                 direction: np.ndarray | None = None) -> np.ndarray:
        """The reading ``q_read`` with ``q_true = q_read + dq(q_read)`` (fixed point) [rad or m],
        at the given ``direction`` of motion (0 where None)."""
        q_true = np.asarray(q_true, dtype=float)
        if not self.effects.any_joint_effect:
            return q_true.copy()
        q = q_true.copy()
        directions = None if direction is None else np.asarray(direction)[None]
        for _ in range(100):
            updated = q_true - self.joint_delta(q[None], np.array([payload]), directions)[0]
            if np.max(np.abs(updated - q)) < 1e-14:
                return updated
            q = updated
        raise InputError("the joint effects are too large to invert (fixed point does not "
                         "converge)", where="effects")

    def readings_in_order(self, Q_true: np.ndarray, payloads) -> np.ndarray:
        """The readings (N x dof) of true joints ``Q_true`` measured in this order: each
        row's direction of motion follows from its own reading and the previous one."""
        Q_true = np.atleast_2d(np.asarray(Q_true, dtype=float))
        out = np.zeros(Q_true.shape)
        last = np.zeros(self.robot.dof)
        for i, (q_true, payload) in enumerate(zip(Q_true, payloads)):
            direction = np.zeros(self.robot.dof)
            if i:
                change = np.sign(q_true - Q_true[i - 1])
                direction = np.where(change != 0, change, last)
            for _ in range(20):
                q = self.readings(q_true, float(payload), direction)
                found = direction
                if i:
                    change = np.sign(q - out[i - 1])
                    found = np.where(change != 0, change, last)
                if np.array_equal(found, direction):
                    break
                direction = found
            else:
                raise InputError(f"row {i + 1}: the joint moves less than its backlash, so its "
                                 "direction of motion has no consistent reading", where="effects")
            out[i], last = q, direction
        return out


    def flange_poses(self, Q_true: np.ndarray, temperatures: np.ndarray | None) -> np.ndarray:
        """True world flange poses (N x 4 x 4) [m]."""
        if temperatures is None:
            return self.kinematics.flange_poses(Q_true)
        return np.array([self.kinematics.flange_poses(q, self.parameters(t))[0]
                         for q, t in zip(Q_true, temperatures)])


# ----------------------------------------------------------------------------- simulate


def simulate(robot: Robot | str | Path, kind: str, *, out_dir: str | Path, rows: int = 100,
             noise: float = 0.0, geometric_errors=None, effects: Mapping | None = None,
             seed: int = 0, units: Units | None = None, mounted_error: float | None = None,
             payload=None, payload_com=None, temperature: tuple[float, float] | None = None,
             reference_temperature: float = 20.0, readings: str = "joints",
             bar_length: float = 0.4, socket_distance: float = 0.05, sockets: int = 2,
             touches: int = 5, sphere_radius: float = 0.025, progress: bool = True,
             force: bool = False
             ) -> SimulatedDataset:
    """Write a simulated dataset of ``kind`` into ``out_dir``; return its paths and truth.

    ``robot``: the nominal robot (a ``Robot`` or a robot file). ``rows``: readings for
    tracker_points and sphere_laser; placements (of the bar or artifact) for cross_bar and
    artifact_touches. ``noise`` [m] (module docstring). ``geometric_errors``: see
    ``true_parameters`` (None, ``(length_std [m], angle_std [rad])`` or ``{name: error}``).
    ``effects``: see ``parse_effects`` (SI). ``seed``: everything random follows from it.
    ``units``: of the dataset file and table (default the robot file's). ``mounted_error``
    [m]: std of the instrument's true offset from the dataset's nominal value (default the
    length std of random geometric errors, else 0; the laser direction tilts by the angle
    std). ``payload`` [kg]: None (no column), a constant, or ``(low, high)`` uniform per
    row; ``payload_com`` [m] flange frame. ``temperature`` ``(start, end)`` [C]: a drifting
    ``temperature`` column (default ``T_ref - 2`` to ``T_ref + 6`` with thermal drift, else
    no column). ``readings``: sphere_laser writes ``joints`` or ``pendant`` poses (the
    controller's nominal flange pose at the readings, world frame). ``bar_length``,
    ``socket_distance`` [m], ``sockets``, ``touches`` (per socket and placement) and
    ``sphere_radius`` [m] shape the artifacts. ``out_dir`` is replaced as a whole: a
    non-empty folder that is no earlier output is refused unless ``force``.
    """
    kind = choice(kind, KINDS, "kind")
    readings = choice(readings, READINGS, "readings")
    rows = count(rows, "rows")
    noise = positive(noise, "noise", allow_zero=True)
    sockets = count(sockets, "sockets", minimum=2)
    touches = count(touches, "touches")
    nominal = load_robot(robot) if isinstance(robot, (str, Path)) else robot
    units = units or nominal.units
    out_dir = Path(out_dir)
    if not force:
        _check_out_dir(out_dir)
    rng = np.random.default_rng(seed)

    p_true, errors = true_parameters(nominal, geometric_errors, rng)
    true_robot = nominal.with_parameters(p_true)
    length_std, angle_std = 0.0, 0.0
    if geometric_errors is not None and not isinstance(geometric_errors, Mapping):
        length_std, angle_std = (float(v) for v in geometric_errors)
    if mounted_error is None:
        mounted_error = length_std
    true_effects = parse_effects(effects, nominal)
    com = np.zeros(3) if payload_com is None else np.asarray(payload_com, dtype=float)
    world = TrueRobot(true_robot, true_effects, reference_temperature, com)
    if temperature is None and true_effects.get("thermal_drift") is not None:
        temperature = (reference_temperature - 2.0, reference_temperature + 6.0)

    setup = _Setup(kind=kind, nominal=nominal, world=world, rng=rng, rows=int(rows),
                   noise=float(noise), mounted_error=float(mounted_error), angle_std=angle_std,
                   payload=payload, temperature=temperature, readings=readings,
                   bar_length=bar_length, socket_distance=socket_distance, sockets=int(sockets),
                   touches=int(touches), sphere_radius=sphere_radius, progress=progress)
    generated = {"tracker_points": _tracker_points, "cross_bar": _touches,
                 "artifact_touches": _touches, "sphere_laser": _sphere_laser}[kind](setup)

    truth = Truth(kind=kind, robot=true_robot, nominal=nominal, parameter_errors=errors,
                  mounted=generated.mounted, placement=generated.placement,
                  effects=true_effects, noise=float(noise), seed=int(seed),
                  reference_temperature=float(reference_temperature))
    table_name = TABLES[kind]
    with atomic_directory(out_dir) as staging:
        save_robot(nominal, staging / "robot.yaml")
        dataset = dict(kind=kind, robot="robot.yaml", units=units.as_dict(),
                       **generated.dataset_fields(units), data=table_name)
        if payload is not None and payload_com is not None:
            dataset["payload_com"] = [float(v) / units.length_scale for v in com]
        (staging / "dataset.yaml").write_text(dump_yaml(dataset))
        columns, table = generated.table(nominal, units)
        write_table(staging / table_name, columns, table)
        (staging / "truth.yaml").write_text(dump_yaml(_truth_dict(truth, units, payload_com)))
    leading = generated.leading
    return SimulatedDataset(
        out_dir / "dataset.yaml", out_dir / "robot.yaml", out_dir / table_name,
        out_dir / "truth.yaml", truth, len(generated.Q_read), joints=generated.Q_read,
        measured=dict(generated.measured), extras=dict(generated.extras),
        pose=np.array(leading["pose"]) if "pose" in leading else None,
        point=tuple(leading.get("point", ())), pendant=generated.pendant)


def _check_out_dir(out_dir: Path) -> None:
    """Refuse to replace a folder that holds something other than a simulated dataset."""
    if out_dir.exists():
        if not out_dir.is_dir():
            raise InputError("exists and is not a folder", file=out_dir, where="--out")
        if any(out_dir.iterdir()) and not (out_dir / "truth.yaml").is_file() \
                and not written_by_robocal(out_dir):
            raise InputError("folder is not empty and holds no earlier simulation "
                             "(truth.yaml); choose a new folder", file=out_dir, where="--out")


@dataclass
class _Setup:
    kind: str
    nominal: Robot
    world: TrueRobot
    rng: np.random.Generator
    rows: int
    noise: float
    mounted_error: float
    angle_std: float
    payload: Any
    temperature: tuple[float, float] | None
    readings: str
    bar_length: float
    socket_distance: float
    sockets: int
    touches: int
    sphere_radius: float
    progress: bool

    def payload_value(self) -> float:
        if self.payload is None:
            return 0.0
        if np.ndim(self.payload) == 0:
            return float(self.payload)
        low, high = self.payload
        return float(self.rng.uniform(low, high))

    def temperature_at(self, fraction: float) -> float | None:
        """A slowly drifting temperature [C] at ``fraction`` of the run, with 0.05 C jitter."""
        if self.temperature is None:
            return None
        start, end = self.temperature
        return float(start + (end - start) * fraction + self.rng.normal(0.0, 0.05))

    def mounted(self, nominal) -> np.ndarray:
        return np.asarray(nominal, dtype=float) + self.rng.normal(0.0, self.mounted_error, 3)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint limits shrunk by 1e-6 of the range: readings after effects stay inside."""
        lower, upper = self.nominal.lower_limits, self.nominal.upper_limits
        inset = np.where(np.isfinite(upper - lower), 1e-6 * (upper - lower), 0.0)
        inset = inset + self.world.play()  # readings move by up to the play with the order
        return lower + inset, upper - inset

    def in_order(self, Q_read: list, Q_true: list, payloads: list) -> np.ndarray:
        """The readings of the rows in written order: as found row by row, or, with an
        effect of the order of motion (backlash), found again in that order from the true
        joints (the direction of each row follows from its reading and the previous one)."""
        if not self.world.effects.sequential:
            return np.array(Q_read)
        out = self.world.readings_in_order(np.array(Q_true), payloads)
        outside = [i for i, q in enumerate(out) if not self.within_limits(q)]
        if outside:
            raise InputError(f"with backlash, row {outside[0] + 1}'s reading leaves the joint "
                             "limits; use a smaller backlash", where="effects.backlash")
        return out

    def within_limits(self, q: np.ndarray) -> bool:
        robot = self.nominal
        return bool(np.all(q >= robot.lower_limits) and np.all(q <= robot.upper_limits))


@dataclass
class _Generated:
    """What a kind produced: readings, extra columns, measured columns, truth parts."""

    Q_read: np.ndarray
    extras: dict[str, np.ndarray]
    mounted: dict[str, np.ndarray]
    placement: dict[str, Any]
    fields: Callable[[Units], dict]  # dataset-file entries in the given units
    measured: dict[str, np.ndarray] = field(default_factory=dict)  # column -> values [m] or text
    leading: dict[str, Any] = field(default_factory=dict)  # columns before the joints
    pendant: np.ndarray | None = None  # (N, 7) x, y, z [m], qw, qx, qy, qz

    def dataset_fields(self, units: Units) -> dict:
        """The dataset file's instrument entries in ``units``."""
        return self.fields(units)

    def table(self, robot: Robot, units: Units) -> tuple[list[str], list[list]]:
        columns: list[str] = list(self.leading)
        data: list[np.ndarray | list] = [self.leading[c] for c in self.leading]
        if self.pendant is not None:
            columns += ["x", "y", "z", "qw", "qx", "qy", "qz"]
            data += [self.pendant[:, k] / units.length_scale for k in range(3)]
            data += [self.pendant[:, k] for k in range(3, 7)]
        else:
            scales = np.array([units.angle_scale if j.revolute else units.length_scale
                               for j in robot.joints])
            columns += [f"q{i}" for i in range(1, robot.dof + 1)]
            data += [self.Q_read[:, i] / scales[i] for i in range(robot.dof)]
        for name, values in self.measured.items():
            columns.append(name)
            data.append(np.asarray(values) / units.length_scale)
        for name, values in self.extras.items():
            columns.append(name)
            data.append(values)
        rows = [[column[i] for column in data] for i in range(len(self.Q_read))]
        return columns, rows


def _in(units: Units, xyz) -> list[float]:
    """A position [m] as a list in ``units``."""
    return [float(v) / units.length_scale for v in xyz]


def _extras(payloads: list[float], temperatures: list, setup: _Setup) -> dict[str, np.ndarray]:
    extras = {}
    if setup.temperature is not None:
        extras["temperature"] = np.array(temperatures, dtype=float)
    if setup.payload is not None:
        extras["payload"] = np.array(payloads, dtype=float)
    return extras


# ----------------------------------------------------------------------------- tracker_points


def _tracker_points(setup: _Setup) -> _Generated:
    rng, world = setup.rng, setup.world
    target = setup.mounted(DEFAULT_TARGET)
    yaw = rng.uniform(-math.pi, math.pi)
    direction = rng.uniform(-math.pi, math.pi)
    T_world_instrument = pose_from_xyz_rpy(
        [2.5 * math.cos(direction), 2.5 * math.sin(direction), rng.uniform(0.0, 0.5)],
        [rng.normal(0.0, 0.05), rng.normal(0.0, 0.05), yaw])
    Q_read = random_joints(setup.nominal, setup.rows, rng, margin=LIMIT_MARGIN)
    payloads = [setup.payload_value() for _ in range(setup.rows)]
    temperatures = [setup.temperature_at(i / max(setup.rows - 1, 1)) for i in range(setup.rows)]
    Q_true = world.true_joints(Q_read, np.array(payloads))
    poses = world.flange_poses(Q_true, None if setup.temperature is None else
                               np.array(temperatures))
    p_world = poses[:, :3, :3] @ target + poses[:, :3, 3]
    T_instrument_world = invert(T_world_instrument)
    measured = p_world @ T_instrument_world[:3, :3].T + T_instrument_world[:3, 3]
    measured = measured + rng.normal(0.0, setup.noise, measured.shape)
    return _Generated(
        Q_read=Q_read, extras=_extras(payloads, temperatures, setup),
        mounted={"target": target}, placement={"T_world_instrument": T_world_instrument},
        fields=lambda units: {"target": {"xyz": _in(units, DEFAULT_TARGET)},
                              "instrument": {"xyz": _in(units, T_world_instrument[:3, 3])}},
        measured={"x": measured[:, 0], "y": measured[:, 1], "z": measured[:, 2]})


# ----------------------------------------------------------------------------- touches


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random 3x3 rotation (from a random unit quaternion)."""
    q = rng.normal(size=4)
    return matrix_from_quaternion(q / np.linalg.norm(q))


def _tilt(rng: np.random.Generator, max_angle: float) -> np.ndarray:
    """A rotation by up to ``max_angle`` [rad] about a random axis (3x3)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0.0, max_angle)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _socket_layout(setup: _Setup) -> tuple[list[str], np.ndarray, list, list]:
    """Socket names, positions in the artifact frame [m], distances, perpendicularity."""
    if setup.kind == "cross_bar":
        h = setup.bar_length / 2
        local = np.array([[h, 0, 0], [0, h, 0], [-h, 0, 0], [0, -h, 0]])
        return ["A", "B", "C", "D"], local, [], []
    count = max(2, setup.sockets)
    names = [f"hole_{k}" for k in range(count)]
    local = np.array([[(k - (count - 1) / 2) * setup.socket_distance, 0.0, 0.0]
                      for k in range(count)])
    distances = [[names[i], names[j], float(np.linalg.norm(local[i] - local[j]))]
                 for i in range(count) for j in range(i + 1, count)]
    return names, local, distances, []


def _touches(setup: _Setup) -> _Generated:
    """cross_bar and artifact_touches: place the artifact, seat the probe in each socket."""
    rng, world, robot = setup.rng, setup.world, setup.nominal
    probe = setup.mounted(DEFAULT_PROBE)
    names, local, distances, _ = _socket_layout(setup)
    per_socket = 1 if setup.kind == "cross_bar" else max(1, setup.touches)
    ik = inverse_kinematics(world.kinematics, "point")
    bounds = setup.bounds()
    poses, points, Q_read, Q_true, payloads, temperatures = [], [], [], [], [], []
    sockets_truth: dict[int, dict[str, np.ndarray]] = {}
    attempts = 0
    with Progress(f"simulate {setup.kind}", total=setup.rows,
                  force=False) if setup.progress else _Quiet() as bar:
        while len(sockets_truth) < setup.rows:
            attempts += 1
            if attempts > 20 * setup.rows + 20:
                raise InputError(f"could place only {len(sockets_truth)} of {setup.rows} "
                                 "artifacts within reach; use a smaller artifact or fewer "
                                 "placements", where="rows")
            index = len(sockets_truth)
            temperature = setup.temperature_at(index / max(setup.rows - 1, 1))
            p_row = world.parameters(temperature)
            q0 = random_joints(robot, 1, rng, margin=0.15)[0]
            T0 = world.kinematics.flange_poses(q0, p_row)[0]
            centre = T0[:3, :3] @ probe + T0[:3, 3]
            if setup.kind == "cross_bar":
                R_artifact = _random_rotation(rng)
            else:  # a plate on a table: level, turned about the vertical, slightly tilted
                R_artifact = rot_z(rng.uniform(-math.pi, math.pi))[:3, :3] @ _tilt(rng, 0.1)
            positions = centre + local @ R_artifact.T
            placed = []
            for name, position in zip(names, positions):
                for touch in range(per_socket):
                    preferred = T0[:3, :3] if setup.kind == "cross_bar" or touch == 0 else (
                        _tilt(rng, 0.5) @ T0[:3, :3])
                    seat = position + rng.normal(0.0, setup.noise, 3)
                    payload = setup.payload_value()
                    result = ik.solve(seat, seed=q0, p=p_row, offset=probe, orientation=preferred,
                                      bounds=bounds, restarts=3, rng=rng,
                                      orientation_tolerance=1e-3)
                    if not result.success:
                        break
                    q_read = world.readings(result.q, payload)
                    if not setup.within_limits(q_read):
                        break
                    placed.append((name, q_read, payload, result.q))
                else:
                    continue
                break
            if len(placed) != len(names) * per_socket:
                continue  # out of reach: skip this placement
            for name, q_read, payload, q_true in placed:
                poses.append(index)
                points.append(name)
                Q_read.append(q_read)
                Q_true.append(q_true)
                payloads.append(payload)
                temperatures.append(temperature)
            sockets_truth[index] = dict(zip(names, positions))
            bar.update(len(sockets_truth))
    bar_length = float(setup.bar_length)
    Q_read_array = setup.in_order(Q_read, Q_true, payloads)

    def fields(units: Units) -> dict:
        out: dict[str, Any] = {"probe": {"xyz": _in(units, DEFAULT_PROBE)}}
        if setup.kind == "cross_bar":
            return {"bar": {"length": bar_length / units.length_scale}, **out}
        out["artifact"] = {"distances": [[a, b, d / units.length_scale] for a, b, d in distances]}
        return out

    return _Generated(
        Q_read=Q_read_array, extras=_extras(payloads, temperatures, setup),
        mounted={"probe": probe}, placement={"sockets": sockets_truth}, fields=fields,
        leading={"pose": poses, "point": points})


class _Quiet:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def update(self, *args, **kwargs):
        return None


# ----------------------------------------------------------------------------- sphere_laser


def ray_sphere_distance(origin, direction, centre, radius: float) -> float:
    """Distance [m] along the unit ``direction`` from ``origin`` to the first hit of the
    sphere (``centre`` [m], ``radius`` [m]); NaN when the ray misses or starts inside."""
    origin, direction, centre = (np.asarray(v, dtype=float) for v in (origin, direction, centre))
    m = origin - centre
    b = float(m @ direction)
    c = float(m @ m) - radius * radius
    discriminant = b * b - c
    if c <= 0.0 or discriminant < 0.0:
        return math.nan
    t = -b - math.sqrt(discriminant)
    return t if t > 0.0 else math.nan


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b`` (3x3)."""
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _sphere_laser(setup: _Setup) -> _Generated:
    rng, world, robot = setup.rng, setup.world, setup.nominal
    radius = float(setup.sphere_radius)
    origin = setup.mounted(DEFAULT_LASER_ORIGIN)
    direction = np.asarray(DEFAULT_LASER_DIRECTION) @ _tilt(rng, 2 * setup.angle_std).T
    direction = direction / np.linalg.norm(direction)
    ik = inverse_kinematics(world.kinematics, "flange_pose")
    bounds = setup.bounds()
    standoff = (0.08, 0.2)  # [m] laser distances

    # the sphere sits where the beam of a comfortable configuration points
    for _ in range(200):
        q0 = random_joints(robot, 1, rng, margin=0.2)[0]
        T0 = world.kinematics.flange_poses(q0, world.parameters(setup.temperature_at(0.0)))[0]
        beam0 = T0[:3, :3] @ direction
        if beam0[2] < -0.3:  # pointing down at something on a table
            break
    centre = T0[:3, :3] @ origin + T0[:3, 3] + (np.mean(standoff) + radius) * beam0

    Q_read: list[np.ndarray] = []
    Q_true: list[np.ndarray] = []
    payloads: list[float] = []
    temperatures: list[float | None] = []
    distances: list[float] = []
    attempts = 0
    with Progress("simulate sphere_laser", total=setup.rows) if setup.progress else _Quiet() as bar:
        while len(Q_read) < setup.rows:
            attempts += 1
            if attempts > 20 * setup.rows + 20:
                raise InputError(f"could reach only {len(Q_read)} of {setup.rows} laser poses",
                                 where="rows")
            temperature = setup.temperature_at(len(Q_read) / max(setup.rows - 1, 1))
            p_row = world.parameters(temperature)
            beam = _tilt(rng, 0.5) @ beam0  # tilted up to about 30 degrees
            lateral = rng.normal(size=3)
            lateral -= (lateral @ beam) * beam
            lateral *= rng.uniform(0.0, 0.7 * radius) / np.linalg.norm(lateral)
            aim = centre + lateral
            hit_from = aim - 2 * radius * beam
            to_surface = ray_sphere_distance(hit_from, beam, centre, radius)
            if not np.isfinite(to_surface):
                continue
            hit = hit_from + to_surface * beam
            laser_origin = hit - rng.uniform(*standoff) * beam
            R = _rotation_between(T0[:3, :3] @ direction, beam) @ T0[:3, :3]
            roll = rng.uniform(-0.5, 0.5)
            R = _axis_rotation(beam, roll) @ R
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = laser_origin - R @ origin
            payload = setup.payload_value()
            result = ik.solve(T, seed=q0, p=p_row, bounds=bounds, restarts=2, rng=rng)
            if not result.success:
                continue
            q_read = world.readings(result.q, payload)
            if not setup.within_limits(q_read):
                continue
            F = world.kinematics.flange_poses(result.q, p_row)[0]
            distance = ray_sphere_distance(F[:3, :3] @ origin + F[:3, 3], F[:3, :3] @ direction,
                                           centre, radius)
            if not np.isfinite(distance):
                continue
            Q_read.append(q_read)
            Q_true.append(result.q)
            payloads.append(payload)
            temperatures.append(temperature)
            distances.append(distance + rng.normal(0.0, setup.noise))
            bar.update(len(Q_read))
    Q_read_array = setup.in_order(Q_read, Q_true, payloads)
    pendant = None
    if setup.readings == "pendant":
        flanges = Kinematics(robot).flange_poses(Q_read_array)
        pendant = np.array([np.concatenate([F[:3, 3], quaternion_from_matrix(F[:3, :3])])
                            for F in flanges])
    centre_guess = centre + rng.normal(0.0, 0.005, 3)
    return _Generated(
        Q_read=Q_read_array, extras=_extras(payloads, temperatures, setup),
        mounted={"laser_origin": origin, "laser_direction": direction},
        placement={"sphere_centre": centre},
        fields=lambda units: {
            "sphere": {"radius": radius / units.length_scale,
                       "centre_guess": _in(units, centre_guess)},
            "laser": {"origin_guess": _in(units, DEFAULT_LASER_ORIGIN),
                      "direction_guess": [float(v) for v in DEFAULT_LASER_DIRECTION]}},
        measured={"distance": np.array(distances)}, pendant=pendant)


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


# ----------------------------------------------------------------------------- truth file


def _truth_dict(truth: Truth, units: Units, payload_com) -> dict:
    """``truth.yaml``: lengths and angles in ``units``; effects in SI (their own units)."""
    L, A = units.length_scale, units.angle_scale
    registry = truth.robot.parameters()
    true_vector = registry.vector_of(truth.robot)

    def value(name: str, v: float) -> float:
        return float(v) / units.scale(registry.quantity(name))

    def length3(v) -> list[float]:
        return [float(x) / L for x in v]

    placement: dict[str, Any] = {}
    for key, item in truth.placement.items():
        if key == "T_world_instrument":
            placement["instrument"] = {"xyz": length3(item[:3, 3]),
                                       "rpy": [float(a) / A for a in rpy_from_matrix(item[:3, :3])]}
        elif key == "sphere_centre":
            placement["sphere_centre"] = length3(item)
        elif key == "sockets":
            placement["sockets"] = {int(pose): {name: length3(xyz) for name, xyz in s.items()}
                                    for pose, s in item.items()}
    mounted = {key: (length3(v) if key != "laser_direction" else [float(x) for x in v])
               for key, v in truth.mounted.items()}
    content: dict[str, Any] = {
        "kind": truth.kind,
        "seed": truth.seed,
        "units": units.as_dict(),
        "noise": truth.noise / L,
        "reference_temperature": truth.reference_temperature,
        "robot": {n: value(n, v) for n, v in zip(registry.names, true_vector)},
        "parameter_errors": {n: value(n, v) for n, v in truth.parameter_errors.items()},
        "mounted": mounted,
        "placement": placement,
        "effects": truth.effects.as_dict(),
    }
    if payload_com is not None:
        content["payload_com"] = length3(payload_com)
    return content


__all__ = ["SimulatedDataset", "Truth", "TrueEffects", "TrueRobot", "simulate",
           "parse_effects", "true_parameters", "ray_sphere_distance"]
