"""The robot model: a DH chain with base, tool, limits and inertial data.

A ``Robot`` holds everything in SI (metres, radians, kilograms) and remembers the units
of the file it came from, so ``save_robot`` writes it back in those units.

The file format is docs/formats.md#robot-file; the conventions (which DH row a joint's
entry holds, how readings enter, the ``com`` frame) are docs/conventions.md. In one line:
``world_T_tool = base * T(0,1) ... T(n-1,n) * tool`` (docs/conventions.md#pose-chain).

A third convention, ``urdf``, holds a serial chain read from a URDF file
(``robocal_casadi.urdf``): joint i is its fixed placement ``origin_i = Trans(xyz_i)
Rz(yaw_i) Ry(pitch_i) Rx(roll_i)`` in the previous link's frame, followed by the motion
about (revolute) or along (prismatic) its unit ``axis`` by the reading q_i::

    T(i-1,i) = origin_i Motion(axis_i, q_i),   T_world_flange = base T(0,1) ... T(n-1,n) flange

where ``flange`` is the fixed placement of the chain's tip link in the last moving
link's frame (identity for DH robots).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..common import exact
from ..common.checks import path_argument
from ..common.fields import (
    MAX_LENGTH,
    check_keys,
    cut,
    load_yaml,
    mapping,
    number,
    quantities,
    quantity,
    require,
    vector,
)
from ..common.units import SI, Units, to_file_units, units_of
from ..errors import InputError
from .parameters import ParameterRegistry
from .transforms import pose_from_xyz_rpy
from .transmission import TransmissionGroup, transmission_from_dict, transmission_to_dict

JOINT_TYPES = ("revolute", "prismatic")
# How a joint's motor turns it (docs/formats.md#robot-file); the plausible sizes of the
# effects the DH model lacks depend on it (docs/methods.md#drives).
DRIVES = ("gear", "harmonic", "cycloid", "belt", "cable", "direct")
DEFAULT_DRIVE = "gear"
CONVENTIONS = ("dh", "mdh", "urdf")
JOINT_KEYS = {"type", "theta", "d", "a", "alpha", "beta", "limits", "mass", "com", "tolerance",
              "drive"}
ROBOT_KEYS = ("name", "convention", "units", "joints", "base", "tool", "gravity", "tolerance",
              "transmission")
JOINT_TOLERANCE_KEYS = {"theta": "angle", "d": "length", "a": "length", "alpha": "angle",
                        "beta": "angle"}
# Top-level ``tolerance:`` keys: a kind of parameter (``prior.DEFAULT_TOLERANCE``) each.
TOLERANCE_KEYS = {"length": ("dh_length", "length"), "angle": ("dh_angle", "angle"),
                  "base_xyz": ("base_xyz", "length"), "base_rpy": ("base_rpy", "angle"),
                  "tool_xyz": ("tool_xyz", "length"), "tool_rpy": ("tool_rpy", "angle"),
                  "instrument": ("instrument_length", "length"),
                  "direction": ("instrument_direction", "angle")}
URDF_JOINT_KEYS = {"name", "child", "type", "xyz", "rpy", "axis", "limits", "mass", "com",
                   "drive"}
URDF_ROBOT_KEYS = ROBOT_KEYS + ("flange", "urdf")
MAX_MASS = 1e5  # kg, a link heavier than this is a typo
MAX_GRAVITY = 1e3  # m/s^2
MAX_NAME = 200  # characters of a robot's name
# In a file that declares rad, a DH angle or rpy beyond a full turn, or a joint limit
# beyond two turns, is almost surely written in degrees (alpha: -90).
FULL_TURN = 2 * math.pi  # [rad]
MAX_LIMIT = 4 * math.pi  # [rad]
DEGREES_HINT = "the value looks like degrees in a file that declares rad"


@dataclass(frozen=True)
class Joint:
    """One row of the DH table, SI units: lengths [m], angles [rad], mass [kg]."""

    type: str
    theta: float
    d: float
    a: float
    alpha: float
    beta: float = 0.0
    limits: tuple[float, float] | None = None  # [rad] or [m] for prismatic joints
    mass: float | None = None
    com: tuple[float, float, float] | None = None  # [m], in the link's own frame
    has_beta: bool = False  # the file gave a beta; written back even when zero
    drive: str = DEFAULT_DRIVE  # one of DRIVES

    @property
    def revolute(self) -> bool:
        return self.type == "revolute"


@dataclass(frozen=True)
class Frame:
    """A fixed pose: ``xyz`` [m] and ``rpy`` [rad] with ``R = Rz(y) Ry(p) Rx(r)``."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        return pose_from_xyz_rpy(self.xyz, self.rpy)


