"""Data that cannot calibrate anything, found before the numbers turn into NaN.

A calibration needs the robot to move between readings and the instrument to see it
move. Some tables break that so completely that the residual itself is undefined (two
sockets touched at the same joints coincide, and the length of a zero vector has no
derivative) or the fit is meaningless (a tracker that read the same point while the
arm moved). ``check_dataset`` refuses such a dataset with one line naming its table and
what is degenerate; ``check_finite`` is the last guard, naming the dataset whose
residual or Jacobian is not finite where no simpler cause was recognised.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..datasets import ArtifactTouches, TrackerPoints
from ..errors import InputError


def _same_rows(values: np.ndarray) -> bool:
    """Every row of ``values`` (N x k) equal to the first, bit for bit."""
    return len(values) > 1 and bool(np.all(values == values[0]))


def check_dataset(dataset) -> None:
    """Refuse ``dataset`` when its rows carry no usable information (``InputError``).

    Recognised: every reading at the same joints; in a placement of an artifact or bar,
    two related sockets touched only at one and the same joint reading (they coincide);
    a tracker that measured the same point in every row while the joints moved.
    """
    joints = dataset.joints
    if joints is None or len(joints) == 0:
        return
    joints = np.asarray(joints, dtype=float)
    where = dataset.data_path if dataset.data_path is not None else dataset.path
    if _same_rows(joints):
        units = dataset.units
        scales = [units.angle_scale if j.revolute else units.length_scale
                  for j in dataset.robot.joints]
        shown = ", ".join(f"{v / k:.6g}" for v, k in zip(joints[0], scales))
        raise InputError(f"all {len(joints)} readings were taken at the same joints "
                         f"[{shown}] ({units.angle}, {units.length}): the robot never moved, "
                         f"so the data say nothing about its geometry; move it between "
                         f"readings", file=where)
    if isinstance(dataset, ArtifactTouches):
        _check_sockets(dataset, joints, where)
    measured = getattr(dataset, "measured", None)
    if isinstance(dataset, TrackerPoints) and measured is not None and _same_rows(
            np.asarray(measured, dtype=float)):
        raise InputError(f"every one of the {len(measured)} measured points is the same "
                         f"(x, y, z equal in all rows) while the joints move: the instrument "
                         f"did not follow the target", file=where)


def _check_sockets(dataset, joints: np.ndarray, where) -> None:
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
            if a in touched and b in touched and _same_rows(rows):
                raise InputError(f"sockets {a} and {b} were touched at the same joints, so "
                                 f"they coincide and their known relation cannot hold: "
                                 f"touch each socket where it is", file=where,
                                 where=f"pose {int(placement)}")


def check_finite(models: Sequence, residual: np.ndarray, jacobian: np.ndarray,
                 stage: str) -> None:
    """Refuse non-finite numbers in ``residual`` or ``jacobian`` (stacked over ``models``),
    naming the first dataset they come from; ``stage`` says where (e.g. "the nominal fit")."""
    bad = ~np.isfinite(residual) | ~np.all(np.isfinite(jacobian), axis=1)
    if not bad.any():
        return
    start = 0
    for model in models:
        size = model.residual_size()
        rows = np.flatnonzero(bad[start:start + size])
        start += size
        if rows.size:
            dataset = model.dataset
            where = dataset.data_path if dataset.data_path is not None else dataset.path
            raise InputError(f"{rows.size} of {size} residuals (or their derivatives) are not "
                             f"finite at {stage}: the data are degenerate (repeated or "
                             f"coinciding readings, or values far outside the robot's reach)",
                             file=where)
    raise InputError(f"the residuals are not finite at {stage}: degenerate data")
