"""Absolute positions from a laser tracker (``tracker_points``).

Unknowns: the reflector centre in the flange frame (mounted: ``target_x, target_y,
target_z`` [m]) and the tracker's frame (placement: ``<label>/instrument_x, _y, _z`` [m]
and ``<label>/instrument_rx, _ry, _rz`` [rad], ``<label>`` the station's prefix when the
dataset names one). The instrument rotation is
``R = R0 Rz(rz) Ry(ry) Rx(rx)`` with ``R0`` from a closed-form rigid registration of the
nominal positions to the measured ones (Kabsch), so the angles stay small and far from
gimbal lock.

Residual per point [m]: ``measured_i - (R p_world_i + t)``, measured in the instrument
frame; the error of a point is the length of that 3-vector.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np

from ...model.parameters import ParameterRegistry
from ...model.transforms import pose_from_xyz_rpy
from ...results import ErrorTerm
from ..model import MeasurementModel, PointsFunction


def _frozen_rotation(R: np.ndarray) -> np.ndarray:
    """A read-only copy of the 3 x 3 rotation ``R``."""
    out = np.array(R, dtype=float)
    out.flags.writeable = False
    return out


def rigid_registration(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``R, t`` with ``target ~ R source + t`` (points as rows, Kabsch)."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    H = (source - source_mean).T @ (target - target_mean)
    U, _, Vt = np.linalg.svd(H)
    sign = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, sign]) @ U.T
    return R, target_mean - R @ source_mean


class TrackerModel(MeasurementModel):
    """Residuals of absolute position data; see the module docstring."""

    kind = "tracker_points"
    table = "points.csv"
    reach = "configuration"
    error_title = "position error"
    reading_name = "tracker point"
    measured_columns = ("x", "y", "z")
    separable = True
    instrument_name = "tracker"
    # Half a typical tracker's maximum permissible error, 15 um + 6 um/m, per coordinate.
    default_noise = (7.5e-6, 3e-6)
    noise_grows_with_range = True
    invisible_reason = "has no effect on the measured positions"
    absorbed_reason = "absorbed by the unknown instrument frame (tracker data fix no robot base)"

    def __init__(self, dataset, label: str, reference: np.ndarray | None = None):
        """``reference``: the rotation ``R0`` (3 x 3); None leaves it to ``placed`` (the
        identity until then)."""
        super().__init__(dataset, label)
        names = tuple(f"{self.placement_prefix}/instrument_{k}"
                      for k in ("x", "y", "z", "rx", "ry", "rz"))
        self._placement = ParameterRegistry(names, ("length",) * 3 + ("angle",) * 3)
        self.R0 = _frozen_rotation(np.eye(3) if reference is None else reference)
        self.referenced = reference is not None

    def with_reference(self, R0: np.ndarray) -> TrackerModel:
        """This model with the reference rotation ``R0`` (3 x 3)."""
        model = self._replaced(R0=_frozen_rotation(R0), referenced=True)
        assert isinstance(model, TrackerModel)
        return model

    @property
    def mounted(self) -> ParameterRegistry:
        return ParameterRegistry(("target_x", "target_y", "target_z"), ("length",) * 3)

    @property
    def placement(self) -> ParameterRegistry:
        return self._placement

    def initial_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.target, dtype=float).copy()

    def initial_placement(self, points, mounted) -> np.ndarray:
        return self.placed(points, mounted)[1]

    def placed(self, points, mounted) -> tuple[TrackerModel, np.ndarray]:
        """The translation of a rigid registration of the current robot's target positions
        onto the measured ones, angles zero about its rotation; the model takes that
        rotation as ``R0`` unless it has a reference already (a problem built again over
        models another problem placed keeps their frames)."""
        world = points(np.asarray(mounted, float).reshape(3, 1)).T  # N x 3
        R, t = rigid_registration(world, self.dataset.measured)
        model = self if self.referenced else self.with_reference(R)
        return model, np.concatenate([t, np.zeros(3)])

    def follow(self, leader: MeasurementModel) -> TrackerModel:
        """This model with ``leader``'s reference rotation ``R0`` (same station, same
        placement)."""
        if isinstance(leader, TrackerModel):
            return self.with_reference(leader.R0)
        return self

    def instrument_transform(self, placement: np.ndarray) -> np.ndarray:
        """``T_instrument_world`` (4x4) of a placement vector."""
        T = pose_from_xyz_rpy(placement[:3], placement[3:])
        T[:3, :3] = self.R0 @ T[:3, :3]
        return T

    def residual_size(self) -> int:
        return 3 * self.dataset.rows

    def residual(self, points: PointsFunction, mounted, placement) -> ca.MX:
        world = points(mounted)  # 3 x N
        T = pose_from_xyz_rpy([placement[0], placement[1], placement[2]],
                              [placement[3], placement[4], placement[5]])
        R = ca.DM(self.R0) @ T[:3, :3]
        predicted = R @ world + ca.repmat(T[:3, 3], 1, self.dataset.rows)
        return ca.vec(ca.DM(self.dataset.measured.T) - predicted)

    def row_residual(self, point, data, mounted, placement, constants):
        """``measured - (R point + t)`` for one row (the same as ``residual``); ``R0``
        comes in as ``constants`` (row-major), so the compiled code fits every dataset."""
        T = pose_from_xyz_rpy([placement[0], placement[1], placement[2]],
                              [placement[3], placement[4], placement[5]])
        R0 = ca.reshape(constants, 3, 3).T  # CasADi reshapes column by column
        return data - (R0 @ T[:3, :3] @ point + T[:3, 3])

    def row_data(self) -> np.ndarray:
        return np.asarray(self.dataset.measured, dtype=float)

    def row_constants(self) -> np.ndarray:
        """``R0`` row by row (9,)."""
        return np.asarray(self.R0, dtype=float).ravel()

    def entry_noise(self) -> np.ndarray:
        """``a + b_per_m * range`` on each coordinate, ``range`` [m] the measured point's
        distance from the tracker (the instrument frame's origin)."""
        measured = np.asarray(self.dataset.measured, dtype=float)
        sigma = self.instrument_noise.at(np.linalg.norm(measured, axis=1))
        return np.repeat(sigma, 3)

    def errors(self, residual: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.asarray(residual, float).reshape(-1, 3), axis=1)

    def nominal_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.target, dtype=float).copy()

    @classmethod
    def planned_dataset(cls, dataset, joints, kinematics, *, pose=None, point=(), distance=None):
        """The nominal robot's target positions as the measurements, the instrument frame
        being the world frame (``nominal_placement`` zero, ``R0`` the identity)."""
        joints = np.asarray(joints, dtype=float)
        return replace(dataset, joints=joints, measured=kinematics.points(joints, dataset.target),
                       extras={})

    def error_rows(self) -> np.ndarray:
        return np.arange(self.dataset.rows)

    component_frame = "instrument"

    def error_components(self, residual: np.ndarray) -> np.ndarray:
        """Measured minus predicted x, y, z of each point (N x 3) [m], instrument frame."""
        return np.asarray(residual, float).reshape(-1, 3).copy()

    def error_terms(self) -> tuple:
        return (ErrorTerm("position"),) * self.dataset.rows
