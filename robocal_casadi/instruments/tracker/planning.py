"""What the planner needs of a tracker set-up (``planning.setup``): the reflector, where
the tracker stands and the cone it sees the reflector in."""

from __future__ import annotations

from typing import Any

import numpy as np

from .reader import TrackerPoints


def setup_fields(dataset: TrackerPoints, options: Any) -> dict:
    """The plan set-up's fields of a tracker dataset; ``options`` reads the ``planning``
    block (``planning.setup.PlanningOptions``)."""
    return dict(offset=np.asarray(dataset.target, float), instrument=dataset.instrument,
                visibility_cone=options.option("visibility_cone", np.radians(60.0),
                                               options.units.angle_scale))
