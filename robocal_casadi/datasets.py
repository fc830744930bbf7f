"""Dataset files (docs/formats.md#dataset-file): reading and checking, all kinds.

A dataset is a YAML file naming its ``kind``, its robot file, its units, the
instrument's geometry and a CSV table. ``load_dataset`` returns a frozen object per
kind with every quantity in SI; the file's units are kept for writing results back.

Extra CSV columns are kept in ``extras`` (``temperature`` [C], ``time`` [s],
``payload`` [kg], others as read) and offered to diagnosis.

Keys are checked strictly: a key the kind does not define (at the top level or inside
``bar``, ``probe``, ``artifact``, ``sphere``, ``laser``, ``target``, ``instrument``) is
refused with the list of allowed keys, so a misspelt optional key (``centre_gues``,
``payload_comm``) is never ignored. An optional key written with no value counts as
absent. Socket names are text (or whole numbers); a socket that appears in no known
distance or perpendicularity and is touched only once in the whole table adds nothing
to the fit and is refused as a likely misspelling.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .checks import path_argument
from .effects.motion import with_directions
from .errors import InputError
from .fields import (
    MAX_ANGLE,
    MAX_LENGTH,
    check_keys,
    check_magnitude,
    cut,
    file_kind,
    file_name,
    load_yaml,
    mapping,
    quantities,
    quantity,
    referenced_file,
    require,
    resolved,
    vector,
)
from .robot import Robot, load_robot
from .table import Table, read_table
from .transforms import matrix_from_quaternion
from .units import Units, units_of

KINDS = ("cross_bar", "artifact_touches", "sphere_laser", "tracker_points")
BAR_POINTS = ("A", "B", "C", "D")
POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
QUATERNION_TOLERANCE = 1e-6
COMMON_KEYS = ("kind", "robot", "units", "data", "payload_com", "planning", "report",
               "base_link", "tip_link", "station", "work_cell")
MAX_STATION_CHARACTERS = 200
KIND_KEYS = {"cross_bar": ("bar", "probe"), "artifact_touches": ("probe", "artifact"),
             "sphere_laser": ("sphere", "laser"), "tracker_points": ("target", "instrument")}
BLOCK_KEYS = {"bar": ("length",), "probe": ("xyz",), "artifact": ("distances", "perpendicular"),
              "sphere": ("radius", "centre_guess"),
              "laser": ("origin_guess", "direction_guess"), "target": ("xyz",),
              "instrument": ("xyz",)}
MAX_POSE_ID = 10**9


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
    lines: np.ndarray | None = field(default=None, repr=False)  # table line of each reading
    # the instrument station (one tracker placement, socket plate or sphere) the readings
    # were taken from; datasets of one station share its placement unknowns
    station: str | None = None
    # the joint ranges [rad or m] the robot works in, per joint (low, high), where the
    # file declares them (``work_cell``); the predicted accuracy is stated over them
    # (or the text ``"measured"``: the poses the fit data were measured in)
    work_cell: tuple[tuple[float, float] | None, ...] | str | None = None

    def line(self, reading: int) -> int:
        """The data table's line (1-based, header on line 1) of reading ``reading``
        (0-based; a row of the table, or one laser reading of a pendant table)."""
        if self.lines is not None and len(self.lines) == self.readings:
            return int(self.lines[reading])
        return reading + 2

    @property
    def readings(self) -> int:
        """How many readings (table rows) the dataset holds; a pendant scan has no joints."""
        distance = getattr(self, "distance", None)
        return self.rows if self.joints is not None or distance is None else len(distance)

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


Dataset = ArtifactTouches | SphereLaser | TrackerPoints


def dataset_rows(dataset: Dataset, mask: np.ndarray) -> Dataset:
    """A copy of ``dataset`` with only the rows where ``mask`` is True (any kind)."""
    mask = np.asarray(mask, dtype=bool)
    # the directions of motion belong to the full table's order: computed before cutting
    extras = with_directions(dataset.joints, dataset.extras)
    changes: dict[str, Any] = {"extras": {k: np.asarray(v)[mask] for k, v in extras.items()}}
    for name in ("joints", "measured", "distance", "flange_poses", "pose"):
        value = getattr(dataset, name, None)
        if value is not None:
            changes[name] = np.asarray(value)[mask]
    # the table lines, where they still describe these rows (a copy cut by hand may not)
    if hasattr(dataset, "lines"):  # a stand-in holding joints and extras only has none
        lines = dataset.lines if dataset.lines is not None and \
            len(dataset.lines) == len(mask) else None
        changes["lines"] = None if lines is None else np.asarray(lines)[mask]
    points = getattr(dataset, "point", None)
    if points:
        changes["point"] = tuple(p for p, keep in zip(points, mask) if keep)
    return replace(dataset, **changes)


# ----------------------------------------------------------------------------- loading


def load_dataset(path: str | Path, *, require_data: bool = True,
                 robot: Robot | str | Path | None = None,
                 allow_outside_data: bool = False) -> Dataset:
    """Read and check a dataset file and its table.

    ``require_data=False`` (planning) does not read the table (it may be missing, or a
    plan whose measured columns are still empty) and returns no rows.
    ``robot`` (a ``Robot`` or a robot file) replaces the robot file the dataset names
    (e.g. a calibrated robot).
    The data table must lie in the dataset file's folder or below it unless
    ``allow_outside_data`` (see ``fields.referenced_file``).
    Every problem raises ``InputError`` naming the file, the key or line, and what is wrong.
    """
    path = path_argument(path, "path")
    if robot is not None and not isinstance(robot, Robot):
        robot = load_robot(path_argument(robot, "robot", what="a Robot or a robot file"))
    content = load_yaml(path, what="dataset file")
    looks = file_kind(content)
    if looks is not None and looks != "a dataset file":
        raise InputError(f"this is {looks}, not a dataset file", file=path)
    kind = require(content, "kind", file=path)
    if not isinstance(kind, str) or kind not in KINDS:
        raise InputError(f"unknown kind {cut(kind)}; expected one of {list(KINDS)}", file=path,
                         where="kind")
    check_keys(content, COMMON_KEYS + KIND_KEYS[kind], file=path)
    for block in KIND_KEYS[kind]:
        if content.get(block) is not None:
            mapping(content[block], file=path, where=block)
            check_keys(content[block], BLOCK_KEYS[block], file=path, where=block)
    units = units_of(content, file=path)
    if content.get("planning") is not None:
        _check_planning(content["planning"], units, path)
    robot_path, robot = referenced_robot(content, path, robot)
    data_path = referenced_file(content, "data", file=path, allow_outside=allow_outside_data,
                                required=False)
    table = None
    if data_path is not None:
        if data_path.is_dir():
            raise InputError(f"the data table {data_path} is a folder", file=path, where="data")
        if data_path.exists() and not data_path.is_file():
            raise InputError(f"the data table {data_path} is not a regular file (a device, "
                             f"pipe or socket)", file=path, where="data")
        if not data_path.exists() and not data_path.is_symlink() and require_data:
            raise InputError(f"data table {data_path} not found", file=path, where="data")
        # Planning describes a set-up: its table may be missing or an unmeasured plan.
        if require_data:
            table = read_table(data_path)
    elif require_data:
        raise InputError("missing required key (the data table)", file=path, where="data")

    payload_com = None
    if content.get("payload_com") is not None:
        payload_com = np.array(quantities(content["payload_com"], 3, units.length_scale, "length",
                                          file=path, where="payload_com", unit=units.length))
    lines = None if table is None else np.array([table.line(i) for i in range(len(table))])
    common = dict(path=path, kind=kind, robot=robot, robot_path=robot_path, units=units,
                  data_path=data_path, payload_com=payload_com, raw=content, lines=lines,
                  station=station_name(content.get("station"), path),
                  work_cell=work_cell_of(content.get("work_cell"), robot, units, path))
    readers: dict[str, Callable[[dict, Table | None, dict], Dataset]] = {
        "cross_bar": _cross_bar, "artifact_touches": _artifact,
        "sphere_laser": _sphere_laser, "tracker_points": _tracker}
    dataset = readers[kind](content, table, common)
    if table is not None:
        dataset = replace(dataset, lines=np.array([table.line(i) for i in range(len(table))]))
    return dataset


def station_name(value: Any, path: Path) -> str | None:
    """The ``station`` key: None when absent, else a non-empty single line of text (a
    number is accepted and read as its text, ``station: 3`` naming station ``"3"``)."""
    if value is None:
        return None
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"expected a station name (text), got {cut(value)}", file=path,
                         where="station")
    name = value.strip()
    if len(name) > MAX_STATION_CHARACTERS or "\n" in name or "\x00" in name:
        raise InputError(f"expected a station name on one line of at most "
                         f"{MAX_STATION_CHARACTERS} characters, got {cut(name, 40)}", file=path,
                         where="station")
    return name


MEASURED_CELL = "measured"


def work_cell_of(value: Any, robot: Robot, units: Units,
                 path: Path) -> tuple[tuple[float, float] | None, ...] | str | None:
    """The ``work_cell`` key: per joint column ``q1..qn`` a range ``[low, high]`` in the
    file's units (angles for revolute joints, lengths for prismatic ones), within the
    robot's limits. Returned in SI, per joint ``(low, high)`` or None for a joint it
    does not name (the prediction then takes the range the fit data cover); None when
    the key is absent. ``work_cell: measured`` names the poses the fit data were
    measured in (returned as that text)."""
    if value is None:
        return None
    if value == MEASURED_CELL:
        return MEASURED_CELL
    block = mapping(value, file=path, where="work_cell",
                    hint="{q1: [low, high], ...} or the text 'measured'")
    names = [f"q{i}" for i in range(1, robot.dof + 1)]
    unknown = [k for k in block if k not in names]
    if unknown:
        raise InputError(f"unknown joint(s) {[cut(k) for k in unknown]}; expected some of "
                         f"{names}", file=path, where="work_cell")
    cell: list[tuple[float, float] | None] = []
    for i, (name, joint) in enumerate(zip(names, robot.joints)):
        if block.get(name) is None:
            cell.append(None)
            continue
        low, high = float(robot.lower_limits[i]), float(robot.upper_limits[i])
        kind = "angle" if joint.revolute else "length"
        scale = units.angle_scale if joint.revolute else units.length_scale
        where = f"work_cell.{name}"
        given = quantities(block[name], 2, scale, kind, file=path, where=where,
                           unit=units.unit_name(kind))
        if not given[0] < given[1]:
            raise InputError(f"expected [low, high] with low below high, got "
                             f"{cut(block[name])}", file=path, where=where)
        if given[0] < low - 1e-9 or given[1] > high + 1e-9:
            raise InputError(f"{cut(block[name])} {units.unit_name(kind)} reaches beyond the "
                             f"robot's limits [{low / scale:g}, {high / scale:g}]", file=path,
                             where=where)
        cell.append((given[0], given[1]))
    return tuple(cell)


# The planning block's angles (file units) must lie in (0, limit] degrees.
PLANNING_ANGLES = {"max_tilt": 90.0, "max_incidence": 90.0, "visibility_cone": 180.0}


def _check_planning(block: Any, units: Units, path: Path) -> None:
    """Types and ranges of the optional ``planning`` block (its keys are checked by the
    planner): angles within (0, 90] deg (cone (0, 180]), a whole touch count of at least
    1, plausible lengths."""
    if not isinstance(block, dict):
        return  # the planner names it
    for key, limit in PLANNING_ANGLES.items():
        if block.get(key) is None:
            continue
        value = quantity(block[key], units.angle_scale, "angle", file=path,
                         where=f"planning.{key}", unit=units.angle)
        if not 0 < value <= np.radians(limit) + 1e-12:
            raise InputError(f"expected an angle above 0 and at most {limit:g} deg, got "
                             f"{cut(block[key])} {units.angle}", file=path, where=f"planning.{key}")
    touches = block.get("touches_per_socket")
    if touches is not None and (isinstance(touches, bool) or not isinstance(touches, int)
                                or touches < 1):
        raise InputError(f"expected a whole number of at least 1, got {cut(touches)}", file=path,
                         where="planning.touches_per_socket")
    if block.get("table_height") is not None:
        quantity(block["table_height"], units.length_scale, "length", file=path,
                 where="planning.table_height", unit=units.length)
    if block.get("laser_range") is not None:
        quantities(block["laser_range"], 2, units.length_scale, "length", file=path,
                   where="planning.laser_range", unit=units.length)


def referenced_robot(content: dict, path: Path, robot: Robot | None = None
                     ) -> tuple[Path, Robot]:
    """The robot file a dataset or job names (relative to it), loaded unless given.

    A missing robot file is reported against the naming file's ``robot`` key; a broken
    one by its own name, key and line.
    """
    name = file_name(require(content, "robot", file=path), file=path, where="robot")
    robot_path = resolved(path.parent / name)
    if robot is None:
        if robot_path.is_dir():
            raise InputError(f"robot file {robot_path} is a folder", file=path, where="robot")
        if not robot_path.exists() and not robot_path.is_symlink():  # a loop: named below
            raise InputError(f"robot file {robot_path} not found", file=path, where="robot")
        if robot_path.exists() and not robot_path.is_file():
            raise InputError(f"robot file {robot_path} is not a regular file (a device, pipe "
                             f"or socket)", file=path, where="robot")
        links = {}
        for key in ("base_link", "tip_link"):  # the chain of a URDF robot
            if content.get(key) is not None:
                links[key] = file_name(content[key], file=path, where=key)
        robot = load_robot(robot_path, **links)
    return robot_path, robot


def _positive_length(content: dict, block: str, key: str, hint: str, units: Units,
                     path: Path) -> tuple[dict, float]:
    """``content[block][key]`` as a positive length [m], with the block mapping."""
    block_map = mapping(require(content, block, file=path), file=path, where=block, hint=hint)
    value = quantity(require(block_map, key, file=path, where=block), units.length_scale,
                     "length", file=path, where=f"{block}.{key}", unit=units.length)
    if value <= 0:
        raise InputError(f"{block} {key} must be positive, got {value / units.length_scale:g}",
                         file=path, where=f"{block}.{key}")
    return block_map, value


def _length3(content: dict, key: str, sub: str, units: Units, path: Path) -> np.ndarray:
    """``content[key][sub]``: three lengths in file units, as SI [m]."""
    block = mapping(require(content, key, file=path), file=path, where=key,
                    hint=f"{{{sub}: [x, y, z]}}")
    return np.array(quantities(require(block, sub, file=path, where=key), 3, units.length_scale,
                               "length", file=path, where=f"{key}.{sub}", unit=units.length))


def _lengths(table: Table, names, units: Units) -> np.ndarray:
    """Table columns of lengths in the dataset's unit, as SI [m] (N x len(names))."""
    table.require(*names)
    values = np.column_stack([table.numbers(n) for n in names])
    too_big = np.abs(values * units.length_scale) > MAX_LENGTH
    if too_big.any():
        row, col = map(int, np.argwhere(too_big)[0])
        check_magnitude(values[row, col] * units.length_scale, "length", file=table.path,
                        where=f"line {table.line(row)}, column {names[col]!r}",
                        shown=values[row, col], unit=units.length)
    return values * units.length_scale


