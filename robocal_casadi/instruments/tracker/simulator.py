"""Simulated tracker readings: random configurations, the true target seen from a
tracker standing about 2.5 m away (``simulate.simulate``)."""

from __future__ import annotations

import math

import numpy as np

from ...common import exact
from ...common.units import Units
from ...model.transforms import invert, pose_from_xyz_rpy, rpy_from_matrix
from ..simulation import Generated, Setup, in_units, run_extras

DEFAULT_TARGET = (0.0, 0.0, 0.10)  # [m]


def simulate(setup: Setup) -> Generated:
    rng, world = setup.rng, setup.world
    target = setup.keep("target", setup.mounted(DEFAULT_TARGET))
    yaw = rng.uniform(-math.pi, math.pi)
    direction = rng.uniform(-math.pi, math.pi)
    T_world_instrument = pose_from_xyz_rpy(
        [2.5 * math.cos(direction), 2.5 * math.sin(direction), rng.uniform(0.0, 0.5)],
        [rng.normal(0.0, 0.05), rng.normal(0.0, 0.05), yaw])
    run = setup.random_run()
    poses = run.poses
    p_world = (exact.matmul(poses[:, :3, :3], target) + poses[:, :3, 3]
               + world.shift(run.Q_true, run.payloads))
    T_instrument_world = invert(T_world_instrument)
    measured = exact.matmul(p_world, T_instrument_world[:3, :3].T) + T_instrument_world[:3, 3]
    measured = measured + rng.normal(0.0, setup.noise, measured.shape)
    return Generated(
        Q_read=run.Q_read, extras=run_extras(run.payloads, run.temperatures, setup),
        mounted={"target": target}, placement={"T_world_instrument": T_world_instrument},
        fields=lambda units: {"target": {"xyz": in_units(units, DEFAULT_TARGET)},
                              "instrument": {"xyz": in_units(units, T_world_instrument[:3, 3])}},
        measured={"x": measured[:, 0], "y": measured[:, 1], "z": measured[:, 2]},
        written=lambda units: _written(target, T_world_instrument, units))


def _written(target: np.ndarray, T_world_instrument: np.ndarray, units: Units
             ) -> tuple[dict, dict]:
    """``truth.yaml``'s entries: the target [length] and the tracker's pose (position
    [length], roll-pitch-yaw [angle]) in the world."""
    rpy = rpy_from_matrix(T_world_instrument[:3, :3])
    return ({"target": in_units(units, target)},
            {"instrument": {"xyz": in_units(units, T_world_instrument[:3, 3]),
                            "rpy": [float(a) / units.angle_scale for a in rpy]}})


def corrupt(rows: list[list], columns: list[str], row: int, length: float,
            rng: np.random.Generator, dataset) -> None:
    """Move the measured point of ``row`` by ``length`` [m] in a random direction."""
    units = dataset.units
    step = rng.normal(size=3)
    step *= length / exact.norm(step)
    for axis, value in zip("xyz", step):
        k = columns.index(axis)
        rows[row][k] = float(rows[row][k]) + value / units.length_scale
