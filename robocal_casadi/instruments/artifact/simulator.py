"""Simulated touches: the cross bar or an artifact plate placed near a random
configuration, the probe seated in each socket by inverse kinematics of the true robot
(``simulate.simulate``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...common import exact
from ...common.units import Units
from ...errors import InputError
from ...model.ik import inverse_kinematics, random_joints
from ...model.kinematics import Kinematics
from ...model.transforms import rot_z
from ..simulation import Generated, Setup, in_units, progress_of, random_rotation, run_extras, tilt

DEFAULT_PROBE = (0.0, 0.0, 0.15)  # [m] flange frame


def _socket_layout(setup: Setup, cross: bool) -> tuple[list[str], np.ndarray, list, list]:
    """Socket names, positions in the artifact frame [m], distances, perpendicularity."""
    if cross:
        h = setup.bar_length / 2
        local = np.array([[h, 0, 0], [0, h, 0], [-h, 0, 0], [0, -h, 0]])
        return ["A", "B", "C", "D"], local, [], []
    count = max(2, setup.sockets)
    names = [f"hole_{k}" for k in range(count)]
    local = np.array([[(k - (count - 1) / 2) * setup.socket_distance, 0.0, 0.0]
                      for k in range(count)])
    distances = [[names[i], names[j], exact.norm(local[i] - local[j])]
                 for i in range(count) for j in range(i + 1, count)]
    return names, local, distances, []


def touches(setup: Setup, cross: bool) -> Generated:
    """The cross bar (``cross``: four sockets A, C and B, D at the ends of two arms of
    ``setup.bar_length``, touched once each) or an artifact: place it, seat the probe in
    each socket."""
    probe = setup.keep("probe", setup.mounted(DEFAULT_PROBE))
    names, local, distances, _ = _socket_layout(setup, cross)
    per_socket = 1 if cross else max(1, setup.touches)
    ik = inverse_kinematics(setup.world.kinematics, "point")
    bounds = setup.bounds()
    poses, points, Q_read, Q_true, payloads, temperatures = [], [], [], [], [], []
    sockets_truth: dict[int, dict[str, np.ndarray]] = {}
    attempts = 0
    with progress_of(setup) as bar:
        while len(sockets_truth) < setup.rows:
            attempts += 1
            if attempts > 20 * setup.rows + 20:
                raise InputError(f"could place only {len(sockets_truth)} of {setup.rows} "
                                 "artifacts within reach; use a smaller artifact or fewer "
                                 "placements", where="rows")
            index = len(sockets_truth)
            temperature = setup.temperature_at(index / max(setup.rows - 1, 1))
            positions, placed = _placement(setup, ik, bounds, probe, names, local,
                                           per_socket, temperature, cross)
            if len(placed) != len(names) * per_socket:
                continue  # out of reach: skip this placement
            for name, q_read, payload, q_true in placed:
                poses.append(index)
                points.append(name)
                Q_read.append(q_read)
                Q_true.append(q_true)
                payloads.append(payload)
                temperatures.append(temperature)
            sockets_truth[index] = dict(zip(names, positions))
            bar.update(len(sockets_truth))
    bar_length = float(setup.bar_length)
    Q_read_array = setup.in_order(Q_read, Q_true, payloads)

    def fields(units: Units) -> dict:
        out: dict[str, Any] = {"probe": {"xyz": in_units(units, DEFAULT_PROBE)}}
        if cross:
            return {"bar": {"length": bar_length / units.length_scale}, **out}
        out["artifact"] = {"distances": [[a, b, d / units.length_scale] for a, b, d in distances]}
        return out

    return Generated(
        Q_read=Q_read_array, extras=run_extras(payloads, temperatures, setup),
        mounted={"probe": probe}, placement={"sockets": sockets_truth}, fields=fields,
        leading={"pose": poses, "point": points},
        written=lambda units: ({"probe": in_units(units, probe)}, {"sockets": {
            int(pose): {name: in_units(units, xyz) for name, xyz in sockets.items()}
            for pose, sockets in sockets_truth.items()}}))


def _placement(setup: Setup, ik, bounds: tuple[np.ndarray, np.ndarray], probe: np.ndarray,
               names: list[str], local: np.ndarray, per_socket: int,
               temperature: float | None, cross: bool) -> tuple[np.ndarray, list]:
    """One random placement of the bar or artifact near a random configuration: the
    sockets' true positions [m] (world frame) and the touches seated so far, each
    ``(socket, joint readings, payload [kg], true joints)``; fewer than all when one is
    out of reach or outside the joint limits."""
    rng, world = setup.rng, setup.world
    p_row = world.parameters(temperature)
    q0 = random_joints(setup.nominal, 1, rng, margin=0.15)[0]
    T0 = world.kinematics.flange_poses(q0, p_row)[0]
    centre = exact.matmul(T0[:3, :3], probe) + T0[:3, 3]
    if cross:
        R_artifact = random_rotation(rng)
    else:  # a plate on a table: level, turned about the vertical, slightly tilted
        R_artifact = exact.matmul(rot_z(rng.uniform(-math.pi, math.pi))[:3, :3], tilt(rng, 0.1))
    positions = centre + exact.matmul(local, R_artifact.T)
    placed: list = []
    for name, position in zip(names, positions):
        for touch in range(per_socket):
            preferred = T0[:3, :3] if cross or touch == 0 else (
                exact.matmul(tilt(rng, 0.5), T0[:3, :3]))
            seat = position + rng.normal(0.0, setup.noise, 3)
            payload = setup.payload_value()
            result = ik.solve(seat, seed=q0, p=p_row, offset=probe, orientation=preferred,
                              bounds=bounds, restarts=3, rng=rng,
                              orientation_tolerance=1e-3)
            if not result.success:
                return positions, placed
            q_read = world.readings(result.q, payload)
            if not setup.within_limits(q_read):
                return positions, placed
            placed.append((name, q_read, payload, result.q))
    return positions, placed


def simulate(setup: Setup) -> Generated:
    """An artifact plate with ``setup.sockets`` sockets in a row, each touched
    ``setup.touches`` times per placement."""
    return touches(setup, cross=False)


def corrupt(rows: list[list], columns: list[str], row: int, length: float,
            rng: np.random.Generator, dataset) -> None:
    """Take the touch of ``row`` with the probe beside its socket: the first joint turned
    so that the probe moves by ``length`` [m] along its circle about the first axis."""
    units = dataset.units
    k = columns.index("q1")
    joints = np.asarray(dataset.joints)
    probe = np.asarray(getattr(dataset, "probe", np.zeros(3)))
    point = Kinematics(dataset.robot).points(joints[row:row + 1], probe)
    radius = max(float(np.hypot(point[0, 0], point[0, 1])), 0.1)
    turn = rng.choice([-1, 1]) * length / radius
    rows[row][k] = float(rows[row][k]) + turn / units.angle_scale
