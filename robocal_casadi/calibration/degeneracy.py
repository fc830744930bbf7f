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

from ..errors import InputError
from ..instruments import instrument
from ..instruments.dataset import same_rows


def check_dataset(dataset) -> None:
    """Refuse ``dataset`` when its rows carry no usable information (``InputError``).

    Recognised here: every reading at the same joints; then the kind's own checks
    (``Instrument.check``: e.g. two related sockets of an artifact touched at one and the
    same joint reading, a tracker that measured the same point in every row).
    """
    joints = dataset.joints
    if joints is None or len(joints) == 0:
        return
    joints = np.asarray(joints, dtype=float)
    where = dataset.data_path if dataset.data_path is not None else dataset.path
    if same_rows(joints):
        units = dataset.units
        scales = [units.angle_scale if j.revolute else units.length_scale
                  for j in dataset.robot.joints]
        shown = ", ".join(f"{v / k:.6g}" for v, k in zip(joints[0], scales))
        raise InputError(f"all {len(joints)} readings were taken at the same joints "
                         f"[{shown}] ({units.angle}, {units.length}): the robot never moved, "
                         f"so the data say nothing about its geometry; move it between "
                         f"readings", file=where)
    instrument(dataset.kind, file=dataset.path).check(dataset, joints, where)


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