@dataclass(frozen=True)
class UrdfJoint:
    """One moving joint of a URDF chain, SI: ``T(i-1,i) = origin Motion(axis, q)``.

    ``origin`` [m, rad] places the joint in the frame of the previous moving link (the
    base link for joint 1), with any fixed joints in between already composed into it;
    ``axis`` is a unit vector in the joint's own frame. ``name`` is the URDF joint's name
    and ``child`` the link it moves. ``mass`` [kg] and ``com`` [m] lump that link and the
    links fixed to it, in its frame (the tip link's frame for the last joint).
    """

    type: str
    origin: Frame
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    limits: tuple[float, float] | None = None  # [rad] or [m] for prismatic joints
    mass: float | None = None
    com: tuple[float, float, float] | None = None  # [m], in the link's own frame
    name: str = ""
    child: str = ""
    has_beta: bool = False  # a URDF joint has no Hayati beta
    drive: str = DEFAULT_DRIVE  # one of DRIVES

    @property
    def revolute(self) -> bool:
        return self.type == "revolute"


@dataclass(frozen=True)
class UrdfSource:
    """Where a ``urdf`` robot came from: the file (absolute path) and the chain's ends."""

    file: str
    base_link: str
    tip_link: str


@dataclass(frozen=True)
class Robot:
    """A serial robot, everything SI. ``units`` are the source file's units.

    ``convention`` ``dh`` or ``mdh``: ``joints`` are ``Joint`` rows of a DH table;
    ``urdf``: ``UrdfJoint`` placements, ``flange`` the tip link in the last moving link's
    frame and ``urdf`` the file they were read from.
    """

    name: str
    convention: str
    joints: tuple
    base: Frame = field(default_factory=Frame)
    tool: Frame = field(default_factory=Frame)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    units: Units = SI
    has_base: bool = False
    has_tool: bool = False
    has_gravity: bool = False
    # Prior tolerances [SI] by parameter name (``theta2``) or kind (``dh_length``), as the
    # file gave them; see ``prior``.
    tolerance: dict[str, float] = field(default_factory=dict, compare=False, hash=False)
    flange: Frame = field(default_factory=Frame)
    urdf: UrdfSource | None = field(default=None, compare=False)  # where, not what
    # Groups of joints driven together (differentials), ``transmission``; none by default.
    transmission: tuple[TransmissionGroup, ...] = ()

    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def lower_limits(self) -> np.ndarray:
        """Lower joint limits [rad or m]; -inf where none is given."""
        return np.array([j.limits[0] if j.limits else -np.inf for j in self.joints])

    @property
    def upper_limits(self) -> np.ndarray:
        """Upper joint limits [rad or m]; +inf where none is given."""
        return np.array([j.limits[1] if j.limits else np.inf for j in self.joints])

    @property
    def has_inertia(self) -> bool:
        """True when every joint carries ``mass`` and ``com``."""
        return all(j.mass is not None and j.com is not None for j in self.joints)

    def drive(self, joint: int) -> str:
        """The drive of joint ``joint`` (1-based): one of ``DRIVES``."""
        return str(getattr(self.joints[joint - 1], "drive", DEFAULT_DRIVE))

    def reach(self) -> float:
        """An upper bound [m] on how far the flange can be from the joint-1 frame: the sum
        over links of their length (``sqrt(a^2 + d^2)`` in DH, ``|xyz|`` in URDF), a
        prismatic joint at its farthest reading, plus the flange and tool offsets."""
        total = float(exact.norm(self.tool.xyz)) + float(exact.norm(self.flange.xyz))
        for joint in self.joints:
            travel = 0.0
            if not joint.revolute:
                lo, hi = joint.limits if joint.limits else (-MAX_LENGTH, MAX_LENGTH)
                travel = max(abs(lo), abs(hi))
            if isinstance(joint, UrdfJoint):
                total += float(exact.norm(joint.origin.xyz)) + travel
            else:
                d = joint.d if joint.revolute else max(abs(joint.d + lo), abs(joint.d + hi))
                total += float(np.hypot(joint.a, d))
        return total

    def reading_scales(self) -> np.ndarray:
        """SI per file unit of each joint reading (angle unit for revolute, length for
        prismatic)."""
        return np.array(
            [self.units.angle_scale if j.revolute else self.units.length_scale for j in self.joints]
        )

    def parameters(self) -> ParameterRegistry:
        """The parameter registry of this robot (see ``parameters.ParameterRegistry``)."""
        return ParameterRegistry.for_robot(self)

    def parameter_vector(self) -> np.ndarray:
        """The nominal geometric parameter vector in registry order, SI."""
        return self.parameters().vector_of(self)

    def with_parameters(self, values: np.ndarray) -> Robot:
        """A copy whose geometry is ``values`` (registry order, SI)."""
        return self.parameters().robot_from(self, np.asarray(values, dtype=float))

    def with_units(self, units: Units) -> Robot:
        return replace(self, units=units)