def joint_readings(table: Table, robot: Robot, units: Units, used: set[str],
                   robot_file: Path | str | None = None) -> np.ndarray:
    """Joint columns ``q1..qn`` in SI, checked against the robot's limits.

    Names added to ``used``; a reading outside the limits is an ``InputError`` that says
    when it looks like a unit mix-up (degrees in a file that declares rad, ...).
    ``robot_file`` (where the joints and limits come from) is named in the messages.
    """
    source = f"robot {robot.name!r}" + (f" ({Path(robot_file).name})" if robot_file else "")
    names = [f"q{i}" for i in range(1, robot.dof + 1)]
    missing = [n for n in names if not table.has(n)]
    if missing:
        near = table.missing(missing)
        hint = ""
        if near is not None and "case-sensitive" in near.what:
            hint = near.what[near.what.index(" (found"):]
        raise InputError(
            f"missing joint column(s) {missing}: {source} has {robot.dof} joints"
            f"{hint}", file=table.path, where="line 1")
    extra_q = [c for c in table.columns if c.startswith("q") and c[1:].isdigit() and c not in names]
    if extra_q:
        raise InputError(f"joint column(s) {extra_q} beyond the {robot.dof} joints of {source}",
                         file=table.path, where="line 1")
    used.update(names)
    # The dataset's units apply to its table; prismatic readings are lengths.
    scales = np.array([units.angle_scale if j.revolute else units.length_scale
                       for j in robot.joints])
    raw = np.column_stack([table.numbers(n) for n in names])
    Q = raw * scales
    lower, upper = robot.lower_limits, robot.upper_limits
    tolerance = 1e-9
    bad = (Q < lower - tolerance) | (Q > upper + tolerance)
    if bad.any():
        row, col = map(int, np.argwhere(bad)[0])
        value = raw[row, col]
        unit = units.angle if robot.joints[col].revolute else units.length
        lo, hi = lower[col] / scales[col], upper[col] / scales[col]
        hint = ""
        if robot.joints[col].revolute and units.angle == "rad" and abs(value) > 2 * np.pi:
            hint = "; the value looks like degrees in a file that declares rad"
        elif (robot.joints[col].revolute and units.angle == "deg"
              and np.all(np.abs(raw) < 2 * np.pi)):
            hint = "; all readings are small: radians in a file that declares deg?"
        elif not robot.joints[col].revolute:
            hint = "; check the length unit (mm or m)"
        raise InputError(
            f"q{col + 1} = {value:g} {unit} is outside the robot's limits [{lo:g}, {hi:g}] {unit}"
            f" ({int(bad.sum())} reading(s) out of limits; limits from {source}){hint}",
            file=table.path, where=f"line {table.line(row)}")
    # Joints without limits: still refuse readings no joint could have (overflow, typos).
    bound = np.array([MAX_ANGLE if j.revolute else MAX_LENGTH for j in robot.joints])
    huge = np.abs(Q) > bound
    if huge.any():
        row, col = map(int, np.argwhere(huge)[0])
        kind = "angle" if robot.joints[col].revolute else "length"
        check_magnitude(Q[row, col], kind, file=table.path,
                        where=f"line {table.line(row)}, q{col + 1}", shown=raw[row, col],
                        unit=units.unit_name(kind))
    return Q


