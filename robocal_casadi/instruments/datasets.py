"""Dataset files (docs/formats.md#dataset-file): reading and checking, any registered kind.

A dataset is a YAML file naming its ``kind``, its robot file, its units, the
instrument's geometry and a CSV table. ``load_dataset`` reads what every kind shares and
hands the instrument's keys and the table to the reader of the kind's ``Instrument``
(``robocal_casadi.instruments``), which returns a frozen record with every quantity in
SI; the file's units are kept for writing results back.

Extra CSV columns are kept in ``extras`` (``temperature`` [C], ``time`` [s],
``payload`` [kg], others as read) and offered to diagnosis.

Keys are checked strictly: a key the kind does not define (at the top level or inside
one of the instrument's blocks) is refused with the list of allowed keys, so a misspelt
optional key (``centre_gues``, ``payload_comm``) is never ignored. An optional key
written with no value counts as absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..common.checks import path_argument
from ..common.fields import (
    check_keys,
    file_kind,
    load_yaml,
    mapping,
    quantities,
    referenced_file,
    require,
)
from ..common.table import Table, read_table
from ..common.units import Units, units_of
from ..errors import InputError
from ..model.robot import Robot, load_robot
from . import Instrument, instrument, noise
from .artifact.reader import ArtifactTouches
from .dataset import (
    COMMON_KEYS,
    DatasetBase,
    check_planning,
    check_unit_quaternions,
    dataset_rows,
    joint_readings,
    referenced_robot,
    station_name,
    work_cell_of,
)
from .laser.reader import SphereLaser
from .tracker.reader import TrackerPoints

Dataset = DatasetBase  # any kind's record (its reader's class)


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
    record = _checked_keys(content, path)
    units = units_of(content, file=path)
    if content.get("planning") is not None:
        check_planning(content["planning"], units, path)
    robot_path, robot = referenced_robot(content, path, robot)
    data_path = referenced_file(content, "data", file=path, allow_outside=allow_outside_data,
                                required=False)
    table = _table(data_path, path, require_data)
    lines = None if table is None else np.array([table.line(i) for i in range(len(table))])
    common = dict(path=path, kind=record.kind, robot=robot, robot_path=robot_path, units=units,
                  data_path=data_path, payload_com=_payload_com(content, units, path),
                  raw=content, lines=lines, station=station_name(content.get("station"), path),
                  work_cell=work_cell_of(content.get("work_cell"), robot, units, path),
                  instrument_noise=noise.declared(
                      content.get("instrument_noise"), units,
                      grows_with_range=record.model.noise_grows_with_range, path=path))
    return record.read(content, table, common)


def _checked_keys(content: dict, path: Path) -> Instrument:
    """The registered instrument ``content`` names, its keys checked (top level and inside
    the instrument's blocks)."""
    looks = file_kind(content)
    if looks is not None and looks != "a dataset file":
        raise InputError(f"this is {looks}, not a dataset file", file=path)
    record = instrument(require(content, "kind", file=path), file=path)
    check_keys(content, COMMON_KEYS + tuple(record.blocks), file=path)
    for block, keys in record.blocks.items():
        if content.get(block) is not None:
            mapping(content[block], file=path, where=block)
            check_keys(content[block], keys, file=path, where=block)
    return record


def _table(data_path: Path | None, path: Path, require_data: bool) -> Table | None:
    """The data table ``data_path`` the dataset file ``path`` names, read when
    ``require_data`` (planning describes a set-up: its table may be missing or an
    unmeasured plan)."""
    if data_path is None:
        if require_data:
            raise InputError("missing required key (the data table)", file=path, where="data")
        return None
    if data_path.is_dir():
        raise InputError(f"the data table {data_path} is a folder", file=path, where="data")
    if data_path.exists() and not data_path.is_file():
        raise InputError(f"the data table {data_path} is not a regular file (a device, "
                         f"pipe or socket)", file=path, where="data")
    if not data_path.exists() and not data_path.is_symlink() and require_data:
        raise InputError(f"data table {data_path} not found", file=path, where="data")
    return read_table(data_path) if require_data else None


def _payload_com(content: dict, units: Units, path: Path) -> np.ndarray | None:
    """``payload_com`` [m] (flange frame), or None when the file does not give it."""
    if content.get("payload_com") is None:
        return None
    return np.array(quantities(content["payload_com"], 3, units.length_scale, "length",
                               file=path, where="payload_com", unit=units.length))


__all__ = ["ArtifactTouches", "Dataset", "DatasetBase", "SphereLaser", "TrackerPoints",
           "check_unit_quaternions", "dataset_rows", "joint_readings", "load_dataset",
           "referenced_robot"]
