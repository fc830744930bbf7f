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
from scipy.optimize import least_squares

from robocal_casadi.datasets import ArtifactTouches, Dataset, SphereLaser, TrackerPoints
from robocal_casadi.errors import InputError
from robocal_casadi.fields import number, vector
from robocal_casadi.measurement import ArtifactModel, MeasurementModel, model_class
from robocal_casadi.robot import Robot
from robocal_casadi.units import Units

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
        return model_class(self.kind, file=self.path)

    def __repr__(self) -> str:
        return f"PlanSetup({self.path.name!r}, kind={self.kind}, robot={self.robot.name!r})"


def setup_from_dataset(dataset: Dataset) -> PlanSetup:
    """Read the set-up (and the optional ``planning`` block) of a loaded dataset."""
    path, units = dataset.path, dataset.units
    options = dataset.raw.get("planning") or {}
    if not isinstance(options, dict):
        raise InputError("expected a mapping", file=path, where="planning")
    unknown = set(options) - PLANNING_KEYS
    if unknown:
        raise InputError(f"unknown key(s) {sorted(unknown)}; allowed: {sorted(PLANNING_KEYS)}",
                         file=path, where="planning")
    L, A = units.length_scale, units.angle_scale

    def option(key, default, scale):
        if key not in options:
            return default
        return number(options[key], file=path, where=f"planning.{key}") * scale

    def positive(key, default, scale):
        value = option(key, default, scale)
        if not value > 0:
            raise InputError(f"expected a positive value, got {options[key]!r}", file=path,
                             where=f"planning.{key}")
        return value

    common = dict(path=path, kind=dataset.kind, robot=dataset.robot, units=units,
                  table_height=option("table_height", None, L), dataset=dataset,
                  noise=positive("noise", 10e-6, L), laser_rate=positive("laser_rate", 50.0, 1.0),
                  max_joint_speed=positive("max_joint_speed", np.radians(60.0), A),
                  max_joint_acceleration=positive("max_joint_acceleration",
                                                  np.radians(120.0), A))
    if isinstance(dataset, TrackerPoints):
        return PlanSetup(offset=np.asarray(dataset.target, float), instrument=dataset.instrument,
                         visibility_cone=option("visibility_cone", np.radians(60.0), A), **common)
    if isinstance(dataset, ArtifactTouches):
        model = model_class(dataset.kind, file=path)
        assert issubclass(model, ArtifactModel)  # every touch kind's model is an artifact's
        bar = model.cross
        touches = 1 if bar else int(option("touches_per_socket", 4, 1.0))
        if touches < 1:
            raise InputError("must be at least 1", file=path, where="planning.touches_per_socket")
        return PlanSetup(offset=np.asarray(dataset.probe, float),
                         layout=artifact_layout(dataset, bar),
                         distances=dataset.distances, perpendicular=dataset.perpendicular,
                         touches=touches, max_tilt=option("max_tilt", np.radians(45.0), A),
                         size_key=model.size_key, **common)
    assert isinstance(dataset, SphereLaser)
    for value, key in ((dataset.centre_guess, "sphere.centre_guess"),
                       (dataset.origin_guess, "laser.origin_guess"),
                       (dataset.direction_guess, "laser.direction_guess")):
        if value is None:
            raise InputError("planning needs this guess; add it to the dataset file",
                             file=path, where=key)
    laser_range = (0.05, 0.30)
    if "laser_range" in options:
        lo, hi = vector(options["laser_range"], 2, file=path, where="planning.laser_range")
        if not 0 <= lo < hi:
            raise InputError(f"expected 0 <= min < max, got [{lo}, {hi}]", file=path,
                             where="planning.laser_range")
        laser_range = (lo * L, hi * L)
    return PlanSetup(offset=np.asarray(dataset.origin_guess, float),
                     axis=np.asarray(dataset.direction_guess, float),
                     centre=np.asarray(dataset.centre_guess, float), radius=dataset.radius,
                     laser_range=laser_range, sensor_only=dataset.flange_poses is not None,
                     max_incidence=option("max_incidence", np.radians(45.0), A), **common)


def artifact_layout(dataset: ArtifactTouches, bar: bool) -> dict[str, np.ndarray]:
    """Socket positions [m] in the artifact frame that satisfy its distances and
    perpendicularities (the cross: A, C on x and B, D on y, centred)."""
    if bar:
        h = dataset.distances[0][2] / 2
        return {"A": np.array([-h, 0, 0]), "C": np.array([h, 0, 0]),
                "B": np.array([0, -h, 0]), "D": np.array([0, h, 0])}
    names = sorted({s for d in dataset.distances for s in d[:2]}
                   | {s for p in dataset.perpendicular for s in p})
    if not names:
        raise InputError("planning needs at least one known distance between sockets",
                         file=dataset.path, where="artifact.distances")
    index = {n: i for i, n in enumerate(names)}
    scale = max(d[2] for d in dataset.distances) if dataset.distances else 0.1

    def residual(flat):
        X = flat.reshape(-1, 3)
        out = [np.linalg.norm(X[index[a]] - X[index[b]]) - L for a, b, L in dataset.distances]
        for a, c, b, d in dataset.perpendicular:
            out.append(np.dot(X[index[c]] - X[index[a]], X[index[d]] - X[index[b]]) / scale)
        out += list(X[:, 2] * 1e-3)  # prefer a flat artifact
        return np.array(out)

    rng = np.random.default_rng(0)
    fits = []
    for _ in range(5):
        start = rng.normal(scale=scale, size=(len(names), 3))
        start[:, 2] = 0.0
        fits.append(least_squares(residual, start.ravel(), xtol=1e-15, ftol=1e-15, gtol=1e-15))
    best = min(fits, key=lambda fit: fit.cost)
    X = best.x.reshape(-1, 3)
    constraint = residual(best.x)[: len(dataset.distances) + len(dataset.perpendicular)]
    if np.max(np.abs(constraint)) > 1e-9 * max(scale, 1.0):
        raise InputError("the known distances and perpendicularities contradict each other: no "
                         "rigid artifact has them", file=dataset.path, where="artifact")
    X -= X.mean(axis=0)
    return {n: X[index[n]] for n in names}
