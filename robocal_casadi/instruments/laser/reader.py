"""Reading a laser-on-a-sphere dataset: distances to a sphere of known radius.

Keys: ``sphere: {radius, centre_guess}``, ``laser: {origin_guess, direction_guess}``;
table columns ``distance`` and either the joints ``q1..qn`` or the pendant's flange pose
``x, y, z, qw, qx, qy, qz`` (base frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...common.fields import quantities, vector
from ...common.table import Table
from ...common.units import Units
from ...errors import InputError
from ...model.transforms import matrix_from_quaternion
from ..dataset import (
    DatasetBase,
    check_unit_quaternions,
    extra_columns,
    lengths,
    positive_length,
    with_table,
)

POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
BLOCKS = {"sphere": ("radius", "centre_guess"), "laser": ("origin_guess", "direction_guess")}


@dataclass(frozen=True, repr=False)
class SphereLaser(DatasetBase):
    """Point-laser readings of a sphere. Either ``joints`` or ``flange_poses`` is set.

    ``flange_poses`` (N x 4 x 4) [m] base frame, from the pendant; ``distance`` (N,) [m]
    raw laser readings; ``radius`` [m]; guesses in SI (flange frame for the laser, base
    frame for the centre) or None.
    """

    row_fields = ("distance", "flange_poses")

    flange_poses: np.ndarray | None = None
    distance: np.ndarray | None = None
    radius: float = 0.0
    centre_guess: np.ndarray | None = None
    origin_guess: np.ndarray | None = None
    direction_guess: np.ndarray | None = None

def read(content: dict, table: Table | None, common: dict) -> SphereLaser:
    path, units = common["path"], common["units"]
    sphere, radius = positive_length(content, "sphere", "radius", "{radius: R}", units, path)
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
        fields["distance"] = lengths(table, ["distance"], units)[:, 0]
        pose_columns = [c for c in POSE_COLUMNS if table.has(c)]
        joint_columns = [c for c in table.columns if c.startswith("q") and c[1:].isdigit()]
        if pose_columns and joint_columns:
            raise InputError(f"the table has both pendant pose columns {pose_columns} and joint "
                             f"columns {joint_columns}; a scan is read one way: keep one",
                             file=table.path, where="line 1")
        if pose_columns:
            table.require(*POSE_COLUMNS)
            used.update(POSE_COLUMNS)
            fields["flange_poses"] = pendant_poses(table, units)
        elif joint_columns:
            common = with_table(common, table, common["robot"], used)
        else:
            raise InputError("expected joint columns q1..qn or pendant pose columns "
                             f"{list(POSE_COLUMNS)}, with 'distance'; the table has "
                             f"{list(table.columns)}", file=table.path, where="line 1")
        fields["extras"] = extra_columns(table, used)
    return SphereLaser(**common, **fields)

def pendant_poses(table: Table, units: Units) -> np.ndarray:
    xyz = lengths(table, list("xyz"), units)
    quaternions = np.column_stack([table.numbers(c) for c in ("qw", "qx", "qy", "qz")])
    norms = check_unit_quaternions(quaternions, table)
    poses = np.tile(np.eye(4), (len(xyz), 1, 1))
    for i, q in enumerate(quaternions / norms[:, None]):
        poses[i, :3, :3] = matrix_from_quaternion(q)
    poses[:, :3, 3] = xyz
    return poses

