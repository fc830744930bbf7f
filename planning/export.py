"""A scan as a time-stamped table, and a program's text written all or nothing.

The programs a controller runs (URScript, KRL, RAPID, ...) are formats of
``robocal_casadi.formats``, each in its own module.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal_casadi.common.output import atomic_file
from robocal_casadi.common.table import write_table
from robocal_casadi.model.transforms import quaternion_from_matrix


def write_text(text: str, path: str | Path) -> None:
    """Write ``text`` to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        Path(staging).write_text(text)


def scan_columns(scan) -> list[str]:
    """``t``, then joints (or the pendant pose columns, sensor only), then ``distance``."""
    if scan.sensor_only:
        return ["t", "x", "y", "z", "qw", "qx", "qy", "qz", "distance"]
    return ["t"] + [f"q{i}" for i in range(1, scan.setup.robot.dof + 1)] + ["distance"]


def scan_rows(scan) -> list[list]:
    """Rows of the scan table in the dataset's units; ``distance`` left empty."""
    setup = scan.setup
    length = setup.units.length_scale
    rows = []
    if scan.sensor_only:
        for t, T in zip(scan.times, scan.flange_poses):
            rows.append([t, *(T[:3, 3] / length), *quaternion_from_matrix(T[:3, :3]), np.nan])
        return rows
    scales = np.array([setup.units.angle_scale if j.revolute else length
                       for j in setup.robot.joints])
    for t, q in zip(scan.times, scan.joints):
        rows.append([t, *(q / scales), np.nan])
    return rows


def write_scan(scan, path: str | Path) -> None:
    """Write the scan table to ``path`` all or nothing."""
    with atomic_file(path) as staging:
        write_table(staging, scan_columns(scan), scan_rows(scan))
