"""A point laser on the flange measuring a sphere of known radius (``sphere_laser``).

Unknowns (docs/methods.md#point-laser-and-sphere):

* mounted, shared by name: the laser reference point ``laser_x, laser_y, laser_z`` [m]
  and the beam direction ``laser_nx, laser_ny, laser_nz``, both in the flange frame;
* placement, per dataset: the sphere centre ``<label>/sphere_x, _y, _z`` [m], base frame.

Residual per reading ``i`` [m], the distance of the laser point from the sphere surface::

    r_i = || T_i (p0 + l_i n) - c || - R,      n = v / |v|,  v = (laser_nx, laser_ny, laser_nz)

``T_i`` is the flange pose: from the robot model and the joint readings, or, for a table
of pendant poses (``x, y, z, qw, qx, qy, qz``), the pose as read (the robot then plays no
part, ``uses_robot`` is False).

Unit beam direction (``robocal_casadi.model.beam``): the engine treats mounted values as free
unknowns, so the model uses ``n = beam_direction(v) = v / |v|`` (any direction, no pole,
no sign choice) and adds one last residual ``(|v| - 1) * 1 m``. The distance residuals
do not change with ``|v|``, so that row is zero at the solution and only fixes the
length of ``v``: the estimate of ``v`` is a unit vector, its covariance is that of the
constrained direction, and the Jacobian has full rank. ``errors`` leaves that row out.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cached_property

import casadi as ca
import numpy as np

from ...errors import InputError
from ...model.beam import beam_direction, tangent_basis
from ...model.parameters import ParameterRegistry
from ...results import ErrorTerm
from ..model import MeasurementModel, PointsFunction
from .sphere_fit import Scan, SensorFit, fit_dataset, sphere_centre

MOUNTED_NAMES = ("laser_x", "laser_y", "laser_z", "laser_nx", "laser_ny", "laser_nz")
GAUGE_LENGTH = 1.0  # [m] weight of the |v| = 1 row


class SphereLaserModel(MeasurementModel):
    """Residuals of point-laser readings of a sphere; see the module docstring."""

    kind = "sphere_laser"
    table = "scan.csv"
    reach = "beam"
    error_title = "distance from the sphere surface"
    reading_name = "laser reading"
    instrument_name = "laser"
    default_noise = (1e-5, 0.0)  # [m] a triangulating point laser's distance reading
    measured_columns = ("distance",)
    sphere = True
    invisible_reason = "has no effect on the laser points' distances from the sphere centre"
    absorbed_reason = ("absorbed by the unknown sphere centre (distances from one point do not "
                       "change when the whole robot moves or turns about it)")

    def __init__(self, dataset, label: str):
        super().__init__(dataset, label)
        if dataset.distance is None:
            raise InputError("sphere_laser dataset has no readings (no data table)",
                             file=dataset.path, where="data")
        self.count = len(dataset.distance)
        self._placement = ParameterRegistry(
            tuple(f"{self.placement_prefix}/sphere_{axis}" for axis in "xyz"), ("length",) * 3)
        self._scan = None if dataset.flange_poses is None else Scan.from_poses(
            dataset.flange_poses, dataset.distance, dataset.radius)

    def _pendant_scan(self) -> Scan:
        """The flange poses of sensor-only data (pendant readings); joint data have none."""
        if self._scan is None:
            raise TypeError(f"{self.label}: joint readings carry no pendant flange poses")
        return self._scan

    # ------------------------------------------------------------------ unknowns

    @property
    def mounted(self) -> ParameterRegistry:
        return ParameterRegistry(MOUNTED_NAMES, ("length",) * 3 + ("none",) * 3)

    @property
    def placement(self) -> ParameterRegistry:
        return self._placement

    @property
    def uses_robot(self) -> bool:
        return self.dataset.flange_poses is None

    def sensor_fit(self) -> SensorFit:
        """Sensor-only calibration on the pendant poses, or on the nominal robot's flange
        poses for joint readings (``sphere_fit.fit_sensor``), computed once."""
        return self._sensor

    @cached_property
    def _sensor(self) -> SensorFit:
        return fit_dataset(self.dataset)

    def initial_mounted(self) -> np.ndarray:
        """``[p0 [m], n]`` from the sensor-only fit (file guesses only seed that fit)."""
        fit = self.sensor_fit()
        return np.concatenate([fit.origin, fit.direction])

    def initial_placement(self, points, mounted) -> np.ndarray:
        """Sphere centre [m] through the laser points of the current robot and laser."""
        origin, direction = laser_of(mounted)
        offsets = origin[:, None] + direction[:, None] * self.dataset.distance[None, :]
        if self.uses_robot:
            hit = np.asarray(points(offsets), float)
            beam = np.asarray(points(offsets + direction[:, None]), float) - hit
        else:
            scan = self._pendant_scan()
            hit = scan.points(origin, direction)
            beam = scan.beams(direction)
        return sphere_centre(hit.T, self.dataset.radius, beam=beam.T)

    def consistent_dataset(self, kinematics, p, mounted, placement):
        """The dataset with every distance replaced by where the beam meets the sphere.

        For the robot ``p`` [SI], laser ``mounted`` and centre ``placement`` [m], reading
        ``i``'s beam ``T_i p0 + l R_i n`` meets the sphere at the root ``l`` of
        ``|w + l d|^2 = R^2`` (``w = T_i p0 - c``, ``d = R_i n``) nearest the measured
        distance; a beam that misses takes its closest approach.
        """
        origin, direction = laser_of(mounted)
        scan = self._scan
        if scan is None:
            poses = kinematics.flange_poses(self.dataset.joints, p)
            scan = Scan.from_poses(poses, self.dataset.distance, self.dataset.radius)
        w = scan.points(origin, direction) - scan.distance * scan.beams(direction) \
            - np.asarray(placement, float)[:3, None]
        d = scan.beams(direction)
        along = np.sum(d * w, axis=0)
        root = np.sqrt(np.maximum(along ** 2 - np.sum(w * w, axis=0) + scan.radius ** 2, 0.0))
        near, far = -along - root, -along + root
        distance = np.where(np.abs(near - scan.distance) <= np.abs(far - scan.distance),
                            near, far)
        return replace(self.dataset, distance=distance)

    # ------------------------------------------------------------------ residuals

    def residual_size(self) -> int:
        return self.count + 1

    def residual(self, points: PointsFunction, mounted, placement) -> ca.MX:
        origin, v, centre = mounted[0:3], mounted[3:6], placement[0:3]
        length = ca.sqrt(ca.sumsqr(v))
        n = beam_direction(v)
        distance = ca.DM(self.dataset.distance.reshape(1, -1))
        offsets = ca.repmat(origin, 1, self.count) + ca.mtimes(n, distance)  # 3 x N
        if self.uses_robot:
            world = points(offsets)
        else:
            scan = self._pendant_scan()
            R, t = scan.rotations, scan.translations
            world = ca.vertcat(*[
                sum(ca.DM(R[k, j].reshape(1, -1)) * offsets[j, :] for j in range(3))
                + ca.DM(t[k].reshape(1, -1)) for k in range(3)])
        w = world - ca.repmat(centre, 1, self.count)
        surface = ca.sqrt(ca.sum1(w * w)) - self.dataset.radius
        return ca.vertcat(surface.T, GAUGE_LENGTH * (length - 1.0))

    def row_offset(self, data, mounted):
        """The laser point ``p0 + l n`` [m] of a reading ``data = [l]`` (flange frame)."""
        return mounted[0:3] + data[0] * beam_direction(mounted[3:6])

    def row_residual(self, point, data, mounted, placement, constants):
        """``|point - c| - R`` [m] for one reading (``constants = [R]``); the gauge row
        ``|v| - 1`` is not a row's, so the model is not ``separable``."""
        return ca.norm_2(point - placement[0:3]) - constants[0]

    def row_data(self) -> np.ndarray:
        return np.asarray(self.dataset.distance, dtype=float).reshape(-1, 1)

    def row_constants(self) -> np.ndarray:
        return np.array([float(self.dataset.radius)])

    def errors(self, residual: np.ndarray) -> np.ndarray:
        """|distance of each laser point from the sphere surface| [m] (gauge row left out)."""
        return np.abs(np.asarray(residual, float).ravel()[:self.count])

    def error_rows(self) -> np.ndarray:
        return np.arange(self.count)

    # ------------------------------------------------------------------ planning

    def nominal_mounted(self) -> np.ndarray:
        """``[p0 [m], n]`` from the file's guesses (``n`` made unit)."""
        return np.concatenate([np.asarray(self.dataset.origin_guess, float),
                               beam_direction(np.asarray(self.dataset.direction_guess, float))])

    def nominal_placement(self, sockets=None) -> np.ndarray:
        """The file's sphere centre guess [m]."""
        return np.asarray(self.dataset.centre_guess, dtype=float).copy()

    def mounted_chart(self, nominal):
        """``[p0 + d(0:3), n0 + E(n0) d(3:5)]``: the beam moved in its tangent plane
        (``robocal_casadi.model.beam``), two coordinates ``laser_n1, laser_n2`` instead of the
        engine's three with their length fixed by a residual."""
        nominal = np.asarray(nominal, float)
        n0 = beam_direction(nominal[3:6])
        basis = tangent_basis(n0)
        names = ("laser_x", "laser_y", "laser_z", "laser_n1", "laser_n2")

        def chart(delta):
            return ca.vertcat(ca.DM(nominal[0:3]) + delta[0:3],
                              ca.DM(n0) + ca.mtimes(ca.DM(basis), delta[3:5]))

        return names, chart

    @classmethod
    def planned_dataset(cls, dataset, joints, kinematics, *, pose=None, point=(), distance=None):
        """The laser readings the planner aimed at, joint readings (no pendant poses)."""
        return replace(dataset, joints=np.asarray(joints, dtype=float),
                       distance=np.asarray(distance, dtype=float).ravel(), flange_poses=None,
                       extras={})

    def error_components(self, residual: np.ndarray) -> np.ndarray:
        """Signed distance of each laser point from the sphere surface [m] (outside
        positive) in column 0, NaN after."""
        out = np.full((self.count, 3), np.nan)
        out[:, 0] = np.asarray(residual, float).ravel()[:self.count]
        return out

    def error_terms(self) -> tuple:
        return (ErrorTerm("surface"),) * self.count


def laser_of(mounted) -> tuple[np.ndarray, np.ndarray]:
    """``(p0 [m], unit n)`` from mounted values ``[x, y, z, nx, ny, nz]`` (flange frame)."""
    mounted = np.asarray(mounted, float)
    return mounted[0:3], beam_direction(mounted[3:6])
