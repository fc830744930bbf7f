"""robocal_casadi: kinematic calibration, diagnosis, experiment design and tracking.

The public API is re-exported here; see the README for a worked example.
"""

# First, before the heavy imports: a worker process of a command must not answer Ctrl-C.
from .common import workers  # noqa: F401, I001
from .calibration import calibrate
from .common.units import Units
from .job.compensation import compensate
from .results import CalibrationResult
from .errors import InputError, RobocalError, SolverError
from .instruments.datasets import ArtifactTouches, SphereLaser, TrackerPoints, load_dataset
from .instruments.simulate import simulate
from .model.ik import inverse_kinematics
from .model.kinematics import Kinematics
from .model.parameters import ParameterRegistry
from .model.robot import Frame, Joint, Robot, load_robot, save_robot
from .tracking import Tracker, TrackStep

__all__ = [
    "ArtifactTouches", "CalibrationResult", "Frame", "InputError", "Joint", "Kinematics",
    "ParameterRegistry", "Robot", "RobocalError", "SolverError", "SphereLaser", "TrackStep",
    "Tracker", "TrackerPoints", "Units", "calibrate", "compensate", "inverse_kinematics",
    "load_dataset", "load_robot", "save_robot", "simulate",
]
__version__ = "0.1.0"
