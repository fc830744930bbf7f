"""The measurement set-up a dataset file describes, as the planner needs it (SI).

Besides the keys of docs/formats.md#dataset-file, a dataset file may carry an optional
``planning`` block (docs/formats.md#planning-block), in
the file's units::

    planning:
      table_height: 0.0        # worktable plane z in the world (default: robot base z)
      touches_per_socket: 4    # artifact: configurations per socket (the cross bar: 1)
      max_tilt: 45             # largest tilt of a placed artifact from horizontal (angle)
      laser_range: [50, 300]   # laser: usable readings (default 0.05-0.30 m)
      max_incidence: 45        # laser: largest beam angle from the surface normal
      visibility_cone: 60      # tracker: target axis within this of the instrument
      noise: 0.01              # reading noise (length), for the predicted tool error
      laser_rate: 50           # laser: readings per second [Hz] of a scan
      max_joint_speed: 60      # laser scans: per joint (angle per s)
      max_joint_acceleration: 120  # laser scans: per joint (angle per s^2)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robocal_casadi.common.fields import number
from robocal_casadi.common.units import Units
from robocal_casadi.errors import InputError
from robocal_casadi.instruments import MeasurementModel, instrument
from robocal_casadi.instruments.datasets import Dataset
from robocal_casadi.model.robot import Robot

PLANNING_KEYS = {"table_height", "touches_per_socket", "max_tilt", "laser_range",
                 "max_incidence", "visibility_cone", "noise", "laser_rate", "max_joint_speed",
                 "max_joint_acceleration"}


@dataclass(frozen=True)
class PlanSetup:
    """Kind, robot and instrument geometry of a dataset file, SI.

    ``offset`` [m] the flange-frame point that is measured (probe centre, reflector,
    laser origin); ``axis`` the laser beam in the flange frame (unit); ``layout`` socket
    positions [m] in the artifact's own frame; ``centre``, ``radius`` [m] the sphere;
    ``instrument`` [m] the tracker position in the world, or None; ``dataset`` the
    dataset it was read from (its measurement model builds the planner's residuals).
    """

    path: Path
    kind: str
    robot: Robot
    units: Units
    offset: np.ndarray
    table_height: float | None = None
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    layout: dict[str, np.ndarray] = field(default_factory=dict)
    distances: tuple[tuple[str, str, float], ...] = ()
    perpendicular: tuple[tuple[str, str, str, str], ...] = ()
    touches: int = 1
    max_tilt: float = np.radians(45.0)
    size_key: str = ""
    centre: np.ndarray | None = None
    radius: float = 0.0
    laser_range: tuple[float, float] = (0.05, 0.30)
    max_incidence: float = np.radians(45.0)
    instrument: np.ndarray | None = None
    visibility_cone: float = np.radians(60.0)
    noise: float = 10e-6  # [m] standard deviation of one reading
    laser_rate: float = 50.0  # [Hz]
    max_joint_speed: float = np.radians(60.0)  # [rad/s]
    max_joint_acceleration: float = np.radians(120.0)  # [rad/s^2]
    sensor_only: bool = False  # laser with pendant poses: only the 8 laser unknowns
    dataset: Any = field(default=None, repr=False, compare=False)

    @property
    def model(self) -> type[MeasurementModel]:
        """The measurement model class of the set-up's kind: what the planner asks."""
        return instrument(self.kind, file=self.path).model

    def __repr__(self) -> str:
        return f"PlanSetup({self.path.name!r}, kind={self.kind}, robot={self.robot.name!r})"


class PlanningOptions:
    """The dataset's optional ``planning`` block, read in SI (file units at the edge)."""

    def __init__(self, dataset: Dataset):
        self.path, self.units = dataset.path, dataset.units
        options = dataset.raw.get("planning") or {}
        if not isinstance(options, dict):
            raise InputError("expected a mapping", file=self.path, where="planning")
        unknown = set(options) - PLANNING_KEYS
        if unknown:
            raise InputError(f"unknown key(s) {sorted(unknown)}; allowed: "
                             f"{sorted(PLANNING_KEYS)}", file=self.path, where="planning")
        self.options = options

    def option(self, key: str, default, scale: float):
        """``planning.<key>`` times ``scale`` (to SI), or ``default`` when absent."""
        if key not in self.options:
            return default
        return number(self.options[key], file=self.path, where=f"planning.{key}") * scale

    def positive(self, key: str, default, scale: float):
        """``option``, refused unless positive."""
        value = self.option(key, default, scale)
        if not value > 0:
            raise InputError(f"expected a positive value, got {self.options[key]!r}",
                             file=self.path, where=f"planning.{key}")
        return value


def setup_from_dataset(dataset: Dataset) -> PlanSetup:
    """Read the set-up (and the optional ``planning`` block) of a loaded dataset: what
    every kind shares here, the instrument's own fields from its ``Planner.setup``."""
    options = PlanningOptions(dataset)
    L, A = dataset.units.length_scale, dataset.units.angle_scale
    planner = instrument(dataset.kind, file=dataset.path).planner
    if planner is None:
        raise InputError(f"the planner has no set-up for {dataset.kind} data",
                         file=dataset.path, where="kind")
    return PlanSetup(
        path=dataset.path, kind=dataset.kind, robot=dataset.robot, units=dataset.units,
        table_height=options.option("table_height", None, L), dataset=dataset,
        noise=options.positive("noise", 10e-6, L),
        laser_rate=options.positive("laser_rate", 50.0, 1.0),
        max_joint_speed=options.positive("max_joint_speed", np.radians(60.0), A),
        max_joint_acceleration=options.positive("max_joint_acceleration", np.radians(120.0), A),
        **planner.setup(dataset, options))