def _extras(table: Table, used: set[str]) -> dict[str, np.ndarray]:
    """Unused columns: numeric ones as floats, others kept as text.

    ``temperature`` [C], ``time`` [s] and ``payload`` [kg] feed the effects and must be
    numbers in every row; a payload is never negative and a temperature never below
    absolute zero.
    """
    extras: dict[str, Any] = {}
    for name in table.columns:
        if name in used:
            continue
        if name in ("temperature", "time", "payload"):
            values = table.numbers(name)
            floor = {"payload": 0.0, "temperature": -273.15}.get(name)
            if floor is not None and np.any(values < floor):
                row = int(np.argmax(values < floor))
                what = "a payload must not be negative [kg]" if name == "payload" else \
                    "a temperature [C] below absolute zero"
                raise InputError(f"column {name!r}: {values[row]:g}: {what}", file=table.path,
                                 where=f"line {table.line(row)}")
            extras[name] = values
            continue
        try:
            extras[name] = table.numbers(name)
        except InputError:
            extras[name] = np.array(table.text(name), dtype=object)
    return extras


def _with_table(common: dict, table: Table | None, robot: Robot, used: set[str]) -> dict:
    if table is None:
        return common
    joints = joint_readings(table, robot, common["units"], used, common.get("robot_path"))
    _check_angle_unit(joints, robot, common["units"], table)
    return dict(common, joints=joints)


