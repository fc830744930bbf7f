"""Simulated laser readings: a laser on the flange scanning a sphere placed where its
beam points, the flange poses found by inverse kinematics of the true robot
(``simulate.simulate``)."""

from __future__ import annotations

import math

import numpy as np

from ...common import exact
from ...common.units import Units
from ...errors import InputError
from ...model.ik import inverse_kinematics, random_joints
from ...model.kinematics import Kinematics
from ...model.robot import Robot
from ...model.transforms import quaternion_from_matrix
from ..simulation import Generated, Setup, in_units, progress_of, run_extras, tilt

DEFAULT_LASER_ORIGIN = (0.06, -0.015, 0.14)  # [m]
DEFAULT_LASER_DIRECTION = (0.0, 0.0, 1.0)


def ray_sphere_distance(origin, direction, centre, radius: float) -> float:
    """Distance [m] along the unit ``direction`` from ``origin`` to the first hit of the
    sphere (``centre`` [m], ``radius`` [m]); NaN when the ray misses or starts inside."""
    origin, direction, centre = (np.asarray(v, dtype=float) for v in (origin, direction, centre))
    m = origin - centre
    b = exact.dot(m, direction)
    c = exact.dot(m, m) - radius * radius
    discriminant = b * b - c
    if c <= 0.0 or discriminant < 0.0:
        return math.nan
    t = -b - math.sqrt(discriminant)
    return t if t > 0.0 else math.nan


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b`` (3x3)."""
    v = exact.cross(a, b)
    c = exact.dot(a, b)
    if exact.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = exact.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= exact.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + exact.matmul(K, K) / (1.0 + c)


def simulate(setup: Setup) -> Generated:
    """A laser on the flange scanning a sphere placed where its beam points."""
    rng, world, robot = setup.rng, setup.world, setup.nominal
    radius = float(setup.sphere_radius)
    origin = setup.keep("laser_origin", setup.mounted(DEFAULT_LASER_ORIGIN))
    direction = exact.matmul(np.asarray(DEFAULT_LASER_DIRECTION), tilt(rng, 2 * setup.angle_std).T)
    direction = setup.keep("laser_direction", direction / exact.norm(direction))
    ik = inverse_kinematics(world.kinematics, "flange_pose")
    bounds = setup.bounds()
    standoff = (0.08, 0.2)  # [m] laser distances
    q0, T0, beam0 = _comfortable_beam(setup, direction)
    centre = exact.matmul(T0[:3, :3], origin) + T0[:3, 3] + (np.mean(standoff) + radius) * beam0
    Q_read: list[np.ndarray] = []
    Q_true: list[np.ndarray] = []
    payloads: list[float] = []
    temperatures: list[float | None] = []
    distances: list[float] = []
    attempts = 0
    with progress_of(setup) as bar:
        while len(Q_read) < setup.rows:
            attempts += 1
            if attempts > 20 * setup.rows + 20:
                raise InputError(f"could reach only {len(Q_read)} of {setup.rows} laser poses",
                                 where="rows")
            temperature = setup.temperature_at(len(Q_read) / max(setup.rows - 1, 1))
            p_row = world.parameters(temperature)
            T = _aimed_pose(rng, T0, beam0, centre, radius, direction, origin, standoff)
            if T is None:
                continue
            payload = setup.payload_value()
            result = ik.solve(T, seed=q0, p=p_row, bounds=bounds, restarts=2, rng=rng)
            if not result.success:
                continue
            q_read = world.readings(result.q, payload)
            if not setup.within_limits(q_read):
                continue
            F = world.kinematics.flange_poses(result.q, p_row)[0]
            distance = ray_sphere_distance(exact.matmul(F[:3, :3], origin) + F[:3, 3],
                                           exact.matmul(F[:3, :3], direction), centre, radius)
            if not np.isfinite(distance):
                continue
            Q_read.append(q_read)
            Q_true.append(result.q)
            payloads.append(payload)
            temperatures.append(temperature)
            distances.append(distance + rng.normal(0.0, setup.noise))
            bar.update(len(Q_read))
    Q_read_array = setup.in_order(Q_read, Q_true, payloads)
    pendant = _pendant_poses(robot, Q_read_array) if setup.readings == "pendant" else None
    centre_guess = centre + rng.normal(0.0, 0.005, 3)
    return Generated(
        Q_read=Q_read_array, extras=run_extras(payloads, temperatures, setup),
        mounted={"laser_origin": origin, "laser_direction": direction},
        placement={"sphere_centre": centre},
        written=lambda units: ({"laser_origin": in_units(units, origin),
                                "laser_direction": [float(x) for x in direction]},
                               {"sphere_centre": in_units(units, centre)}),
        fields=lambda units: _fields(radius, centre_guess, units),
        measured={"distance": np.array(distances)}, pendant=pendant)


def _fields(radius: float, centre_guess: np.ndarray, units: Units) -> dict:
    """The dataset file's ``sphere`` (radius [length], a guess of its centre) and
    ``laser`` (the default guesses) entries in ``units``."""
    return {"sphere": {"radius": radius / units.length_scale,
                       "centre_guess": in_units(units, centre_guess)},
            "laser": {"origin_guess": in_units(units, DEFAULT_LASER_ORIGIN),
                      "direction_guess": [float(v) for v in DEFAULT_LASER_DIRECTION]}}


def _comfortable_beam(setup: Setup, direction: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random configuration whose beam points down at something on a table (the last
    one drawn after 200 tries): its joints [rad or m], flange pose (4x4, world frame, at
    the run's first temperature) and beam direction (unit, world frame)."""
    world = setup.world
    for _ in range(200):
        q0 = random_joints(setup.nominal, 1, setup.rng, margin=0.2)[0]
        T0 = world.kinematics.flange_poses(q0, world.parameters(setup.temperature_at(0.0)))[0]
        beam0 = exact.matmul(T0[:3, :3], direction)
        if beam0[2] < -0.3:  # pointing down at something on a table
            break
    return q0, T0, beam0


