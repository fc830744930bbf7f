"""Tracking: keep the tool facing a moving target, level with the worktable.

The method and its source: docs/methods.md#tracking.

``goal`` the method's chain of frames, ``problem`` the per-cycle NLP in CasADi, ``solver``
its real-time and reference solvers, ``tracker`` the ``Tracker`` a control loop uses,
``job`` the tracking job file of the command line.
"""

from .goal import (
                   R_B,
                   facing_pose,
                   goal_pose,
                   level_turn,
                   observation_for,
                   target_in_end,
                   target_in_world,
)
from .problem import TrackingProblem
from .solver import GaussNewtonSolver, NlpsolSolver, SolveOutcome
from .tracker import STATUSES, Tracker, TrackStep

__all__ = [
    "GaussNewtonSolver", "NlpsolSolver", "R_B", "STATUSES", "SolveOutcome", "TrackStep",
    "Tracker", "TrackingProblem", "facing_pose", "goal_pose", "level_turn", "observation_for",
    "target_in_end",
    "target_in_world",
]