UNIT_CHECK_ROWS = 10  # readings needed before a narrow spread counts as a unit mix-up
WIDE_RANGE = np.radians(90.0)  # a joint whose limits span more than this may move widely


def _check_angle_unit(joints: np.ndarray, robot: Robot, units: Units, table: Table) -> None:
    """Refuse calibration readings that look like radians in a file that declares deg.

    Every revolute reading within +-2 pi deg (+-6.3 deg), while they do vary and the
    robot's limits allow far more, is what radians read as degrees give; such data
    could not calibrate anything even if meant (the arm hardly moved), and the fit
    would end in undetermined parameters without saying why.
    """
    revolute = [j for j, joint in enumerate(robot.joints) if joint.revolute]
    if units.angle != "deg" or not revolute or len(joints) < UNIT_CHECK_ROWS:
        return
    readings = joints[:, revolute] / units.angle_scale  # as written, in deg
    spans = robot.upper_limits[revolute] - robot.lower_limits[revolute]
    if (np.all(np.abs(readings) <= 2 * np.pi) and np.any(np.ptp(readings, axis=0) > 0)
            and np.any(spans > WIDE_RANGE)):
        raise InputError(f"every joint angle of the {len(joints)} readings lies within "
                         f"+-{2 * np.pi:.3g} deg although the file declares deg and the "
                         f"robot's limits allow far more: radians in a file that declares "
                         f"deg? (set units: {{angle: rad}})", file=table.path,
                         where=f"columns {', '.join(f'q{j + 1}' for j in revolute)}")