def _aimed_pose(rng: np.random.Generator, T0: np.ndarray, beam0: np.ndarray,
                centre: np.ndarray, radius: float, direction: np.ndarray, origin: np.ndarray,
                standoff: tuple[float, float]) -> np.ndarray | None:
    """A random flange pose (4x4, world frame) [m] whose beam, tilted from ``beam0`` by up
    to about 30 degrees, hits the sphere from a distance within ``standoff`` [m]; None
    when the drawn beam misses it."""
    beam = exact.matmul(tilt(rng, 0.5), beam0)  # tilted up to about 30 degrees
    lateral = rng.normal(size=3)
    lateral -= exact.dot(lateral, beam) * beam
    lateral *= rng.uniform(0.0, 0.7 * radius) / exact.norm(lateral)
    aim = centre + lateral
    hit_from = aim - 2 * radius * beam
    to_surface = ray_sphere_distance(hit_from, beam, centre, radius)
    if not np.isfinite(to_surface):
        return None
    hit = hit_from + to_surface * beam
    laser_origin = hit - rng.uniform(*standoff) * beam
    R = exact.matmul(_rotation_between(exact.matmul(T0[:3, :3], direction), beam), T0[:3, :3])
    roll = rng.uniform(-0.5, 0.5)
    R = exact.matmul(_axis_rotation(beam, roll), R)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = laser_origin - exact.matmul(R, origin)
    return T


def _pendant_poses(robot: Robot, Q_read: np.ndarray) -> np.ndarray:
    """The controller's nominal flange poses at the readings: (N, 7) x, y, z [m] and the
    quaternion qw, qx, qy, qz (world frame)."""
    flanges = Kinematics(robot).flange_poses(Q_read)
    return np.array([np.concatenate([F[:3, 3], quaternion_from_matrix(F[:3, :3])])
                     for F in flanges])


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * exact.matmul(K, K)


def corrupt(rows: list[list], columns: list[str], row: int, length: float,
            rng: np.random.Generator, dataset) -> None:
    """Lengthen or shorten the laser reading of ``row`` by ``length`` [m]."""
    units = dataset.units
    k = columns.index("distance")
    rows[row][k] = float(rows[row][k]) + rng.choice([-1, 1]) * length / units.length_scale
