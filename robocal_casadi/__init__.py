"""robocal_casadi: kinematic calibration, diagnosis, experiment design and tracking.

The front door, in the files' units (``api``): ``load_robot``, ``load_dataset``, ``fk``,
``calibrate``, ``plan``, ``track``, ``compensate``, each running what its ``robocal`` verb
runs. The engine's own classes (SI inside) are re-exported beside them.
"""

# First, before the heavy imports: a worker process of a command must not answer Ctrl-C.
from .common import workers  # noqa: F401, I001
from .api import (
    Commands,
    PlannedTable,
    calibrate,
    compensate,
    fk,
    load_dataset,
    load_robot,
    plan,
    track,
)
from .common.units import Units
from .job.compensation import Compensation
from .results import CalibrationResult
from .errors import InputError, RobocalError, SolverError
from .instruments.datasets import ArtifactTouches, SphereLaser, TrackerPoints
from .instruments.simulate import simulate
from .model.ik import inverse_kinematics
from .model.kinematics import Kinematics
from .model.parameters import ParameterRegistry
from .model.robot import Frame, Joint, Robot, save_robot
from .tracking import Tracker, TrackStep
from .tracking.run import TrackedJob

__all__ = [
    "ArtifactTouches", "CalibrationResult", "Commands", "Compensation", "Frame", "InputError",
    "Joint", "Kinematics", "ParameterRegistry", "PlannedTable", "Robot", "RobocalError",
    "SolverError", "SphereLaser", "TrackStep", "TrackedJob", "Tracker", "TrackerPoints",
    "Units", "calibrate", "compensate", "fk", "inverse_kinematics", "load_dataset",
    "load_robot", "plan", "save_robot", "simulate", "track",
]
__version__ = "0.1.0"
