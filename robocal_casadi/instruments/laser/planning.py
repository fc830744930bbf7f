"""What the planner needs of a laser-on-a-sphere set-up (``planning.setup``): the laser,
the sphere, the usable range of readings and the largest angle of incidence."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import InputError
from ...fields import vector
from .reader import SphereLaser


def setup_fields(dataset: SphereLaser, options: Any) -> dict:
    """The plan set-up's fields of a laser dataset; ``options`` reads the ``planning``
    block (``planning.setup.PlanningOptions``). The file's guesses are required."""
    path = dataset.path
    for value, key in ((dataset.centre_guess, "sphere.centre_guess"),
                       (dataset.origin_guess, "laser.origin_guess"),
                       (dataset.direction_guess, "laser.direction_guess")):
        if value is None:
            raise InputError("planning needs this guess; add it to the dataset file",
                             file=path, where=key)
    laser_range = (0.05, 0.30)
    if "laser_range" in options.options:
        lo, hi = vector(options.options["laser_range"], 2, file=path,
                        where="planning.laser_range")
        if not 0 <= lo < hi:
            raise InputError(f"expected 0 <= min < max, got [{lo}, {hi}]", file=path,
                             where="planning.laser_range")
        laser_range = (lo * options.units.length_scale, hi * options.units.length_scale)
    return dict(offset=np.asarray(dataset.origin_guess, float),
                axis=np.asarray(dataset.direction_guess, float),
                centre=np.asarray(dataset.centre_guess, float), radius=dataset.radius,
                laser_range=laser_range, sensor_only=dataset.flange_poses is not None,
                max_incidence=options.option("max_incidence", np.radians(45.0),
                                             options.units.angle_scale))
