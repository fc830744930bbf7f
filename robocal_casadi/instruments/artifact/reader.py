"""Reading an artifact dataset: probe touches of named sockets on a rigid artifact.

Keys: ``probe: {xyz}`` the probe-ball centre in the flange frame, ``artifact:
{distances, perpendicular}`` its certified geometry; table columns ``pose`` (placement
id), ``point`` (socket name) and the joints ``q1..qn``. Socket names are text (or whole
numbers); a socket that appears in no known distance or perpendicularity and is touched
only once in the whole table adds nothing to the fit and is refused as a likely
misspelling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...common.fields import cut, mapping, quantity, require
from ...common.table import Table
from ...common.units import Units
from ...errors import InputError
from ..dataset import DatasetBase, extra_columns, length3, same_rows, with_table

MAX_POSE_ID = 10**9
BLOCKS = {"probe": ("xyz",), "artifact": ("distances", "perpendicular")}


@dataclass(frozen=True, repr=False)
class ArtifactTouches(DatasetBase):
    """Probe touches of named sockets on a rigid artifact (the cross bar is one of these).

    ``pose`` (N,) placement ids, ``point`` (N,) socket names, ``probe`` [m] flange
    frame, ``distances`` ``[(socket, socket, length [m])]``, ``perpendicular``
    ``[(A, C, B, D)]`` meaning AC is perpendicular to BD.
    """

    row_fields = ("pose", "point")

    pose: np.ndarray | None = None
    point: tuple[str, ...] = ()
    probe: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distances: tuple[tuple[str, str, float], ...] = ()
    perpendicular: tuple[tuple[str, str, str, str], ...] = ()

def touch_columns(table: Table, path: Path) -> tuple[np.ndarray, tuple[str, ...]]:
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


def read(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    probe = length3(content, "probe", "xyz", units, path)
    artifact = mapping(require(content, "artifact", file=path), file=path, where="artifact",
                       hint="{distances: [[socket, socket, length], ...]}")
    distances = _distances(artifact, units, path)
    perpendicular = _perpendiculars(artifact, path)
    fields: dict[str, Any] = dict(probe=probe, distances=distances,
                                  perpendicular=perpendicular)
    if table is not None:
        used = {"pose", "point"}
        poses, points = touch_columns(table, path)
        named = {s for d in distances for s in d[:2]} | {s for p in perpendicular for s in p}
        _check_touched(named, points, table, path)
        common = with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=extra_columns(table, used))
    return ArtifactTouches(**common, **fields)


def _distances(artifact: dict, units: Units, path: Path) -> tuple[tuple[str, str, float], ...]:
    """``artifact.distances``: ``(socket, socket, length [m])``, each pair once."""
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
    return tuple(distances)


def _perpendiculars(artifact: dict, path: Path) -> tuple[tuple[str, str, str, str], ...]:
    """``artifact.perpendicular``: ``(A, C, B, D)``, AC perpendicular to BD."""
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
        perpendicular.append((names[0], names[1], names[2], names[3]))
    return tuple(perpendicular)


def _check_touched(named: set[str], points: tuple[str, ...], table: Table, path: Path) -> None:
    """Refuse a socket ``named`` in the artifact that the table never touches, and one
    touched once that no distance or perpendicularity names (a misspelling)."""
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


def check(dataset: ArtifactTouches, joints: np.ndarray, where: Path) -> None:
    """In a placement, refuse two related sockets touched only at one and the same joint
    reading: they coincide, and the length of a zero vector has no derivative."""
    pose = np.asarray(dataset.pose)
    point = np.asarray(dataset.point)
    related = [(a, b) for a, b, _ in dataset.distances]
    for entry in dataset.perpendicular:
        related += [(entry[0], entry[1]), (entry[2], entry[3])]
    for placement in np.unique(pose):
        in_pose = pose == placement
        for a, b in related:
            rows = joints[in_pose & ((point == a) | (point == b))]
            touched = set(point[in_pose])
            if a in touched and b in touched and same_rows(rows):
                raise InputError(f"sockets {a} and {b} were touched at the same joints, so "
                                 f"they coincide and their known relation cannot hold: "
                                 f"touch each socket where it is", file=where,
                                 where=f"pose {int(placement)}")