def _touch_columns(table: Table, path: Path) -> tuple[np.ndarray, tuple[str, ...]]:
    """The ``pose`` ids (whole numbers) and ``point`` socket names of a touch table."""
    table.require("pose", "point")
    poses = table.numbers("pose")
    bad = (poses != np.round(poses)) | (np.abs(poses) > MAX_POSE_ID)
    if bad.any():
        row = int(np.argmax(bad))
        raise InputError(f"column 'pose': expected a whole-number placement id (at most "
                         f"{MAX_POSE_ID:.0e} in size), got {cut(table.text('pose')[row])}",
                         file=table.path, where=f"line {table.line(row)}")
    points = tuple(table.text("point"))
    for i, p in enumerate(points):
        if not p:
            raise InputError("column 'point': empty socket name", file=table.path,
                             where=f"line {table.line(i)}")
    return poses.astype(np.int64), points


def _cross_bar(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    _, length = _positive_length(content, "bar", "length", "{length: L}", units, path)
    probe = _length3(content, "probe", "xyz", units, path)
    fields: dict[str, Any] = dict(probe=probe, distances=(("A", "C", length), ("B", "D", length)),
                                  perpendicular=(("A", "C", "B", "D"),))
    if table is not None:
        used = {"pose", "point"}
        poses, points = _touch_columns(table, path)
        for i, p in enumerate(points):
            if p not in BAR_POINTS:
                raise InputError(f"column 'point': expected one of A, B, C, D, got {cut(p)}",
                                 file=table.path, where=f"line {table.line(i)}")
        for pose_id in np.unique(poses):
            seen = {points[i] for i in np.flatnonzero(poses == pose_id)}
            if seen != set(BAR_POINTS):
                missing = sorted(set(BAR_POINTS) - seen)
                first = int(np.flatnonzero(poses == pose_id)[0])
                raise InputError(f"bar pose {pose_id} has touches of {sorted(seen)} only; "
                                 f"missing {missing} (each pose needs A, B, C and D)",
                                 file=table.path,
                                 where=f"pose {pose_id} (line {table.line(first)})")
        common = _with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=_extras(table, used))
    return ArtifactTouches(**common, **fields)


