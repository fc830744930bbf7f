"""Measurements the robot can really make, one ``Candidate`` per bar/artifact placement
or per reading, drawn at random from what the robot reaches by the kind's
``Planner.candidates`` (``robocal_casadi/instruments/<kind>/planning.py``): artifacts
placed above the worktable with every socket touched by inverse kinematics, laser poses
aiming the beam at the sphere, tracker configurations facing the instrument.

All positions [m], world frame; joints [rad or m].
"""

from __future__ import annotations

import numpy as np

from robocal_casadi.errors import InputError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.planning import Candidate, reach_radius
from robocal_casadi.instruments.tracker.planning import visible

from .reach import Workspace
from .setup import PlanSetup


def generate(setup: PlanSetup, workspace: Workspace, count: int, rng: np.random.Generator,
             progress=None) -> list[Candidate]:
    """Up to ``count`` feasible candidates for ``setup``'s instrument (fewer only if rare)."""
    planner = instrument(setup.kind, file=setup.path).planner
    if planner is None:
        raise InputError(f"the planner has no candidates for {setup.kind} data",
                         file=setup.path, where="kind")
    return planner.candidates(setup, workspace, count, rng, progress)


__all__ = ["Candidate", "generate", "reach_radius", "visible"]