# ----------------------------------------------------------------------------- reading


def load_robot(path: str | Path, *, base_link: str | None = None,
               tip_link: str | None = None) -> Robot:
    """Read a robot file (docs/formats.md#robot-file) or a URDF file (``.urdf``, or text
    that starts with ``<``); errors name the file and the key. ``base_link`` and
    ``tip_link`` choose a URDF's chain (default: its root to its single leaf)."""
    path = path_argument(path, "path", what="a robot file path")
    from .urdf_description import is_urdf, read_description

    if is_urdf(path):
        return robot_from_dict(read_description(path, base_link=base_link, tip_link=tip_link),
                               file=path)
    if base_link is not None or tip_link is not None:
        raise InputError("base_link and tip_link choose the chain of a URDF robot; this "
                         "robot file is not URDF", file=path)
    content = load_yaml(path, what="robot file")
    return robot_from_dict(content, file=path)


def robot_from_dict(content: dict, *, file: str | Path | None = None) -> Robot:
    """Build a ``Robot`` from the parsed YAML mapping of a robot file.

    Unknown keys are refused (at the top level, in a joint, in ``base``/``tool``) with
    the list of allowed ones, so a misspelt key is never silently ignored. An optional
    key written with no value (``tool:``) counts as absent. A joint's ``mass`` and ``com``
    go together.
    """
    if content.get("convention") == "urdf":
        return _urdf_robot_from_dict(content, file=file)
    check_keys(content, ROBOT_KEYS, file=file, expected="a robot file")
    convention = require(content, "convention", file=file)
    if not isinstance(convention, str) or convention not in CONVENTIONS:
        raise InputError(
            f"unknown convention {cut(convention)}; expected one of {list(CONVENTIONS)}",
            file=file,
            where="convention",
        )
    units = units_of(content, file=file)
    raw_joints = require(content, "joints", file=file)
    if not isinstance(raw_joints, list) or not raw_joints:
        raise InputError(f"expected a non-empty list of joints, got {cut(raw_joints)}",
                         file=file, where="joints")
    joints = tuple(
        _joint_from_dict(raw, units, file=file, where=f"joints[{i}] (joint {i + 1})")
        for i, raw in enumerate(raw_joints)
    )
    base = _frame_from_dict(content.get("base"), units, file=file, where="base")
    tool = _frame_from_dict(content.get("tool"), units, file=file, where="tool")
    gravity = _gravity_from_dict(content.get("gravity"), file=file)
    tolerance = _tolerance_from_dict(content.get("tolerance"), units, file=file)
    for i, raw in enumerate(raw_joints, start=1):
        tolerance.update(_joint_tolerance(raw.get("tolerance"), i, units, file=file,
                                          where=f"joints[{i - 1}] (joint {i}).tolerance"))
    return Robot(
        name=_name_from_dict(content.get("name"), file=file),
        convention=convention,
        joints=joints,
        base=base,
        tool=tool,
        gravity=gravity,
        units=units,
        has_base=content.get("base") is not None,
        has_tool=content.get("tool") is not None,
        has_gravity=content.get("gravity") is not None,
        tolerance=tolerance,
        transmission=transmission_from_dict(content.get("transmission"), joints, file=file),
    )


