"""The tracking job file (CONTRACT.md "Tracking job"): reading and checking.

```yaml
kind: tracking
robot: robot.yaml
units: {length: mm, angle: deg}
camera: {xyz: [a, b, c]}      # camera origin in the end frame, axes parallel to it
standoff: 300.0               # Z: the target stays at (0, 0, Z) in the end frame
up: [0, 0, 1]                 # optional: worktable normal in the world frame
data: observations.csv        # time,q1..qn,x,y,z,roll,pitch,yaw in the job's units
```

Everything is returned in SI; the job's units are kept for writing the joints back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..datasets import joint_readings as checked_joint_readings
from ..datasets import referenced_robot
from ..errors import InputError
from ..fields import load_yaml, number, require, vector
from ..robot import Robot
from ..table import read_table
from ..units import Units, parse_units
from .tracker import unit_up

KEYS = ("kind", "robot", "units", "camera", "standoff", "up", "data")
OBSERVATION_COLUMNS = ("x", "y", "z", "roll", "pitch", "yaw")


@dataclass(frozen=True)
class TrackingJob:
    """A tracking job in SI.

    ``camera_xyz`` [m] in the end frame; ``standoff`` [m]; ``up`` unit, world frame;
    ``time`` (N,) [s]; ``joints`` (N x n) capture joints [rad or m]; ``observations``
    (N x 6) target in the camera ``x, y, z`` [m], ``roll, pitch, yaw`` [rad].
    """

    path: Path
    robot: Robot
    robot_path: Path
    units: Units
    camera_xyz: np.ndarray
    standoff: float
    up: np.ndarray
    data_path: Path
    time: np.ndarray = field(repr=False)
    joints: np.ndarray = field(repr=False)
    observations: np.ndarray = field(repr=False)

    @property
    def rows(self) -> int:
        return len(self.time)

    def __repr__(self) -> str:
        return (f"TrackingJob({self.path.name!r}, robot={self.robot.name!r}, rows={self.rows}, "
                f"camera_xyz={list(self.camera_xyz)} m, standoff={self.standoff} m, "
                f"up={list(self.up)})")


def load_tracking_job(path: str | Path, *, robot: Robot | None = None) -> TrackingJob:
    """Read and check a tracking job and its observation table.

    ``robot`` replaces the robot file the job names (e.g. a calibrated robot). Every
    problem raises ``InputError`` naming the file, the key or line, and what is wrong.
    """
    path = Path(path)
    content = load_yaml(path, what="tracking job")
    unknown = sorted(set(content) - set(KEYS))
    if unknown:
        raise InputError(f"unknown key(s) {unknown}; allowed: {list(KEYS)}", file=path,
                         where=unknown[0])
    kind = require(content, "kind", file=path)
    if kind != "tracking":
        raise InputError(f"expected kind 'tracking', got {kind!r}", file=path, where="kind")
    units = parse_units(require(content, "units", file=path), file=path)
    robot_path, robot = referenced_robot(content, path, robot)
    if robot.dof < 6:
        raise InputError(f"tracking needs at least 6 joints; robot {robot.name!r} has "
                         f"{robot.dof}", file=path, where="robot")
    camera = require(content, "camera", file=path)
    if not isinstance(camera, dict):
        raise InputError("expected a mapping {xyz: [a, b, c]}", file=path, where="camera")
    camera_xyz = np.array(vector(require(camera, "xyz", file=path, where="camera"), 3,
                                 file=path, where="camera.xyz")) * units.length_scale
    standoff = number(require(content, "standoff", file=path), file=path, where="standoff")
    if standoff <= 0:
        raise InputError(f"the standoff must be a positive length, got {standoff:g}",
                         file=path, where="standoff")
    up = unit_up(vector(content.get("up", [0.0, 0.0, 1.0]), 3, file=path, where="up"),
                 file=path)
    data_path = path.parent / str(require(content, "data", file=path))
    table = read_table(data_path, required=("time", *OBSERVATION_COLUMNS))
    joints = checked_joint_readings(table, robot, units, set())
    scales = np.array([units.length_scale] * 3 + [units.angle_scale] * 3)
    observations = np.column_stack([table.numbers(c) for c in OBSERVATION_COLUMNS]) * scales
    return TrackingJob(path=path, robot=robot, robot_path=robot_path, units=units,
                       camera_xyz=camera_xyz, standoff=standoff * units.length_scale, up=up,
                       data_path=data_path, time=table.numbers("time"), joints=joints,
                       observations=observations)
