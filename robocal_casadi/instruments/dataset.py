"""What every dataset kind shares: the frozen base record and the reading helpers.

A kind's reader (``instruments/<kind>/reader.py``) builds its own frozen record on
``DatasetBase`` from the checked YAML mapping and table, with the helpers here: every
quantity in SI, the file's units kept for writing results back. ``datasets.load_dataset``
reads what all kinds share and hands the rest to the reader the registry names.

Extra CSV columns are kept in ``extras`` (``temperature`` [C], ``time`` [s],
``payload`` [kg], others as read) and offered to diagnosis.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..common.fields import (
    MAX_ANGLE,
    MAX_LENGTH,
    check_magnitude,
    cut,
    file_name,
    mapping,
    quantities,
    quantity,
    require,
    resolved,
)
from ..common.table import Table
from ..common.units import Units
from ..effects.motion import with_directions
from ..errors import InputError
from ..model.robot import Robot, load_robot
from .noise import InstrumentNoise

QUATERNION_TOLERANCE = 1e-6
COMMON_KEYS = ("kind", "robot", "units", "data", "payload_com", "planning", "report",
               "base_link", "tip_link", "station", "work_cell", "instrument_noise")
MAX_STATION_CHARACTERS = 200


@dataclass(frozen=True)
class DatasetBase:
    """What every kind shares. ``joints`` (N x dof) in SI, NaN-free unless ``planned``.

    A kind's record adds its own fields; ``row_fields`` names those that hold one entry
    per data row (arrays, or tuples of text), so that ``dataset_rows`` cuts them too.
    """

    row_fields: ClassVar[tuple[str, ...]] = ()

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
    # the instrument's own noise as the file declares it (``instruments.noise``); None:
    # the measurement model's typical value stands
    instrument_noise: InstrumentNoise | None = None

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


def dataset_rows(dataset: DatasetBase, mask: np.ndarray) -> DatasetBase:
    """A copy of ``dataset`` with only the rows where ``mask`` is True (any kind)."""
    mask = np.asarray(mask, dtype=bool)
    # the directions of motion belong to the full table's order: computed before cutting
    extras = with_directions(dataset.joints, dataset.extras, getattr(dataset, "robot", None))
    changes: dict[str, Any] = {"extras": {k: np.asarray(v)[mask] for k, v in extras.items()}}
    for name in ("joints", *getattr(dataset, "row_fields", ())):
        value = getattr(dataset, name, None)
        if isinstance(value, tuple):
            changes[name] = tuple(v for v, keep in zip(value, mask) if keep)
        elif value is not None:
            changes[name] = np.asarray(value)[mask]
    # the table lines, where they still describe these rows (a copy cut by hand may not)
    if hasattr(dataset, "lines"):  # a stand-in holding joints and extras only has none
        lines = dataset.lines if dataset.lines is not None and \
            len(dataset.lines) == len(mask) else None
        changes["lines"] = None if lines is None else np.asarray(lines)[mask]
    return replace(dataset, **changes)


def same_rows(values: np.ndarray) -> bool:
    """Every row of ``values`` (N x k) equal to the first, bit for bit (data that cannot
    calibrate: see ``calibration.degeneracy``)."""
    return len(values) > 1 and bool(np.all(values == values[0]))


# ----------------------------------------------------------------------------- reading


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


def check_planning(block: Any, units: Units, path: Path) -> None:
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



def positive_length(content: dict, block: str, key: str, hint: str, units: Units,
                     path: Path) -> tuple[dict, float]:
    """``content[block][key]`` as a positive length [m], with the block mapping."""
    block_map = mapping(require(content, block, file=path), file=path, where=block, hint=hint)
    value = quantity(require(block_map, key, file=path, where=block), units.length_scale,
                     "length", file=path, where=f"{block}.{key}", unit=units.length)
    if value <= 0:
        raise InputError(f"{block} {key} must be positive, got {value / units.length_scale:g}",
                         file=path, where=f"{block}.{key}")
    return block_map, value


def length3(content: dict, key: str, sub: str, units: Units, path: Path) -> np.ndarray:
    """``content[key][sub]``: three lengths in file units, as SI [m]."""
    block = mapping(require(content, key, file=path), file=path, where=key,
                    hint=f"{{{sub}: [x, y, z]}}")
    return np.array(quantities(require(block, sub, file=path, where=key), 3, units.length_scale,
                               "length", file=path, where=f"{key}.{sub}", unit=units.length))


def lengths(table: Table, names, units: Units) -> np.ndarray:
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


def extra_columns(table: Table, used: set[str]) -> dict[str, np.ndarray]:
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


def with_table(common: dict, table: Table | None, robot: Robot, used: set[str]) -> dict:
    if table is None:
        return common
    joints = joint_readings(table, robot, common["units"], used, common.get("robot_path"))
    check_angle_unit(joints, robot, common["units"], table)
    return dict(common, joints=joints)


UNIT_CHECK_ROWS = 10  # readings needed before a narrow spread counts as a unit mix-up
WIDE_RANGE = np.radians(90.0)  # a joint whose limits span more than this may move widely


def check_angle_unit(joints: np.ndarray, robot: Robot, units: Units, table: Table) -> None:
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


