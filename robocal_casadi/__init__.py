"""robocal_casadi: kinematic calibration, diagnosis, experiment design and tracking.

The public API is re-exported here; see the README for a worked example.
"""

from .datasets import ArtifactTouches, SphereLaser, TrackerPoints, load_dataset
from .errors import InputError, RobocalError, SolverError
from .kinematics import Kinematics
from .parameters import ParameterRegistry
from .robot import Frame, Joint, Robot, load_robot, save_robot
from .units import Units

__all__ = [
    "ArtifactTouches", "Frame", "InputError", "Joint", "Kinematics", "ParameterRegistry",
    "Robot", "RobocalError", "SolverError", "SphereLaser", "TrackerPoints", "Units",
    "load_dataset", "load_robot", "save_robot",
]
__version__ = "0.1.0"
