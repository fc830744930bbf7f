"""Reading a cross-bar dataset: an artifact of four sockets A, C and B, D at the ends of
two equal perpendicular arms of length ``bar.length``, each touched once per placement.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...common.fields import cut
from ...common.table import Table
from ...errors import InputError
from ..artifact.reader import ArtifactTouches, touch_columns
from ..dataset import extra_columns, length3, positive_length, with_table

BAR_POINTS = ("A", "B", "C", "D")
BLOCKS = {"bar": ("length",), "probe": ("xyz",)}


def read(content: dict, table: Table | None, common: dict) -> ArtifactTouches:
    path, units = common["path"], common["units"]
    _, length = positive_length(content, "bar", "length", "{length: L}", units, path)
    probe = length3(content, "probe", "xyz", units, path)
    fields: dict[str, Any] = dict(probe=probe, distances=(("A", "C", length), ("B", "D", length)),
                                  perpendicular=(("A", "C", "B", "D"),))
    if table is not None:
        used = {"pose", "point"}
        poses, points = touch_columns(table, path)
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
        common = with_table(common, table, common["robot"], used)
        fields.update(pose=poses, point=points, extras=extra_columns(table, used))
    return ArtifactTouches(**common, **fields)