def _gravity_from_dict(raw: Any, *, file) -> tuple[float, float, float]:
    """``gravity:`` [m/s^2] in the world frame (default ``(0, 0, -9.81)``)."""
    if raw is None:
        return (0.0, 0.0, -9.81)
    gx, gy, gz = vector(raw, 3, file=file, where="gravity")
    gravity = (float(gx), float(gy), float(gz))
    if max(abs(g) for g in gravity) > MAX_GRAVITY:
        raise InputError(f"gravity {list(gravity)} m/s^2 is implausibly large",
                         file=file, where="gravity")
    return gravity


def _name_from_dict(name: Any, *, file) -> str:
    """``name:`` (default the file's stem, else ``robot``), at most ``MAX_NAME`` long."""
    if name is None:
        return Path(file).stem if file else "robot"
    if isinstance(name, (list, dict, bool)):
        raise InputError(f"expected a name, got {cut(name)}", file=file, where="name")
    if len(str(name)) > MAX_NAME:
        raise InputError(f"a name of {len(str(name))} characters; at most {MAX_NAME} are "
                         "allowed", file=file, where="name")
    return str(name)


def _tolerance_value(raw: Any, scale: float, kind: str, unit: str, *, file, where: str) -> float:
    """A positive tolerance in SI from ``raw`` in the file's ``unit``."""
    value = quantity(raw, scale, kind, file=file, where=where, unit=unit)
    if not value > 0:
        raise InputError(f"a tolerance must be positive, got {raw!r} {unit}", file=file,
                         where=where)
    return value


def _tolerance_from_dict(raw: Any, units: Units, *, file) -> dict[str, float]:
    """The top-level ``tolerance:`` block: per kind of parameter, file units -> SI."""
    if raw is None:
        return {}
    mapping(raw, file=file, where="tolerance", hint="{length: 0.5, angle: 0.1, ...}")
    check_keys(raw, tuple(TOLERANCE_KEYS), file=file, where="tolerance")
    out = {}
    for key, value in raw.items():
        if value is None:
            continue
        target, kind = TOLERANCE_KEYS[key]
        scale, unit = units.scale(kind), units.unit_name(kind)
        out[target] = _tolerance_value(value, scale, kind, unit, file=file,
                                       where=f"tolerance.{key}")
    for frame in ("base", "tool"):
        for part, stems in (("xyz", ("x", "y", "z")), ("rpy", ("rx", "ry", "rz"))):
            if f"{frame}_{part}" in out:
                value = out.pop(f"{frame}_{part}")
                out.update({f"{frame}_{stem}": value for stem in stems})
    return out


