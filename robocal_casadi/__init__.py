"""robocal_casadi: kinematic calibration, diagnosis, experiment design and tracking.

The front door, in the files' units (``api``): ``load_robot``, ``load_dataset``, ``fk``,
``calibrate``, ``plan``, ``track``, ``compensate``, each running what its ``robocal`` verb
runs. The engine's own classes (SI inside) are re-exported beside them.

The names are loaded on first use (``robocal_casadi.calibrate`` imports the calibration
then), so that ``import robocal_casadi`` and the ``robocal`` command start in
milliseconds: a command answers Ctrl-C in its own words from its first moments, before
the numerical libraries (CasADi, SciPy, pinocchio) are imported.
"""

# First: a worker process of a command must not answer Ctrl-C.
from .common import workers  # noqa: F401, I001

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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
    from .errors import InputError, RobocalError, SolverError
    from .instruments.datasets import ArtifactTouches, SphereLaser, TrackerPoints
    from .instruments.simulate import simulate
    from .job.compensation import Compensation
    from .model.ik import inverse_kinematics
    from .model.kinematics import Kinematics
    from .model.parameters import ParameterRegistry
    from .model.robot import Frame, Joint, Robot, save_robot
    from .results import CalibrationResult
    from .tracking import Tracker, TrackStep
    from .tracking.run import TrackedJob

# public name -> the module (relative to this package) that defines it
_HOMES = {
    **dict.fromkeys(("Commands", "PlannedTable", "calibrate", "compensate", "fk",
                     "load_dataset", "load_robot", "plan", "track"), ".api"),
    "Units": ".common.units", "Compensation": ".job.compensation",
    "CalibrationResult": ".results",
    **dict.fromkeys(("InputError", "RobocalError", "SolverError"), ".errors"),
    **dict.fromkeys(("ArtifactTouches", "SphereLaser", "TrackerPoints"),
                    ".instruments.datasets"),
    "simulate": ".instruments.simulate", "inverse_kinematics": ".model.ik",
    "Kinematics": ".model.kinematics", "ParameterRegistry": ".model.parameters",
    **dict.fromkeys(("Frame", "Joint", "Robot", "save_robot"), ".model.robot"),
    "Tracker": ".tracking", "TrackStep": ".tracking", "TrackedJob": ".tracking.run",
}

__all__ = [
    "ArtifactTouches", "CalibrationResult", "Commands", "Compensation", "Frame", "InputError",
    "Joint", "Kinematics", "ParameterRegistry", "PlannedTable", "Robot", "RobocalError",
    "SolverError", "SphereLaser", "TrackStep", "TrackedJob", "Tracker", "TrackerPoints",
    "Units", "calibrate", "compensate", "fk", "inverse_kinematics", "load_dataset",
    "load_robot", "plan", "save_robot", "simulate", "track",
]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    """A public name, imported from its home module on first use (then cached here)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
