"""The identified effects applied: tool poses a calibrated robot really reaches.

A calibration whose recommended model carries effects (joint compliance, periodic joint
errors, gear-ratio errors, thermal drift, ...) only delivers its reported accuracy when
forward kinematics and compensation apply them too. ``effects_calibrated.yaml`` in the
result folder holds them (SI values by parameter name, and what each needs to be rebuilt:
a thermal reference, whether compliance saw a payload); ``EffectModel`` evaluates

    T_world_tool = FK(q + dq(q, extras), p + dp(q, extras))          [m]

with the effects' own corrections (``effects.base``), the calibrated geometry ``p`` and a
row's ``extras``: ``payload`` [kg] (a column, or one value for all rows), ``temperature``
[C] or ``time`` [s] as the effects need. The payload is a point mass at ``payload_com``
[m] in the flange frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import casadi as ca
import numpy as np

from ..common.fields import load_yaml
from ..errors import InputError
from ..model.kinematics import Kinematics
from ..model.robot import Robot, dump_yaml
from ..results import Delivered
from . import EFFECTS, LEARNED, Effect, RowContext
from .motion import is_derived_column, with_directions

EFFECTS_FILE = "effects_calibrated.yaml"


def effects_to_dict(result) -> dict | None:
    """The recommended model's effects of a ``CalibrationResult`` as the mapping
    ``effects_calibrated.yaml`` holds, or None when it has none."""
    if result.recommended != "final" or not result.effect_models:
        return None
    values = np.asarray(result.effect_values, dtype=float)
    entries, start = [], 0
    columns = {c for r in result.residuals for c in r.extras}
    for effect in result.effect_models:
        names = effect.parameter_names()
        own = values[start:start + len(names)]
        entries.append(effect.to_dict(dict(zip(names, own)), columns))
        start += len(names)
    com = next((r.payload_com for r in result.residuals if r.payload_com is not None), None)
    # The geometry fitted together with the effects belongs with them: robot_calibrated.yaml
    # may hold another (the best geometry-only model, ``delivery``).
    geometry = {p.name: float(p.estimate) for p in result.parameters}
    return {"units": {"length": "m", "angle": "rad"}, "effects": entries,
            "payload_com": [0.0, 0.0, 0.0] if com is None else [float(v) for v in com],
            "geometry": geometry}


def save_effects(result, folder: Path) -> bool:
    """Write ``effects_calibrated.yaml`` into ``folder`` when the recommended model has
    effects; True when written."""
    content = effects_to_dict(result)
    if content is None:
        return False
    (folder / EFFECTS_FILE).write_text(dump_yaml(content))
    return True


@dataclass(frozen=True)
class EffectModel:
    """A calibrated ``robot`` with its ``effects`` and their ``values`` (SI, in the
    effects' parameter order); ``payload_com`` [m] in the flange frame; ``payload``
    whether compliance was identified with a payload in the data."""

    robot: Robot
    effects: tuple[Effect, ...]
    values: np.ndarray = field(repr=False)
    payload_com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    payload: bool = False

    def columns(self) -> tuple[str, ...]:
        """The per-row values the effects read (``payload``, ``temperature``, ``time``)."""
        names: list[str] = []
        for effect in self.effects:
            needed = list(effect.required_columns())
            if effect.reads_payload():
                needed.append("payload")
            names += [n for n in needed if n not in names]
        return tuple(names)

    @cached_property
    def _pose(self) -> ca.Function:
        kinematics = Kinematics(self.robot)
        q = ca.SX.sym("q", self.robot.dof)
        columns = self.columns()
        extras = ca.SX.sym("extras", len(columns))
        p = ca.DM(kinematics.nominal)
        row = RowContext(self.robot, kinematics.registry, q, ca.SX(p),
                         {c: extras[i] for i, c in enumerate(columns)},
                         ca.SX(ca.DM(list(self.payload_com))))
        dq, dp = ca.SX.zeros(self.robot.dof), ca.SX.zeros(len(kinematics.registry))
        start = 0
        for effect in self.effects:
            size = len(effect.parameter_names())
            delta_q, delta_p = effect.delta(row, ca.SX(ca.DM(self.values[start:start + size])))
            dq += delta_q
            if delta_p is not None:
                dp += delta_p
            start += size
        pose = kinematics.tool_pose(q + dq, ca.SX(p) + dp)
        return ca.Function("tool_pose_with_effects", [q, extras], [pose])

    def tool_poses(self, Q: np.ndarray, extras: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """World tool poses (N x 4 x 4) [m] at readings ``Q`` (N x dof) with the effects;
        ``extras`` one array (or number) per name in ``columns()``; the directions of
        motion (backlash) follow from the order of the rows where not given."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        extras = dict(extras or {})
        if any(is_derived_column(c) for c in self.columns()):
            extras = with_directions(Q, extras, self.robot)
        missing = [c for c in self.columns() if c not in extras]
        if missing:
            raise InputError(f"the effects need {', '.join(missing)} for every row")
        E = np.column_stack([np.broadcast_to(np.asarray(extras[c], dtype=float), (len(Q),))
                             for c in self.columns()]) if self.columns() else np.zeros((len(Q), 0))
        mapped = self._pose.map(len(Q)) if len(Q) > 1 else self._pose
        out = np.asarray(mapped(Q.T, E.T))
        return out.reshape(4, len(Q), 4).transpose(1, 0, 2)


def load_effects(folder: Path, robot: Robot) -> EffectModel:
    """The ``EffectModel`` of a result folder for its calibrated ``robot``; a folder
    without effects gives a model with none."""
    path = Path(folder) / EFFECTS_FILE
    if not path.is_file():
        return EffectModel(robot, (), np.zeros(0))
    content = load_yaml(path, what="effects file")
    robot = _with_geometry(robot, content.get("geometry"), path)
    effects, values = [], []
    for k, entry in enumerate(content.get("effects") or []):
        effect, parameters = _read_entry(entry, robot, path, f"effects[{k}]")
        effects.append(effect)
        values += [parameters[n] for n in effect.parameter_names()]
    x, y, z = (float(v) for v in content.get("payload_com", (0.0, 0.0, 0.0)))
    return EffectModel(robot, tuple(effects), np.array(values, dtype=float), (x, y, z),
                       any(effect.has_payload_term() for effect in effects))


def _read_entry(entry, robot: Robot, path: Path, where: str) -> tuple[Effect, dict[str, float]]:
    """One effect of an effects file and its values (name -> SI), rebuilt by its class."""
    try:
        name, joints = entry["name"], tuple(int(j) for j in entry["joints"])
        parameters = {str(n): float(v) for n, v in entry["parameters"].items()}
    except (KeyError, TypeError, ValueError, AttributeError):
        raise InputError("expected {name, joints, parameters}", file=path, where=where) from None
    known = {**EFFECTS, **LEARNED}
    if name not in known:
        raise InputError(f"unknown effect {name!r}; known: {', '.join(known)}", file=path,
                         where=where)
    try:
        effect = known[name].from_dict(entry, robot)
    except InputError as error:  # the class names what is wrong; the file and entry are ours
        raise InputError(error.what, file=path, where=where) from None
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{name}: malformed entry ({error})", file=path, where=where) from None
    names = effect.parameter_names()
    if set(names) != set(parameters):
        raise InputError(f"{name} on joints {list(joints)} has parameters {list(names)} for "
                         f"this robot, the file gives {sorted(parameters)}", file=path,
                         where=where)
    return effect, parameters


def _with_geometry(robot: Robot, geometry, path: Path) -> Robot:
    """``robot`` with the geometry an effects file carries (SI by parameter name); files
    written before the geometry was kept there use the robot file's."""
    if geometry is None:
        return robot
    registry = robot.parameters()
    if not isinstance(geometry, dict) or set(geometry) != set(registry.names):
        raise InputError(f"geometry: expected a value for each of the robot's "
                         f"{len(registry.names)} parameters", file=path, where="geometry")
    try:
        vector = np.array([float(geometry[name]) for name in registry.names])
    except (TypeError, ValueError):
        raise InputError("geometry: expected numbers", file=path, where="geometry") from None
    if not np.all(np.isfinite(vector)):
        raise InputError("geometry: expected finite numbers", file=path, where="geometry")
    return robot.with_parameters(vector)


def delivered_lines(delivered: Delivered, length_scale: float, unit: str, *,
                    kept: bool = False) -> list[str]:
    """Terminal lines: the accuracy each output delivers (``kept``: held-out readings were
    set aside as gross errors, and the validation figure is over the others)."""
    def label(role: str) -> str:
        return f"{role} RMS over the kept readings" if kept and role == "validation" else \
            f"{role} RMS"

    def text(block):
        return ", ".join(f"{label(role)} {value / length_scale:.4g} {unit}"
                         for role, value in block.items())

    model = delivered.model.replace("_", " ")
    lines = [f"delivered: robot_calibrated.yaml ({model} model, geometry only): "
             + text(delivered.robot_file)]
    if delivered.with_effects:
        lines.append(f"delivered: with {EFFECTS_FILE} (fk/compensate --with-effects): "
                     + text(delivered.with_effects))
    return lines


def row_values(model: EffectModel, table, *, payload: float | None = None,
               temperature: float | None = None) -> dict[str, np.ndarray]:
    """The per-row values ``model`` needs, from ``table``'s columns or the options:
    ``payload`` [kg] (zero when the calibration data carried none), ``temperature`` [C].
    A value needed and given nowhere is an ``InputError`` naming the column."""
    options = {"payload": payload, "temperature": temperature}
    out: dict[str, np.ndarray] = {}
    for name in model.columns():
        if is_derived_column(name) and not table.has(name):
            continue  # from the order of the rows (``EffectModel.tool_poses``)
        if table.has(name):
            if options.get(name) is not None:
                raise InputError(f"{name} is given both as a column and as --{name}",
                                 file=table.path, where="line 1")
            out[name] = np.asarray(table.numbers(name), dtype=float)
        elif (given := options.get(name)) is not None:
            out[name] = np.asarray(float(given))
        elif name == "payload" and not model.payload:
            out[name] = np.asarray(0.0)  # the calibration saw no payload either
        else:
            option = f" (or --{name})" if name in options else ""
            raise InputError(f"the identified effects need a {name!r} column{option}",
                             file=table.path, where="line 1")
        if not np.all(np.isfinite(out[name])):
            raise InputError(f"{name} must be finite numbers", file=table.path, where=name)
    return out
