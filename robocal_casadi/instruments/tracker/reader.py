"""Reading a tracker dataset: absolute target positions (N x 3) [m] in the instrument frame.

Keys: ``target: {xyz}`` the reflector in the flange frame, ``instrument: {xyz}`` where
the tracker stands in the world (optional, for planning); table columns ``q1..qn`` and
``x, y, z`` in the file's length unit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...common.table import Table
from ...common.units import Units
from ...errors import InputError
from ...model.robot import Robot
from ..dataset import DatasetBase, extra_columns, length3, lengths, same_rows, with_table

BLOCKS = {"target": ("xyz",), "instrument": ("xyz",)}


@dataclass(frozen=True, repr=False)
class TrackerPoints(DatasetBase):
    """Absolute positions (N x 3) [m] in the instrument frame of a flange-frame target."""

    row_fields = ("measured",)

    measured: np.ndarray | None = None
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    instrument: np.ndarray | None = None  # [m] instrument origin in the world, for planning


def read(content: dict, table: Table | None, common: dict) -> TrackerPoints:
    path, units = common["path"], common["units"]
    target = length3(content, "target", "xyz", units, path)
    instrument = None
    if content.get("instrument") is not None:
        instrument = length3(content, "instrument", "xyz", units, path)
    fields: dict[str, Any] = dict(target=target, instrument=instrument)
    if table is not None:
        table.require(*"xyz")
        used = set("xyz")
        fields["measured"] = lengths(table, list("xyz"), units)
        _check_spread(fields["measured"], common["robot"], target, table, units)
        common = with_table(common, table, common["robot"], used)
        fields["extras"] = extra_columns(table, used)
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


def check(dataset: TrackerPoints, joints: np.ndarray, where: Path) -> None:
    """Refuse a tracker that measured the same point in every row while the joints moved."""
    measured = dataset.measured
    if measured is not None and same_rows(np.asarray(measured, dtype=float)):
        raise InputError(f"every one of the {len(measured)} measured points is the same "
                         f"(x, y, z equal in all rows) while the joints move: the instrument "
                         f"did not follow the target", file=where)