def _joint_tolerance(raw: Any, joint: int, units: Units, *, file, where: str
                     ) -> dict[str, float]:
    """A joint's ``tolerance: {a: 0.5, theta: 0.1}``: by parameter name, file units -> SI."""
    if raw is None:
        return {}
    mapping(raw, file=file, where=where, hint="{theta: 0.1, d: 0.5, a: 0.5, alpha: 0.1}")
    check_keys(raw, tuple(JOINT_TOLERANCE_KEYS), file=file, where=where)
    out = {}
    for key, value in raw.items():
        if value is None:
            continue
        kind = JOINT_TOLERANCE_KEYS[key]
        out[f"{key}{joint}"] = _tolerance_value(value, units.scale(kind), kind,
                                                units.unit_name(kind), file=file,
                                                where=f"{where}.{key}")
    return out


def _joint_from_dict(raw: Any, units: Units, *, file, where: str,
                     urdf: bool = False) -> Joint:
    if not isinstance(raw, dict):
        raise InputError(f"expected a mapping {{type, theta, d, a, alpha, ...}}, got "
                         f"{cut(raw)}", file=file, where=where)
    unknown = set(raw) - JOINT_KEYS
    if unknown:
        raise InputError(
            f"unknown key(s) {sorted(map(str, unknown))}; allowed: {sorted(JOINT_KEYS)}",
            file=file, where=where,
        )
    joint_type = raw.get("type", "revolute")
    if not isinstance(joint_type, str) or joint_type not in JOINT_TYPES:
        raise InputError(
            f"unknown joint type {cut(joint_type)}; expected one of {list(JOINT_TYPES)}",
            file=file,
            where=f"{where}.type",
        )
    L, A = units.length_scale, units.angle_scale
    values = {}
    for key, scale, kind, unit in (("theta", A, "angle", units.angle),
                                   ("d", L, "length", units.length),
                                   ("a", L, "length", units.length),
                                   ("alpha", A, "angle", units.angle)):
        values[key] = quantity(require(raw, key, file=file, where=where), scale, kind,
                               file=file, where=f"{where}.{key}", unit=unit)
    beta = 0.0
    if raw.get("beta") is not None:
        beta = quantity(raw["beta"], A, "angle", file=file, where=f"{where}.beta",
                        unit=units.angle)
    for key, value in (("theta", values["theta"]), ("alpha", values["alpha"]), ("beta", beta)):
        _within_a_turn(value, units, file=file, where=f"{where}.{key}")
    limits = _limits_from_dict(raw.get("limits"), joint_type == "revolute", units, file=file,
                               where=f"{where}.limits", urdf=urdf)
    mass, com = _link_mass(raw, units, file=file, where=where)
    return Joint(
        type=joint_type, beta=beta, limits=limits, mass=mass, com=com,  # type: ignore[arg-type]
        has_beta=raw.get("beta") is not None, drive=_drive(raw, file=file, where=where),
        **values,
    )


def _limits_from_dict(raw: Any, revolute: bool, units: Units, *, file, where: str,
                      urdf: bool) -> tuple[float, float] | None:
    """A joint's ``limits: [lower, upper]`` in SI [rad or m], or None when not given."""
    if raw is None:
        return None
    scale = units.angle_scale if revolute else units.length_scale
    lo, hi = quantities(raw, 2, scale, "angle" if revolute else "length",
                        file=file, where=where,
                        unit=units.angle if revolute else units.length)
    if lo >= hi:
        raise InputError(f"lower limit {lo / scale:g} is not below upper limit "
                         f"{hi / scale:g}", file=file, where=where)
    # A URDF is in radians by definition: wide limits there are the vendor's, not a unit slip.
    if revolute and units.angle == "rad" and not urdf and max(abs(lo), abs(hi)) > MAX_LIMIT:
        raise InputError(f"[{lo:g}, {hi:g}] rad allows more than two turns each way; "
                         f"{DEGREES_HINT}", file=file, where=where)
    return (lo, hi)