def _socket_name(value: Any, *, path: Path, where: str) -> str:
    """A socket named in the artifact block: text or a whole number, as text."""
    if isinstance(value, bool) or not isinstance(value, (str, int)) or str(value).strip() == "":
        raise InputError(f"expected a socket name, got {cut(value)}", file=path, where=where)
    return str(value).strip()


def _list_of(artifact: dict, key: str, path: Path) -> list:
    value = artifact.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise InputError(f"expected a list, got {cut(value)}", file=path, where=f"artifact.{key}")
    return value


def _artifact(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    probe = _length3(content, "probe", "xyz", units, path)
    artifact = mapping(require(content, "artifact", file=path), file=path, where="artifact",
                       hint="{distances: [[socket, socket, length], ...]}")
    distances = []
    lengths: dict[frozenset, tuple[float, str]] = {}
    for k, entry in enumerate(_list_of(artifact, "distances", path)):
        where = f"artifact.distances[{k}]"
        if not isinstance(entry, list) or len(entry) != 3:
            raise InputError(f"expected [socket, socket, length], got {cut(entry)}", file=path,
                             where=where)
        a = _socket_name(entry[0], path=path, where=f"{where}[0]")
        b = _socket_name(entry[1], path=path, where=f"{where}[1]")
        if a == b:
            raise InputError(f"a distance from socket {cut(a)} to itself", file=path, where=where)
        length = quantity(entry[2], units.length_scale, "length", file=path, where=f"{where}[2]",
                          unit=units.length)
        if length <= 0:
            raise InputError(f"distance must be positive, got {cut(entry[2])}", file=path,
                             where=f"{where}[2]")
        pair = frozenset((a, b))
        if pair in lengths:
            raise InputError(f"the distance {a}-{b} is given twice (also {lengths[pair][1]})",
                             file=path, where=where)
        lengths[pair] = (length, where)
        distances.append((a, b, length))
    perpendicular = []
    for k, entry in enumerate(_list_of(artifact, "perpendicular", path)):
        where = f"artifact.perpendicular[{k}]"
        if not isinstance(entry, list) or len(entry) != 4:
            raise InputError(f"expected [A, C, B, D] (AC perpendicular to BD), got {cut(entry)}",
                             file=path, where=where)
        names = tuple(_socket_name(e, path=path, where=f"{where}[{i}]")
                      for i, e in enumerate(entry))
        if names[0] == names[1] or names[2] == names[3]:
            raise InputError(f"each of the two lines needs two different sockets, got "
                             f"{list(names)}", file=path, where=where)
        if {names[0], names[1]} == {names[2], names[3]}:
            raise InputError(f"a line cannot be perpendicular to itself: {list(names)}",
                             file=path, where=where)
        perpendicular.append(names)
    fields: dict[str, Any] = dict(probe=probe, distances=tuple(distances),
                                  perpendicular=tuple(perpendicular))
    if table is not None:
        used = {"pose", "point"}
        poses, points = _touch_columns(table, path)
        named = {s for d in distances for s in d[:2]} | {s for p in perpendicular for s in p}
        unknown = named - set(points)
        if unknown:
            raise InputError(f"socket(s) {sorted(unknown)} named in the artifact are never "
                             f"touched in {table.path.name}", file=path, where="artifact")
        counts: dict[str, int] = {}
        for p in points:
            counts[p] = counts.get(p, 0) + 1
        for i, p in enumerate(points):
            if counts[p] == 1 and p not in named:
                raise InputError(f"socket {cut(p)} is touched only once and named in no distance "
                                 f"or perpendicularity: it adds nothing (a misspelt socket "
                                 f"name? sockets: {sorted(counts)})", file=table.path,
                                 where=f"line {table.line(i)}")
        common = _with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=_extras(table, used))
    return ArtifactTouches(**common, **fields)


