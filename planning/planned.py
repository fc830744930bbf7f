"""A plan as a dataset: the readings it asks for with the values the nominal robot would
give, so the calibration engine (``robocal_casadi.calibration``) can judge it.

The measurement model fills them in (``planned_dataset``): tracker positions in an
instrument frame taken as the world frame, laser readings at the nominal stand-offs the
planner aimed at, touches by placement and socket.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from robocal_casadi.calibration import Problem, analyse_identifiability
from robocal_casadi.instruments import instrument, model_for
from robocal_casadi.instruments.datasets import Dataset
from robocal_casadi.model.kinematics import Kinematics

from .candidates import Candidate


def planned_dataset(dataset: Dataset, candidates: Iterable[Candidate],
                    kinematics: Kinematics | None = None) -> Dataset:
    """``dataset`` with its rows replaced by those of ``candidates`` (nominal readings)."""
    candidates = list(candidates)
    Q = np.vstack([c.joints for c in candidates])
    kinematics = kinematics or Kinematics(dataset.robot)
    poses = np.concatenate([np.full(len(c.joints), k + 1) for k, c in enumerate(candidates)])
    points = tuple(p for c in candidates for p in c.points)
    distance = (np.concatenate([c.distance for c in candidates])
                if all(c.distance is not None for c in candidates) else None)
    return instrument(dataset.kind, file=dataset.path).model.planned_dataset(
        dataset, Q, kinematics, pose=poses, point=points, distance=distance)


def engine_identifiability(dataset: Dataset, candidates, names=None):
    """The engine's ``Identifiability`` of the plan made of ``candidates`` at the nominal
    robot (``names``: the parameters to judge; default all robot and mounted ones)."""
    planned = planned_dataset(dataset, candidates)
    problem = Problem(planned.robot, [model_for(planned, "plan")])
    return analyse_identifiability(problem, problem.initial(), names)
