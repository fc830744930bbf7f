"""Dataset files (CONTRACT.md "Dataset file"): reading and checking, all kinds.

A dataset is a YAML file naming its ``kind``, its robot file, its units, the
instrument's geometry and a CSV table. ``load_dataset`` returns a frozen object per
kind with every quantity in SI; the file's units are kept for writing results back.

Extra CSV columns are kept in ``extras`` (``temperature`` [C], ``time`` [s],
``payload`` [kg], others as read) and offered to diagnosis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np

from .errors import InputError
from .fields import load_yaml, number, require, vector
from .robot import Robot, load_robot
from .table import Table, read_table
from .transforms import matrix_from_quaternion
from .units import Units, parse_units

KINDS = ("cross_bar", "artifact_touches", "sphere_laser", "tracker_points")
BAR_POINTS = ("A", "B", "C", "D")
POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
QUATERNION_TOLERANCE = 1e-6


@dataclass(frozen=True)
class DatasetBase:
    """What every kind shares. ``joints`` (N x dof) in SI, NaN-free unless ``planned``."""

    path: Path
    kind: str
    robot: Robot
    robot_path: Path
    units: Units
    data_path: Path | None
    joints: np.ndarray | None = None  # no rows when the table is absent (planning)
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    payload_com: np.ndarray | None = None  # [m], flange frame
    raw: dict = field(default_factory=dict, repr=False)  # the YAML mapping as read

    @property
    def rows(self) -> int:
        return 0 if self.joints is None else len(self.joints)

    @property
    def name(self) -> str:
        return self.path.name

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.path.name!r}, kind={self.kind}, "
                f"robot={self.robot.name!r}, rows={self.rows})")


@dataclass(frozen=True, repr=False)
class ArtifactTouches(DatasetBase):
    """Probe touches of named sockets on a rigid artifact (``cross_bar`` is one of these).

    ``pose`` (N,) placement ids, ``point`` (N,) socket names, ``probe`` [m] flange
    frame, ``distances`` ``[(socket, socket, length [m])]``, ``perpendicular``
    ``[(A, C, B, D)]`` meaning AC is perpendicular to BD.
    """

    pose: np.ndarray | None = None
    point: tuple[str, ...] = ()
    probe: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distances: tuple[tuple[str, str, float], ...] = ()
    perpendicular: tuple[tuple[str, str, str, str], ...] = ()


@dataclass(frozen=True, repr=False)
class SphereLaser(DatasetBase):
    """Point-laser readings of a sphere. Either ``joints`` or ``flange_poses`` is set.

    ``flange_poses`` (N x 4 x 4) [m] base frame, from the pendant; ``distance`` (N,) [m]
    raw laser readings; ``radius`` [m]; guesses in SI (flange frame for the laser, base
    frame for the centre) or None.
    """

    flange_poses: np.ndarray | None = None
    distance: np.ndarray | None = None
    radius: float = 0.0
    centre_guess: np.ndarray | None = None
    origin_guess: np.ndarray | None = None
    direction_guess: np.ndarray | None = None


@dataclass(frozen=True, repr=False)
class TrackerPoints(DatasetBase):
    """Absolute positions (N x 3) [m] in the instrument frame of a flange-frame target."""

    measured: np.ndarray | None = None
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    instrument: np.ndarray | None = None  # [m] instrument origin in the world, for planning


Dataset = Union[ArtifactTouches, SphereLaser, TrackerPoints]


# ----------------------------------------------------------------------------- loading


def load_dataset(path: str | Path, *, require_data: bool = True,
                 robot: Robot | None = None) -> Dataset:
    """Read and check a dataset file and its table.

    ``require_data=False`` (planning) accepts a missing table and returns no rows.
    ``robot`` replaces the robot file the dataset names (e.g. a calibrated robot).
    Every problem raises ``InputError`` naming the file, the key or line, and what is wrong.
    """
    path = Path(path)
    content = load_yaml(path, what="dataset file")
    kind = require(content, "kind", file=path)
    if kind not in KINDS:
        raise InputError(f"unknown kind {kind!r}; expected one of {list(KINDS)}", file=path,
                         where="kind")
    units = parse_units(require(content, "units", file=path), file=path)
    robot_path, robot = referenced_robot(content, path, robot)
    data_name = content.get("data")
    table = None
    data_path = None
    if data_name is not None:
        data_path = path.parent / str(data_name)
        if data_path.is_file() or require_data:
            table = read_table(data_path)
    elif require_data:
        raise InputError("missing required key", file=path, where="data")

    payload_com = None
    if "payload_com" in content:
        payload_com = np.array(vector(content["payload_com"], 3, file=path,
                                      where="payload_com")) * units.length_scale
    common = dict(path=path, kind=kind, robot=robot, robot_path=robot_path, units=units,
                  data_path=data_path, payload_com=payload_com, raw=content)
    reader = {"cross_bar": _cross_bar, "artifact_touches": _artifact,
              "sphere_laser": _sphere_laser, "tracker_points": _tracker}[kind]
    return reader(content, table, common)


def referenced_robot(content: dict, path: Path, robot: Robot | None = None
                     ) -> tuple[Path, Robot]:
    """The robot file a dataset or job names (relative to it), loaded unless given."""
    robot_path = (path.parent / str(require(content, "robot", file=path))).resolve()
    if robot is None:
        if not robot_path.is_file():
            raise InputError(f"robot file {robot_path} not found", file=path, where="robot")
        robot = load_robot(robot_path)
    return robot_path, robot


def _positive_length(content: dict, block: str, key: str, hint: str, units: Units,
                     path: Path) -> tuple[dict, float]:
    """``content[block][key]`` as a positive length [m], with the block mapping."""
    mapping = require(content, block, file=path)
    if not isinstance(mapping, dict):
        raise InputError(f"expected a mapping {hint}", file=path, where=block)
    value = number(require(mapping, key, file=path, where=block), file=path,
                   where=f"{block}.{key}") * units.length_scale
    if value <= 0:
        raise InputError(f"{block} {key} must be positive, got {value / units.length_scale:g}",
                         file=path, where=f"{block}.{key}")
    return mapping, value


def _length3(content: dict, key: str, sub: str, units: Units, path: Path) -> np.ndarray:
    block = require(content, key, file=path)
    if not isinstance(block, dict):
        raise InputError("expected a mapping", file=path, where=key)
    return np.array(vector(require(block, sub, file=path, where=key), 3, file=path,
                           where=f"{key}.{sub}")) * units.length_scale


def joint_readings(table: Table, robot: Robot, units: Units, used: set[str]) -> np.ndarray:
    """Joint columns ``q1..qn`` in SI, checked against the robot's limits.

    Names added to ``used``; a reading outside the limits is an ``InputError`` that says
    when it looks like a unit mix-up (degrees in a file that declares rad, ...).
    """
    names = [f"q{i}" for i in range(1, robot.dof + 1)]
    missing = [n for n in names if not table.has(n)]
    if missing:
        raise InputError(
            f"missing joint column(s) {missing}: robot {robot.name!r} has {robot.dof} joints",
            file=table.path)
    extra_q = [c for c in table.columns if c.startswith("q") and c[1:].isdigit() and c not in names]
    if extra_q:
        raise InputError(f"joint column(s) {extra_q} beyond the robot's {robot.dof} joints",
                         file=table.path)
    used.update(names)
    # The dataset's units apply to its table; prismatic readings are lengths.
    scales = np.array([units.angle_scale if j.revolute else units.length_scale
                       for j in robot.joints])
    Q = np.column_stack([table.numbers(n) for n in names]) * scales
    lower, upper = robot.lower_limits, robot.upper_limits
    tolerance = 1e-9
    bad = (Q < lower - tolerance) | (Q > upper + tolerance)
    if bad.any():
        row, col = map(int, np.argwhere(bad)[0])
        value = Q[row, col] / scales[col]
        unit = units.angle if robot.joints[col].revolute else units.length
        lo, hi = lower[col] / scales[col], upper[col] / scales[col]
        hint = ""
        if robot.joints[col].revolute and units.angle == "rad" and abs(value) > 2 * np.pi:
            hint = "; the value looks like degrees in a file that declares rad"
        elif robot.joints[col].revolute and units.angle == "deg" and np.all(np.abs(Q / scales) < 2 * np.pi):
            hint = "; all readings are small: radians in a file that declares deg?"
        elif not robot.joints[col].revolute:
            hint = "; check the length unit (mm or m)"
        raise InputError(
            f"q{col + 1} = {value:g} {unit} is outside the robot's limits [{lo:g}, {hi:g}] {unit}"
            f" ({int(bad.sum())} reading(s) out of limits){hint}",
            file=table.path, where=f"line {table.line(row)}")
    return Q


def _extras(table: Table, used: set[str]) -> dict[str, np.ndarray]:
    """Unused columns: numeric ones as floats, others left out with no loss (kept as text)."""
    extras: dict[str, Any] = {}
    for name in table.columns:
        if name in used:
            continue
        try:
            extras[name] = table.numbers(name)
        except InputError:
            if name in ("temperature", "time", "payload"):
                raise
            extras[name] = np.array(table.text(name), dtype=object)
    return extras


def _with_table(common: dict, table: Table | None, robot: Robot, used: set[str]) -> dict:
    if table is None:
        return common
    return dict(common, joints=joint_readings(table, robot, common["units"], used))


def _touch_columns(table: Table, path: Path) -> tuple[np.ndarray, tuple[str, ...]]:
    poses = table.numbers("pose")
    if np.any(poses != np.round(poses)):
        row = int(np.argmax(poses != np.round(poses)))
        raise InputError(f"column 'pose': expected an integer id, got {table.text('pose')[row]!r}",
                         file=table.path, where=f"line {table.line(row)}")
    points = tuple(table.text("point"))
    for i, p in enumerate(points):
        if not p:
            raise InputError("column 'point': empty socket name", file=table.path,
                             where=f"line {table.line(i)}")
    return poses.astype(int), points


def _cross_bar(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    _, length = _positive_length(content, "bar", "length", "{length: L}", units, path)
    probe = _length3(content, "probe", "xyz", units, path)
    fields: dict[str, Any] = dict(probe=probe, distances=(("A", "C", length), ("B", "D", length)),
                                  perpendicular=(("A", "C", "B", "D"),))
    if table is not None:
        for column in ("pose", "point"):
            if not table.has(column):
                raise InputError(f"missing column {column!r}; the table has {list(table.columns)}",
                                 file=table.path)
        used = {"pose", "point"}
        poses, points = _touch_columns(table, path)
        for i, p in enumerate(points):
            if p not in BAR_POINTS:
                raise InputError(f"column 'point': expected one of A, B, C, D, got {p!r}",
                                 file=table.path, where=f"line {table.line(i)}")
        for pose_id in np.unique(poses):
            seen = {points[i] for i in np.flatnonzero(poses == pose_id)}
            if seen != set(BAR_POINTS):
                missing = sorted(set(BAR_POINTS) - seen)
                raise InputError(f"bar pose {pose_id} has touches of {sorted(seen)} only; "
                                 f"missing {missing} (each pose needs A, B, C and D)",
                                 file=table.path, where=f"pose {pose_id}")
        common = _with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=_extras(table, used))
    return ArtifactTouches(**common, **fields)


def _artifact(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    probe = _length3(content, "probe", "xyz", units, path)
    artifact = require(content, "artifact", file=path)
    if not isinstance(artifact, dict):
        raise InputError("expected a mapping", file=path, where="artifact")
    distances = []
    for k, entry in enumerate(artifact.get("distances", []) or []):
        where = f"artifact.distances[{k}]"
        if not isinstance(entry, list) or len(entry) != 3:
            raise InputError(f"expected [socket, socket, length], got {entry!r}", file=path,
                             where=where)
        length = number(entry[2], file=path, where=f"{where}[2]") * units.length_scale
        if length <= 0:
            raise InputError("distance must be positive", file=path, where=f"{where}[2]")
        distances.append((str(entry[0]), str(entry[1]), length))
    perpendicular = []
    for k, entry in enumerate(artifact.get("perpendicular", []) or []):
        if not isinstance(entry, list) or len(entry) != 4:
            raise InputError(f"expected [A, C, B, D], got {entry!r}", file=path,
                             where=f"artifact.perpendicular[{k}]")
        perpendicular.append(tuple(str(e) for e in entry))
    fields: dict[str, Any] = dict(probe=probe, distances=tuple(distances),
                                  perpendicular=tuple(perpendicular))
    if table is not None:
        for column in ("pose", "point"):
            if not table.has(column):
                raise InputError(f"missing column {column!r}; the table has {list(table.columns)}",
                                 file=table.path)
        used = {"pose", "point"}
        poses, points = _touch_columns(table, path)
        named = {s for d in distances for s in d[:2]} | {s for p in perpendicular for s in p}
        unknown = named - set(points)
        if unknown:
            raise InputError(f"socket(s) {sorted(unknown)} named in the artifact are never "
                             f"touched in {table.path.name}", file=path, where="artifact")
        common = _with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=_extras(table, used))
    return ArtifactTouches(**common, **fields)


def _sphere_laser(content: dict, table: Table | None, common: dict) -> SphereLaser:
    path, units = common["path"], common["units"]
    sphere, radius = _positive_length(content, "sphere", "radius", "{radius: R}", units, path)
    centre = None
    if "centre_guess" in sphere:
        centre = np.array(vector(sphere["centre_guess"], 3, file=path,
                                 where="sphere.centre_guess")) * units.length_scale
    origin = direction = None
    laser = content.get("laser") or {}
    if not isinstance(laser, dict):
        raise InputError("expected a mapping", file=path, where="laser")
    if "origin_guess" in laser:
        origin = np.array(vector(laser["origin_guess"], 3, file=path,
                                 where="laser.origin_guess")) * units.length_scale
    if "direction_guess" in laser:
        direction = np.array(vector(laser["direction_guess"], 3, file=path,
                                    where="laser.direction_guess"))
        if np.linalg.norm(direction) < 1e-12:
            raise InputError("direction must not be zero", file=path,
                             where="laser.direction_guess")
        direction = direction / np.linalg.norm(direction)
    fields: dict[str, Any] = dict(radius=radius, centre_guess=centre, origin_guess=origin,
                                  direction_guess=direction)
    if table is not None:
        if not table.has("distance"):
            raise InputError(f"missing column 'distance'; the table has {list(table.columns)}",
                             file=table.path)
        used = {"distance"}
        fields["distance"] = table.numbers("distance") * units.length_scale
        if all(table.has(c) for c in POSE_COLUMNS):
            used.update(POSE_COLUMNS)
            fields["flange_poses"] = _pendant_poses(table, units)
        elif table.has("q1"):
            common = _with_table(common, table, common["robot"], used)
        else:
            raise InputError("expected joint columns q1..qn or pendant pose columns "
                             f"{list(POSE_COLUMNS)}, with 'distance'", file=table.path)
        fields["extras"] = _extras(table, used)
    return SphereLaser(**common, **fields)


def _pendant_poses(table: Table, units: Units) -> np.ndarray:
    xyz = np.column_stack([table.numbers(c) for c in "xyz"]) * units.length_scale
    quaternions = np.column_stack([table.numbers(c) for c in ("qw", "qx", "qy", "qz")])
    norms = np.linalg.norm(quaternions, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_TOLERANCE)
    if bad.size:
        row = int(bad[0])
        raise InputError(f"quaternion (qw, qx, qy, qz) has norm {norms[row]:.9g}, not 1 within "
                         f"{QUATERNION_TOLERANCE:g}", file=table.path, where=f"line {table.line(row)}")
    poses = np.tile(np.eye(4), (len(xyz), 1, 1))
    for i, q in enumerate(quaternions / norms[:, None]):
        poses[i, :3, :3] = matrix_from_quaternion(q)
    poses[:, :3, 3] = xyz
    return poses


def _tracker(content: dict, table: Table | None, common: dict) -> TrackerPoints:
    path, units = common["path"], common["units"]
    target = _length3(content, "target", "xyz", units, path)
    instrument = None
    if "instrument" in content:
        instrument = _length3(content, "instrument", "xyz", units, path)
    fields: dict[str, Any] = dict(target=target, instrument=instrument)
    if table is not None:
        for column in "xyz":
            if not table.has(column):
                raise InputError(f"missing column {column!r}; the table has {list(table.columns)}",
                                 file=table.path)
        used = set("xyz")
        fields["measured"] = np.column_stack([table.numbers(c) for c in "xyz"]) * units.length_scale
        common = _with_table(common, table, common["robot"], used)
        fields["extras"] = _extras(table, used)
    return TrackerPoints(**common, **fields)
