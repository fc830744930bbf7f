"""A plan as a dataset: the readings it asks for with the values the nominal robot would
give, so the calibration engine (``robocal_casadi.calibration``) can judge it.

For tracker points the instrument frame is taken as the world frame; for the sphere, the
laser readings are the nominal stand-offs the planner aimed at.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal_casadi.calibration import Problem, analyse_identifiability
from robocal_casadi.datasets import Dataset
from robocal_casadi.kinematics import Kinematics
from robocal_casadi.measurement import model_for

from .candidates import Candidate


def planned_dataset(dataset: Dataset, candidates, kinematics: Kinematics | None = None) -> Dataset:
    """``dataset`` with its rows replaced by those of ``candidates`` (nominal readings)."""
    candidates: list[Candidate] = list(candidates)
    Q = np.vstack([c.joints for c in candidates])
    kinematics = kinematics or Kinematics(dataset.robot)
    if dataset.kind == "tracker_points":
        measured = kinematics.points(Q, dataset.target)
        return replace(dataset, joints=Q, measured=measured, extras={})
    if dataset.kind == "sphere_laser":
        distance = np.concatenate([c.distance for c in candidates])
        return replace(dataset, joints=Q, distance=distance, flange_poses=None, extras={})
    poses = np.concatenate([np.full(len(c.joints), k + 1) for k, c in enumerate(candidates)])
    points = tuple(p for c in candidates for p in c.points)
    return replace(dataset, joints=Q, pose=poses, point=points, extras={})


def engine_identifiability(dataset: Dataset, candidates, names=None):
    """The engine's ``Identifiability`` of the plan made of ``candidates`` at the nominal
    robot (``names``: the parameters to judge; default all robot and mounted ones)."""
    planned = planned_dataset(dataset, candidates)
    problem = Problem(planned.robot, [model_for(planned, "plan")])
    return analyse_identifiability(problem, problem.initial(), names)
