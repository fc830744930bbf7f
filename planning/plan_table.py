"""Writing a plan as the data table an operator runs (docs/formats.md#plan-table).

Columns: the dataset kind's data-table columns, joints in the dataset's units, the
measured columns (``distance`` or ``x, y, z``) left empty for the operator to fill in;
for bars and artifacts also ``socket_x, socket_y, socket_z``: where the touched socket
must be, world frame, in the dataset's length unit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal_casadi.output import atomic_file
from robocal_casadi.table import write_table

from .design import Plan


def plan_columns(plan: Plan) -> list[str]:
    joints = [f"q{i}" for i in range(1, plan.setup.robot.dof + 1)]
    kind = plan.setup.kind
    if kind == "tracker_points":
        return joints + ["x", "y", "z"]
    if kind == "sphere_laser":
        return joints + ["distance"]
    return ["pose", "point"] + joints + ["socket_x", "socket_y", "socket_z"]


def plan_rows(plan: Plan) -> list[list]:
    """Rows of the plan table, in the dataset's units."""
    setup = plan.setup
    scales = np.array([setup.units.angle_scale if j.revolute else setup.units.length_scale
                       for j in setup.robot.joints])
    length = setup.units.length_scale
    rows = []
    for pose, candidate in enumerate(plan.candidates, start=1):
        for k, q in enumerate(candidate.joints):
            joints = list(q / scales)
            if setup.kind == "tracker_points":
                rows.append(joints + [np.nan] * 3)
            elif setup.kind == "sphere_laser":
                rows.append(joints + [np.nan])
            else:
                name = candidate.points[k]
                rows.append([pose, name] + joints + list(candidate.sockets[name] / length))
    return rows


def write_plan(plan: Plan, path: str | Path) -> None:
    """Write the plan table to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        write_table(staging, plan_columns(plan), plan_rows(plan))
