"""The tracking job file (docs/formats.md#tracking-job): reading and checking.

```yaml
kind: tracking
robot: robot.yaml
units: {length: mm, angle: deg}
camera: {xyz: [a, b, c]}      # camera origin in the end frame, axes parallel to it
standoff: 300.0               # Z: the target stays at (0, 0, Z) in the end frame
up: [0, 0, 1]                 # optional: worktable normal in the world frame
max_velocity: 180             # optional: joint speed limit, one value or one per joint,
                              # job's angle (length for prismatic joints) unit per second
data: observations.csv        # time,q1..qn,x,y,z,roll,pitch,yaw in the job's units
```

Optional, for cameras and marker detectors that describe things their own way
(``tracking.conventions``):

* ``camera: {xyz: [...], rpy: [r, p, y]}`` or ``camera: {xyz: [...], quaternion: [qw, qx,
  qy, qz]}``: the camera axes turned on the end frame (a hand-eye calibration), ``rpy``
  in the job's angle unit, ``R = Rz(y) Ry(p) Rx(r)``;
* ``marker_convention: opencv``: ``x, y, z`` is OpenCV's ``tvec`` and the orientation the
  marker's own (ArUco: x right, y up, z out of its face), given as ``rx, ry, rz`` (the
  ``rvec`` Rodrigues vector, in the job's angle unit) or ``qw, qx, qy, qz``; the default
  ``method`` reads ``roll, pitch, yaw`` (or ``qw, qx, qy, qz``) of the method's target
  frame.

Everything is returned in SI, the observations as the method's ``(x, y, z, roll,
pitch, yaw)`` for a camera at ``camera.xyz`` with axes parallel to the end frame (what
``Tracker`` takes by default); the job's units are kept for writing the joints back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..common.fields import (
    check_keys,
    check_magnitude,
    cut,
    load_yaml,
    mapping,
    quantities,
    quantity,
    referenced_file,
    require,
    vector,
)
from ..common.table import read_table
from ..common.units import Units, units_of
from ..errors import InputError
from ..instruments.datasets import joint_readings as checked_joint_readings
from ..instruments.datasets import referenced_robot
from ..model.robot import Robot
from ..model.transforms import matrix_from_quaternion, pose_from_xyz_rpy
from .conventions import (
    MARKER_CONVENTIONS,
    MarkerConvention,
    method_observation,
    observation_rotation,
)
from .tracker import unit_up

KEYS = ("kind", "robot", "units", "camera", "standoff", "up", "data", "marker_convention",
        "max_velocity")
OBSERVATION_COLUMNS = ("x", "y", "z", "roll", "pitch", "yaw")
#: Orientation columns each marker convention accepts, in order of preference.
ORIENTATION_COLUMNS = {"method": (("roll", "pitch", "yaw"), ("qw", "qx", "qy", "qz")),
                       "opencv": (("rx", "ry", "rz"), ("qw", "qx", "qy", "qz"))}
#: A quaternion whose norm is off 1 by more than this is refused, not normalised.
QUATERNION_NORM_TOLERANCE = 1e-3


@dataclass(frozen=True)
class TrackingJob:
    """A tracking job in SI.

    ``camera_xyz`` [m] and ``camera_rotation`` (3x3) the camera in the end frame;
    ``marker_convention`` as the job gave it; ``standoff`` [m]; ``up`` unit, world frame;
    ``time`` (N,) [s]; ``joints`` (N x n) capture joints [rad or m]; ``observations``
    (N x 6) the method's observation for a camera at ``camera_xyz`` with axes parallel to
    the end frame: ``x, y, z`` [m], ``roll, pitch, yaw`` [rad].
    """

    path: Path
    robot: Robot
    robot_path: Path
    units: Units
    camera_xyz: np.ndarray
    camera_rotation: np.ndarray
    marker_convention: str
    standoff: float
    up: np.ndarray
    data_path: Path
    time: np.ndarray = field(repr=False)
    joints: np.ndarray = field(repr=False)
    observations: np.ndarray = field(repr=False)
    max_velocity: np.ndarray | None = None  # (n) [rad/s or m/s], None: no limit given

    @property
    def rows(self) -> int:
        return len(self.time)

    def __repr__(self) -> str:
        return (f"TrackingJob({self.path.name!r}, robot={self.robot.name!r}, rows={self.rows}, "
                f"camera_xyz={list(self.camera_xyz)} m, standoff={self.standoff} m, "
                f"up={list(self.up)})")


def load_tracking_job(path: str | Path, *, robot: Robot | None = None,
                      allow_outside_data: bool = False) -> TrackingJob:
    """Read and check a tracking job and its observation table.

    ``robot`` replaces the robot file the job names (e.g. a calibrated robot). Every
    problem raises ``InputError`` naming the file, the key or line, and what is wrong.
    """
    path = Path(path)
    content = load_yaml(path, what="tracking job")
    kind = require(content, "kind", file=path)
    if kind != "tracking":
        raise InputError(f"expected kind 'tracking', got {cut(kind)}", file=path, where="kind")
    check_keys(content, KEYS, file=path)
    units = units_of(content, file=path)
    L = units.length_scale
    robot_path, robot = referenced_robot(content, path, robot)
    if robot.dof < 6:
        raise InputError(f"tracking needs at least 6 joints; robot {robot.name!r} has "
                         f"{robot.dof}", file=path, where="robot")
    camera = mapping(require(content, "camera", file=path), file=path, where="camera",
                     hint="{xyz: [a, b, c]}")
    check_keys(camera, ("xyz", "rpy", "quaternion"), file=path, where="camera")
    camera_xyz = np.array(quantities(require(camera, "xyz", file=path, where="camera"), 3, L,
                                     "length", file=path, where="camera.xyz", unit=units.length))
    camera_rotation = _camera_rotation(camera, units, path)
    convention = _marker_convention(content, path)
    standoff = quantity(require(content, "standoff", file=path), L, "length", file=path,
                        where="standoff", unit=units.length)
    if standoff <= 0:
        raise InputError(f"the standoff must be a positive length, got {standoff / L:g} "
                         f"{units.length}", file=path, where="standoff")
    up = _up(content, path)
    data_path = referenced_file(content, "data", file=path, allow_outside=allow_outside_data)
    if not data_path.is_file() and not data_path.is_symlink():  # a loop: named below
        raise InputError(f"observation table {data_path} not found", file=path, where="data")
    table = read_table(data_path, required=("time", "x", "y", "z"))
    orientation = _orientation_columns(table, convention, data_path)
    joints = checked_joint_readings(table, robot, units, set(), robot_path)
    time = _times(table, data_path)
    observations = _observations(table, orientation, convention, camera_xyz, camera_rotation,
                                 units, data_path)
    return TrackingJob(path=path, robot=robot, robot_path=robot_path, units=units,
                       camera_xyz=camera_xyz, camera_rotation=camera_rotation,
                       marker_convention=convention, standoff=standoff, up=up,
                       data_path=data_path, time=time, joints=joints,
                       observations=observations,
                       max_velocity=_max_velocity(content.get("max_velocity"), robot, units,
                                                  path))


def _marker_convention(content: dict, path: Path) -> MarkerConvention:
    """``marker_convention`` (default ``method``), one of ``MARKER_CONVENTIONS``."""
    given = content.get("marker_convention")
    given = "method" if given is None else given
    convention = next((c for c in MARKER_CONVENTIONS if c == given), None)
    if convention is None:
        raise InputError(f"expected one of {', '.join(MARKER_CONVENTIONS)}, got "
                         f"{str(given)[:40]!r}", file=path, where="marker_convention")
    return convention


def _up(content: dict, path: Path) -> np.ndarray:
    """The worktable normal ``up`` (default +z) as a unit vector in the world frame."""
    up_value = content.get("up")
    up = np.array(vector([0.0, 0.0, 1.0] if up_value is None else up_value, 3, file=path,
                         where="up"))
    largest = float(np.abs(up).max())
    return unit_up(up / largest if largest > 0 else up, file=path)  # scaled first: no overflow


def _times(table, data_path: Path) -> np.ndarray:
    """The ``time`` column [s], refused where it goes backwards."""
    time = table.numbers("time")
    backwards = np.flatnonzero(np.diff(time) < 0)
    if backwards.size:
        row = int(backwards[0]) + 1
        raise InputError(f"time goes backwards ({time[row - 1]:g} s, then {time[row]:g} s): rows "
                         "are solved in order, as captured", file=data_path,
                         where=f"line {table.line(row)}")
    return time


def _observations(table, orientation: tuple[str, ...], convention: MarkerConvention,
                  camera_xyz: np.ndarray, camera_rotation: np.ndarray, units: Units,
                  data_path: Path) -> np.ndarray:
    """The observations (N x 6) as the method's ``x, y, z`` [m], ``roll, pitch, yaw``
    [rad] for a camera at ``camera_xyz`` with axes parallel to the end frame."""
    L = units.length_scale
    angular = len(orientation) == 3  # rpy or rvec, in the job's angle unit
    names = ("x", "y", "z", *orientation)
    scales = np.array([L] * 3 + [units.angle_scale if angular else 1.0] * len(orientation))
    raw = np.column_stack([table.numbers(c) for c in names])
    values = raw * scales
    for col, name in enumerate(names):
        if col >= 3 and not angular:
            continue
        kind_of = "length" if col < 3 else "angle"
        for row in np.flatnonzero(np.abs(values[:, col]) > 1e4)[:1]:
            check_magnitude(values[row, col], kind_of, file=data_path,
                            where=f"line {table.line(int(row))}, column {name!r}",
                            shown=raw[row, col], unit=units.unit_name(kind_of))
    if angular and convention == "method" and np.array_equal(camera_rotation, np.eye(3)):
        return values  # the method's own form: nothing to convert
    observations = np.empty((len(values), 6))
    for row, value in enumerate(values):
        if angular:
            rotation = observation_rotation(value, convention)
        else:
            rotation = matrix_from_quaternion(_unit_quaternion(
                value[3:], data_path, f"line {table.line(row)}, columns qw..qz"))
        observations[row] = method_observation(camera_xyz, camera_rotation, value[:3],
                                               rotation, convention)
    return observations


def _max_velocity(value, robot: Robot, units: Units, path: Path) -> np.ndarray | None:
    """``max_velocity`` (one value or one per joint, job units per second) in SI, or None."""
    if value is None:
        return None
    n = robot.dof
    raw = np.array(vector(value if isinstance(value, list) else [value] * n, n, file=path,
                          where="max_velocity"))
    if not (np.all(np.isfinite(raw)) and np.all(raw > 0)):
        raise InputError(f"joint speed limits must be positive numbers, got {cut(value)}",
                         file=path, where="max_velocity")
    scales = np.array([units.angle_scale if j.revolute else units.length_scale
                       for j in robot.joints])
    return raw * scales


def _unit_quaternion(value, file, where: str) -> np.ndarray:
    """``qw, qx, qy, qz`` normalised; a norm off 1 by more than the tolerance is refused."""
    q = np.asarray(value, dtype=float)
    norm = float(np.linalg.norm(q))
    if not abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE:
        raise InputError(f"a quaternion must have norm 1, got {norm:.6g}", file=file, where=where)
    return q / norm


def _camera_rotation(camera: dict, units: Units, path: Path) -> np.ndarray:
    """The camera axes in the end frame (3x3) from ``camera.rpy`` or ``camera.quaternion``."""
    if camera.get("rpy") is not None and camera.get("quaternion") is not None:
        raise InputError("give the camera rotation once: rpy or quaternion, not both",
                         file=path, where="camera")
    if camera.get("rpy") is not None:
        rpy = quantities(camera["rpy"], 3, units.angle_scale, "angle", file=path,
                         where="camera.rpy", unit=units.angle)
        return pose_from_xyz_rpy([0.0, 0.0, 0.0], rpy)[:3, :3]
    if camera.get("quaternion") is not None:
        q = vector(camera["quaternion"], 4, file=path, where="camera.quaternion")
        return matrix_from_quaternion(_unit_quaternion(q, path, "camera.quaternion"))
    return np.eye(3)


def _orientation_columns(table, convention: str, file: Path) -> tuple[str, ...]:
    """The orientation columns ``table`` carries for ``convention`` (exactly one set)."""
    options = ORIENTATION_COLUMNS[convention]
    present = [names for names in options if all(table.has(n) for n in names)]
    if len(present) == 1:
        return present[0]
    listed = " or ".join(",".join(names) for names in options)
    if not present:
        missing = ", ".join(repr(n) for n in options[0] if not table.has(n))
        raise InputError(f"missing column {missing}: expected the orientation columns "
                         f"{listed} (marker_convention {convention})", file=file,
                         where="line 1")
    raise InputError(f"both {listed} are present: keep one orientation", file=file,
                     where="line 1")
