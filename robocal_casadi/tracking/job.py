"""The tracking job file (docs/formats.md#tracking-job): reading and checking.

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
from ..fields import (check_keys, check_magnitude, file_name, load_yaml, mapping, quantities,
                      quantity, require, units_of, vector)
from ..robot import Robot
from ..table import read_table
from ..units import Units
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
    kind = require(content, "kind", file=path)
    if kind != "tracking":
        raise InputError(f"expected kind 'tracking', got {kind!r}", file=path, where="kind")
    check_keys(content, KEYS, file=path)
    units = units_of(content, file=path)
    L = units.length_scale
    robot_path, robot = referenced_robot(content, path, robot)
    if robot.dof < 6:
        raise InputError(f"tracking needs at least 6 joints; robot {robot.name!r} has "
                         f"{robot.dof}", file=path, where="robot")
    camera = mapping(require(content, "camera", file=path), file=path, where="camera",
                     hint="{xyz: [a, b, c]}")
    check_keys(camera, ("xyz",), file=path, where="camera")
    camera_xyz = np.array(quantities(require(camera, "xyz", file=path, where="camera"), 3, L,
                                     "length", file=path, where="camera.xyz", unit=units.length))
    standoff = quantity(require(content, "standoff", file=path), L, "length", file=path,
                        where="standoff", unit=units.length)
    if standoff <= 0:
        raise InputError(f"the standoff must be a positive length, got {standoff / L:g} "
                         f"{units.length}", file=path, where="standoff")
    up_value = content.get("up")
    up = np.array(vector([0.0, 0.0, 1.0] if up_value is None else up_value, 3, file=path,
                         where="up"))
    largest = float(np.abs(up).max())
    up = unit_up(up / largest if largest > 0 else up, file=path)  # scaled first: no overflow
    data_path = path.parent / file_name(require(content, "data", file=path), file=path,
                                        where="data")
    if not data_path.is_file():
        raise InputError(f"observation table {data_path} not found", file=path, where="data")
    table = read_table(data_path, required=("time", *OBSERVATION_COLUMNS))
    joints = checked_joint_readings(table, robot, units, set(), robot_path)
    time = table.numbers("time")
    backwards = np.flatnonzero(np.diff(time) < 0)
    if backwards.size:
        row = int(backwards[0]) + 1
        raise InputError(f"time goes backwards ({time[row - 1]:g} s, then {time[row]:g} s): rows "
                         "are solved in order, as captured", file=data_path,
                         where=f"line {table.line(row)}")
    scales = np.array([L] * 3 + [units.angle_scale] * 3)
    raw = np.column_stack([table.numbers(c) for c in OBSERVATION_COLUMNS])
    observations = raw * scales
    for col, name in enumerate(OBSERVATION_COLUMNS):
        kind_of = "length" if col < 3 else "angle"
        for row in np.flatnonzero(np.abs(observations[:, col]) > 1e4)[:1]:
            check_magnitude(observations[row, col], kind_of, file=data_path,
                            where=f"line {table.line(int(row))}, column {name!r}",
                            shown=raw[row, col], unit=units.unit_name(kind_of))
    return TrackingJob(path=path, robot=robot, robot_path=robot_path, units=units,
                       camera_xyz=camera_xyz, standoff=standoff, up=up,
                       data_path=data_path, time=time, joints=joints,
                       observations=observations)
