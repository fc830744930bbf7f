"""Fleet calibration: many robots, one command, each robot one task on a Dask cluster,
and a summary of what the fleet reveals.

``load_fleet`` reads the fleet file; ``run_fleet`` calibrates every robot on a cluster
(``robot_task.calibrate_robot`` per robot, resumable); ``summarise`` compares the robots
(``outliers``) and ``page.render`` draws ``fleet.html``.
"""

from .outliers import Finding, Move, Spread, high_outliers, spread
from .robot_task import RECORD, RobotOutcome, Settings, calibrate_robot
from .spec import Fleet, FleetRobot, load_fleet
from .summary import FleetSummary, previous_parameters, summarise

__all__ = [
    "RECORD", "Finding", "Fleet", "FleetRobot", "FleetSummary", "Move", "RobotOutcome",
    "Settings", "Spread", "calibrate_robot", "high_outliers", "load_fleet",
    "previous_parameters", "run_fleet", "spread", "summarise",
]


def run_fleet(*args, **kwargs):
    """See ``engine.run_fleet`` (imported on use: it needs Dask)."""
    from .engine import run_fleet as run

    return run(*args, **kwargs)
