"""robocal_casadi: kinematic calibration, diagnosis, experiment design and tracking.

The public API is re-exported here; see the README for a worked example.
"""

# First, before the heavy imports: a worker process of a command must not answer Ctrl-C.
from . import workers  # noqa: F401, I001
from .calibration import calibrate
from .compensation import compensate
from .datasets import ArtifactTouches, SphereLaser, TrackerPoints, load_dataset
from .errors import InputError, RobocalError, SolverError
from .ik import inverse_kinematics
from .kinematics import Kinematics
from .parameters import ParameterRegistry
from .results import CalibrationResult
from .robot import Frame, Joint, Robot, load_robot, save_robot
from .simulate import simulate
from .tracking import Tracker, TrackStep
from .units import Units

__all__ = [
    "ArtifactTouches", "CalibrationResult", "Frame", "InputError", "Joint", "Kinematics",
    "ParameterRegistry", "Robot", "RobocalError", "SolverError", "SphereLaser", "TrackStep",
    "Tracker", "TrackerPoints", "Units", "calibrate", "compensate", "inverse_kinematics",
    "load_dataset", "load_robot", "save_robot", "simulate",
]
__version__ = "0.1.0"