def _link_mass(raw: dict, units: Units, *, file, where: str
               ) -> tuple[float | None, tuple[float, ...] | None]:
    """A joint's link ``mass`` [kg] and ``com`` [m] (its frame), both or neither."""
    mass = None
    if raw.get("mass") is not None:
        mass = number(raw["mass"], file=file, where=f"{where}.mass")
        if mass < 0:
            raise InputError(f"mass must not be negative, got {mass:g} kg", file=file,
                             where=f"{where}.mass")
        if mass > MAX_MASS:
            raise InputError(f"mass {mass:g} kg is implausibly large", file=file,
                             where=f"{where}.mass")
    com = None
    if raw.get("com") is not None:
        com = tuple(quantities(raw["com"], 3, units.length_scale, "length", file=file,
                               where=f"{where}.com", unit=units.length))
    if (mass is None) != (com is None):
        given, lacking = ("mass", "com") if com is None else ("com", "mass")
        raise InputError(f"{given} given without {lacking}: a link's gravity needs both",
                         file=file, where=f"{where}.{lacking}")
    return mass, com


def _drive(raw: dict, *, file, where: str) -> str:
    """A joint's ``drive`` (default ``gear``), one of ``DRIVES``."""
    drive = raw.get("drive")
    if drive is None:
        return DEFAULT_DRIVE
    if not isinstance(drive, str) or drive not in DRIVES:
        raise InputError(f"unknown drive {cut(drive)}; expected one of {list(DRIVES)}",
                         file=file, where=f"{where}.drive")
    return drive


def _urdf_robot_from_dict(content: dict, *, file) -> Robot:
    """A robot file in the ``urdf`` convention (what ``robot_to_dict`` writes for a robot
    read from a URDF file): joints ``{name, child, type, xyz, rpy, axis, limits, mass,
    com}``, ``flange: {xyz, rpy}`` and ``urdf: {file, base_link, tip_link}``."""
    check_keys(content, URDF_ROBOT_KEYS, file=file, expected="a robot file")
    units = units_of(content, file=file)
    raw_joints = require(content, "joints", file=file)
    if not isinstance(raw_joints, list) or not raw_joints:
        raise InputError(f"expected a non-empty list of joints, got {cut(raw_joints)}",
                         file=file, where="joints")
    joints = []
    for i, raw in enumerate(raw_joints):
        where = f"joints[{i}] (joint {i + 1})"
        mapping(raw, file=file, where=where, hint="{type, xyz, rpy, axis, ...}")
        unknown = set(raw) - URDF_JOINT_KEYS
        if unknown:
            raise InputError(f"unknown key(s) {sorted(map(str, unknown))}; allowed: "
                             f"{sorted(URDF_JOINT_KEYS)}", file=file, where=where)
        dh_like = _joint_from_dict(
            {"type": raw.get("type", "revolute"), "theta": 0, "d": 0, "a": 0, "alpha": 0,
             **{k: raw[k] for k in ("limits", "mass", "com", "drive") if k in raw}},
            units, file=file, where=where, urdf=True)
        origin = _frame_from_dict({k: raw[k] for k in ("xyz", "rpy") if k in raw}, units,
                                  file=file, where=where)
        axis = np.array(vector(raw.get("axis", [0, 0, 1]), 3, file=file, where=f"{where}.axis"))
        if not exact.norm(axis) > 1e-9:
            raise InputError("the axis has no direction", file=file, where=f"{where}.axis")
        joints.append(UrdfJoint(
            type=dh_like.type, origin=origin,
            axis=tuple(float(v) for v in axis / exact.norm(axis)),  # type: ignore[arg-type]
            limits=dh_like.limits, mass=dh_like.mass, com=dh_like.com, drive=dh_like.drive,
            name=str(raw.get("name", f"joint_{i + 1}")), child=str(raw.get("child", ""))))
    source = None
    if content.get("urdf") is not None:
        block = mapping(content["urdf"], file=file, where="urdf",
                        hint="{file, base_link, tip_link}")
        check_keys(block, ("file", "base_link", "tip_link"), file=file, where="urdf")
        source = UrdfSource(*(str(require(block, k, file=file, where="urdf"))
                              for k in ("file", "base_link", "tip_link")))
    plain = {k: v for k, v in content.items()
             if k not in ("joints", "flange", "urdf", "transmission")}
    plain.update(convention="dh", joints=[{"theta": 0, "d": 0, "a": 0, "alpha": 0}])
    shell = robot_from_dict(plain, file=file)
    return replace(shell, convention="urdf", joints=tuple(joints), urdf=source,
                   transmission=transmission_from_dict(content.get("transmission"), joints,
                                                       file=file),
                   flange=_frame_from_dict(content.get("flange"), units, file=file,
                                           where="flange"))