def _sphere_laser(content: dict, table: Table | None, common: dict) -> SphereLaser:
    path, units = common["path"], common["units"]
    sphere, radius = _positive_length(content, "sphere", "radius", "{radius: R}", units, path)
    L = units.length_scale
    centre = None
    if sphere.get("centre_guess") is not None:
        centre = np.array(quantities(sphere["centre_guess"], 3, L, "length", file=path,
                                     where="sphere.centre_guess", unit=units.length))
    origin = direction = None
    laser = content.get("laser") or {}
    if laser.get("origin_guess") is not None:
        origin = np.array(quantities(laser["origin_guess"], 3, L, "length", file=path,
                                     where="laser.origin_guess", unit=units.length))
    if laser.get("direction_guess") is not None:
        direction = np.array(vector(laser["direction_guess"], 3, file=path,
                                    where="laser.direction_guess"))
        norm = float(np.linalg.norm(direction / max(np.abs(direction).max(), 1e-300)))
        norm *= float(np.abs(direction).max())
        if not np.isfinite(norm) or norm < 1e-12:
            raise InputError("direction must be a non-zero vector", file=path,
                             where="laser.direction_guess")
        direction = direction / norm
    fields: dict[str, Any] = dict(radius=radius, centre_guess=centre, origin_guess=origin,
                                  direction_guess=direction)
    if table is not None:
        if not table.has("distance"):
            raise InputError(f"missing column 'distance' (the laser readings); the table has "
                             f"{list(table.columns)}", file=table.path, where="line 1")
        used = {"distance"}
        fields["distance"] = _lengths(table, ["distance"], units)[:, 0]
        pose_columns = [c for c in POSE_COLUMNS if table.has(c)]
        joint_columns = [c for c in table.columns if c.startswith("q") and c[1:].isdigit()]
        if pose_columns and joint_columns:
            raise InputError(f"the table has both pendant pose columns {pose_columns} and joint "
                             f"columns {joint_columns}; a scan is read one way: keep one",
                             file=table.path, where="line 1")
        if pose_columns:
            table.require(*POSE_COLUMNS)
            used.update(POSE_COLUMNS)
            fields["flange_poses"] = _pendant_poses(table, units)
        elif joint_columns:
            common = _with_table(common, table, common["robot"], used)
        else:
            raise InputError("expected joint columns q1..qn or pendant pose columns "
                             f"{list(POSE_COLUMNS)}, with 'distance'; the table has "
                             f"{list(table.columns)}", file=table.path, where="line 1")
        fields["extras"] = _extras(table, used)
    return SphereLaser(**common, **fields)


