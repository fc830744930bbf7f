"""Writing a plan as the data table an operator runs (docs/formats.md#plan-table).

Columns: the measurement model's (``plan_columns``): the data-table columns, joints in
the dataset's units, the measured columns (``distance`` or ``x, y, z``) left empty for
the operator to fill in; for bars and artifacts also ``socket_x, socket_y, socket_z``:
where the touched socket must be, world frame, in the dataset's length unit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal_casadi.common.output import atomic_file
from robocal_casadi.common.table import write_table

from .design import Plan


def plan_columns(plan: Plan) -> list[str]:
    joints = [f"q{i}" for i in range(1, plan.setup.robot.dof + 1)]
    return plan.setup.model.plan_columns(joints)


def plan_rows(plan: Plan) -> list[list]:
    """Rows of the plan table, in the dataset's units."""
    setup = plan.setup
    scales = np.array([setup.units.angle_scale if j.revolute else setup.units.length_scale
                       for j in setup.robot.joints])
    length = setup.units.length_scale
    model = setup.model
    rows = []
    for pose, candidate in enumerate(plan.candidates, start=1):
        for k, q in enumerate(candidate.joints):
            name = candidate.points[k] if candidate.points else None
            socket = candidate.sockets[name] / length if name is not None else None
            rows.append(model.plan_row(pose, list(q / scales), name, socket))
    return rows


def write_plan(plan: Plan, path: str | Path) -> None:
    """Write the plan table to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        write_table(staging, plan_columns(plan), plan_rows(plan))