def _within_a_turn(value: float, units: Units, *, file, where: str) -> None:
    """Refuse a fixed angle [rad] beyond a full turn in a file that declares rad."""
    if units.angle == "rad" and abs(value) > FULL_TURN + 1e-9:
        raise InputError(f"{value:g} rad is more than a full turn; {DEGREES_HINT}", file=file,
                         where=where)


def _frame_from_dict(raw: Any, units: Units, *, file, where: str) -> Frame:
    if raw is None:
        return Frame()
    mapping(raw, file=file, where=where, hint="{xyz: [...], rpy: [...]}")
    check_keys(raw, ("xyz", "rpy"), file=file, where=where)
    xyz = raw.get("xyz")
    rpy = raw.get("rpy")
    for k, angle in enumerate([] if rpy is None else quantities(
            rpy, 3, units.angle_scale, "angle", file=file, where=f"{where}.rpy")):
        _within_a_turn(angle, units, file=file, where=f"{where}.rpy[{k}]")
    return Frame(
        tuple(quantities([0, 0, 0] if xyz is None else xyz, 3, units.length_scale, "length",
                         file=file, where=f"{where}.xyz", unit=units.length)),  # type: ignore
        tuple(quantities([0, 0, 0] if rpy is None else rpy, 3, units.angle_scale, "angle",
                         file=file, where=f"{where}.rpy", unit=units.angle)),  # type: ignore
    )


# ----------------------------------------------------------------------------- writing


def robot_to_dict(robot: Robot, units: Units | None = None) -> dict:
    """The robot file mapping in ``units`` (default: the robot's own file units)."""
    units = units or robot.units
    L, A = units.length_scale, units.angle_scale
    if robot.convention == "urdf":
        return _urdf_robot_to_dict(robot, units)
    joints = []
    for i, joint in enumerate(robot.joints, start=1):
        entry: dict[str, Any] = {"type": joint.type}
        entry["theta"] = to_file_units(joint.theta, A)
        entry["d"] = to_file_units(joint.d, L)
        entry["a"] = to_file_units(joint.a, L)
        entry["alpha"] = to_file_units(joint.alpha, A)
        if joint.has_beta or joint.beta != 0.0:
            entry["beta"] = to_file_units(joint.beta, A)
        if joint.limits is not None:
            scale = A if joint.revolute else L
            entry["limits"] = [to_file_units(limit, scale) for limit in joint.limits]
        if joint.mass is not None:
            entry["mass"] = joint.mass
        if joint.com is not None:
            entry["com"] = [to_file_units(c, L) for c in joint.com]
        if joint.drive != DEFAULT_DRIVE:
            entry["drive"] = joint.drive
        own = {stem: to_file_units(robot.tolerance[f"{stem}{i}"], units.scale(kind))
               for stem, kind in JOINT_TOLERANCE_KEYS.items()
               if f"{stem}{i}" in robot.tolerance}
        if own:
            entry["tolerance"] = own
        joints.append(entry)
    content: dict[str, Any] = {
        "name": robot.name,
        "convention": robot.convention,
        "units": units.as_dict(),
        "joints": joints,
    }
    for key, frame, present in (("base", robot.base, robot.has_base),
                                ("tool", robot.tool, robot.has_tool)):
        if present or any(frame.xyz) or any(frame.rpy):
            content[key] = {"xyz": [to_file_units(v, L) for v in frame.xyz],
                            "rpy": [to_file_units(v, A) for v in frame.rpy]}
    if robot.has_gravity or tuple(robot.gravity) != (0.0, 0.0, -9.81):
        content["gravity"] = list(robot.gravity)
    block = {}
    for key, (target, kind) in TOLERANCE_KEYS.items():
        name = target if not target.startswith(("base", "tool")) else \
            target.replace("xyz", "x").replace("rpy", "rx")
        if name in robot.tolerance:
            block[key] = to_file_units(robot.tolerance[name], units.scale(kind))
    if block:
        content["tolerance"] = block
    if robot.transmission:
        content["transmission"] = transmission_to_dict(robot.transmission)
    return content


