"""The calibration engine: the least-squares problem over the robot's parameters, its
solvers, the identifiability analysis, data selection, the calibration front door and the
diagnosis of non-geometric effects.

The public API is re-exported here flat; the submodules hold one concept each.
"""

from .diagnosis import Diagnosis
from .identifiability import PRACTICAL_TOLERANCE, analyse
from .identification import (
                             analyse_identifiability,
                             calibrate,
                             evaluate,
                             models_for,
                             refit_placement,
)
from .problem import Problem
from .selection import Selection, select_by_condition
from .solver import METHODS, Solution, solve

__all__ = [
    "METHODS",
    "PRACTICAL_TOLERANCE",
    "Diagnosis",
    "Problem",
    "Selection",
    "Solution",
    "analyse",
    "analyse_identifiability",
    "calibrate",
    "evaluate",
    "models_for",
    "refit_placement",
    "select_by_condition",
    "solve",
]