def check_unit_quaternions(quaternions: np.ndarray, table: Table) -> np.ndarray:
    """The norms of ``quaternions`` (N x 4: qw, qx, qy, qz, rows of ``table``); the first
    row whose norm is not 1 within ``QUATERNION_TOLERANCE`` is refused (``InputError``
    naming its line)."""
    big = np.abs(quaternions).max(axis=1, keepdims=True)
    norms = np.linalg.norm(quaternions / np.where(big > 0, big, 1.0), axis=1) * big[:, 0]
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= QUATERNION_TOLERANCE))  # NaN is bad too
    if bad.size:
        row = int(bad[0])
        raise InputError(f"quaternion (qw, qx, qy, qz) has norm {norms[row]:.9g}, not 1 within "
                         f"{QUATERNION_TOLERANCE:g}", file=table.path,
                         where=f"line {table.line(row)}")
    return norms


def _pendant_poses(table: Table, units: Units) -> np.ndarray:
    xyz = _lengths(table, list("xyz"), units)
    quaternions = np.column_stack([table.numbers(c) for c in ("qw", "qx", "qy", "qz")])
    norms = check_unit_quaternions(quaternions, table)
    poses = np.tile(np.eye(4), (len(xyz), 1, 1))
    for i, q in enumerate(quaternions / norms[:, None]):
        poses[i, :3, :3] = matrix_from_quaternion(q)
    poses[:, :3, 3] = xyz
    return poses


def _tracker(content: dict, table: Table | None, common: dict) -> TrackerPoints:
    path, units = common["path"], common["units"]
    target = _length3(content, "target", "xyz", units, path)
    instrument = None
    if content.get("instrument") is not None:
        instrument = _length3(content, "instrument", "xyz", units, path)
    fields: dict[str, Any] = dict(target=target, instrument=instrument)
    if table is not None:
        table.require(*"xyz")
        used = set("xyz")
        fields["measured"] = _lengths(table, list("xyz"), units)
        _check_spread(fields["measured"], common["robot"], target, table, units)
        common = _with_table(common, table, common["robot"], used)
        fields["extras"] = _extras(table, used)
    return TrackerPoints(**common, **fields)


def _reach(robot: Robot) -> float:
    """An upper bound [m] on how far the flange can be from the first joint's frame:
    the sum over links of sqrt(a^2 + d^2), a prismatic joint at its farthest reading,
    plus the tool offset."""
    return robot.reach()


def _check_spread(points: np.ndarray, robot: Robot, target: np.ndarray, table: Table,
                  units: Units) -> None:
    """Refuse a measured point farther from the others than the robot can move its target.

    The instrument frame is unknown, so the test is on the spread: every target position
    lies within ``reach + |target|`` of the first joint, hence within twice that of any
    other, and of the median point. A point beyond is an outlier or a unit mix-up that
    the fit would otherwise report as undetermined parameters.
    """
    if len(points) < 3:
        return
    limit = 2.0 * (_reach(robot) + float(np.linalg.norm(target))) * 1.05
    distance = np.linalg.norm(points - np.median(points, axis=0), axis=1)
    far = np.flatnonzero(distance > limit)
    if far.size:
        row = int(far[np.argmax(distance[far])])
        scale = units.length_scale
        raise InputError(f"the point is {distance[row] / scale:g} {units.length} from the median "
                         f"of the others, farther than the robot can carry its target "
                         f"({limit / scale:g} {units.length}): an outlier or a unit mix-up?",
                         file=table.path, where=f"line {table.line(row)}")