def _frame_to_dict(frame: Frame, units: Units) -> dict:
    return {"xyz": [to_file_units(v, units.length_scale) for v in frame.xyz],
            "rpy": [to_file_units(v, units.angle_scale) for v in frame.rpy]}


def _urdf_robot_to_dict(robot: Robot, units: Units) -> dict:
    """The ``urdf``-convention robot file mapping (see ``_urdf_robot_from_dict``)."""
    L, A = units.length_scale, units.angle_scale
    joints = []
    for joint in robot.joints:
        entry: dict[str, Any] = {"name": joint.name, "child": joint.child, "type": joint.type,
                                 **_frame_to_dict(joint.origin, units),
                                 "axis": [float(v) for v in joint.axis]}
        if joint.limits is not None:
            scale = A if joint.revolute else L
            entry["limits"] = [to_file_units(limit, scale) for limit in joint.limits]
        if joint.mass is not None:
            entry["mass"] = joint.mass
            entry["com"] = [to_file_units(c, L) for c in joint.com]
        if joint.drive != DEFAULT_DRIVE:
            entry["drive"] = joint.drive
        joints.append(entry)
    content: dict[str, Any] = {"name": robot.name, "convention": "urdf",
                               "units": units.as_dict(), "joints": joints,
                               "flange": _frame_to_dict(robot.flange, units)}
    if robot.urdf is not None:
        content["urdf"] = {"file": robot.urdf.file, "base_link": robot.urdf.base_link,
                           "tip_link": robot.urdf.tip_link}
    for key, frame, present in (("base", robot.base, robot.has_base),
                                ("tool", robot.tool, robot.has_tool)):
        if present or any(frame.xyz) or any(frame.rpy):
            content[key] = _frame_to_dict(frame, units)
    if robot.has_gravity or tuple(robot.gravity) != (0.0, 0.0, -9.81):
        content["gravity"] = list(robot.gravity)
    if robot.transmission:
        content["transmission"] = transmission_to_dict(robot.transmission)
    return content


class _FlowListDumper(yaml.SafeDumper):
    """Writes short lists inline (``[0, 0, 1]``) the way people write robot files."""


def _represent_list(dumper, data):
    flow = all(not isinstance(v, (list, dict)) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


def _represent_float(dumper, value: float):
    # repr() is the shortest string that reads back to the same float.
    if math.isfinite(value):
        text = repr(float(value))
        if "e" in text and "." not in text.split("e")[0]:
            mantissa, exponent = text.split("e")
            text = f"{mantissa}.0e{exponent}"
        return dumper.represent_scalar("tag:yaml.org,2002:float", text)
    return yaml.SafeDumper.represent_float(dumper, value)


_FlowListDumper.add_representer(list, _represent_list)
_FlowListDumper.add_representer(float, _represent_float)


def dump_yaml(content: dict) -> str:
    """YAML text with inline short lists and full-precision floats."""
    return yaml.dump(content, Dumper=_FlowListDumper, sort_keys=False, width=120)


def save_robot(robot: Robot, path: str | Path, units: Units | None = None) -> None:
    """Write ``robot`` as a robot file in ``units`` (default: its own file units)."""
    Path(path).write_text(dump_yaml(robot_to_dict(robot, units)))
