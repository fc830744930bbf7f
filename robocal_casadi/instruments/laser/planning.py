"""How the planner works with a laser on a sphere (``planning/``): the set-up (the laser,
the sphere, the usable range of readings and the largest angle of incidence), candidates
aiming the beam (a surface point of the sphere, a beam within ``max_incidence`` of its
normal, a stand-off within ``laser_range``, the flange pose that puts the laser there),
and the same kept while refining."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ...common import exact
from ...common.fields import vector
from ...errors import InputError
from ...model.beam import beam_direction, tangent_basis
from ..planning import ANGLE_MARGIN, MARGIN, Candidate, reach_radius, shoulder, unit
from .reader import SphereLaser


def setup_fields(dataset: SphereLaser, options: Any) -> dict:
    """The plan set-up's fields of a laser dataset; ``options`` reads the ``planning``
    block (``planning.setup.PlanningOptions``). The file's guesses are required."""
    path = dataset.path
    for value, key in ((dataset.centre_guess, "sphere.centre_guess"),
                       (dataset.origin_guess, "laser.origin_guess"),
                       (dataset.direction_guess, "laser.direction_guess")):
        if value is None:
            raise InputError("planning needs this guess; add it to the dataset file",
                             file=path, where=key)
    laser_range = (0.05, 0.30)
    if "laser_range" in options.options:
        lo, hi = vector(options.options["laser_range"], 2, file=path,
                        where="planning.laser_range")
        if not 0 <= lo < hi:
            raise InputError(f"expected 0 <= min < max, got [{lo}, {hi}]", file=path,
                             where="planning.laser_range")
        laser_range = (lo * options.units.length_scale, hi * options.units.length_scale)
    return dict(offset=np.asarray(dataset.origin_guess, float),
                axis=np.asarray(dataset.direction_guess, float),
                centre=np.asarray(dataset.centre_guess, float), radius=dataset.radius,
                laser_range=laser_range, sensor_only=dataset.flange_poses is not None,
                max_incidence=options.option("max_incidence", np.radians(45.0),
                                             options.units.angle_scale))


def candidates(setup, workspace, count, rng, progress) -> list[Candidate]:
    centre, radius = setup.centre, setup.radius
    lo, hi = setup.laser_range
    distance_to_shoulder = exact.norm(centre - shoulder(workspace))
    if distance_to_shoulder - radius - hi > reach_radius(setup):
        raise InputError(
            f"the sphere at {np.round(centre / setup.units.length_scale, 6).tolist()} "
            f"{setup.units.length} is out of reach of the robot with this laser",
            file=setup.path, where="sphere.centre_guess")
    found: list[Candidate] = []
    attempts = 0
    batch = 128
    while len(found) < count and attempts < 60 * max(count, 10):
        attempts += batch
        normals = unit(rng.normal(size=(batch, 3)))
        normals[:, 2] = np.abs(normals[:, 2]) * np.sign(rng.uniform(-0.3, 1.0, batch))
        normals = unit(normals)
        beams = np.array([-_tilted(n, rng.uniform(0, setup.max_incidence), rng) for n in normals])
        standoff = rng.uniform(lo, hi, batch)
        hits = centre + radius * normals
        origins = hits - standoff[:, None] * beams
        solved = workspace.solve_beams(origins, beams, setup.offset, setup.axis,
                                       workspace.random_joints(rng, batch))
        ok = solved.ok & workspace.clear_of_table(solved.joints, origins)
        ok &= hits[:, 2] > workspace.table_height
        for i in np.flatnonzero(ok):
            found.append(Candidate(solved.joints[i:i + 1], distance=standoff[i:i + 1]))
        if progress is not None:
            progress.update(min(len(found), count), "feasible laser poses")
    if len(found) < max(1, min(count, 4)):
        raise InputError(
            f"the robot cannot aim the laser at the sphere (centre "
            f"{np.round(centre / setup.units.length_scale, 6).tolist()} {setup.units.length}) "
            f"from within its joint limits above the worktable "
            f"({len(found)} poses found in {attempts} tries)",
            file=setup.path, where="sphere.centre_guess")
    return found[:count]


def _tilted(n: np.ndarray, angle: float, rng) -> np.ndarray:
    """``n`` rotated by ``angle`` [rad] about a random axis perpendicular to it."""
    helper = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = exact.cross(n, helper)
    u /= exact.norm(u)
    v = exact.cross(n, u)
    phi = rng.uniform(-np.pi, np.pi)
    side = np.cos(phi) * u + np.sin(phi) * v
    return np.cos(angle) * n + np.sin(angle) * side


def refine(program, setup, workspace, row_model, candidate, Q) -> None:
    """Aiming a beam (laser on a sphere): the beam hits the sphere within the incidence
    limit and the sensor's range [m]; the expected reading follows the pose."""
    T = workspace.kinematics.flange_pose(Q[:, 0], row_model.p)
    o = T[:3, :3] @ setup.offset + T[:3, 3]
    axis = setup.axis / exact.norm(setup.axis)
    d = T[:3, :3] @ axis
    v = o - setup.centre
    b = ca.dot(d, v)
    disc = b**2 - (ca.dot(v, v) - setup.radius**2)
    reading = -b - ca.sqrt(ca.fmax(disc, 1e-12))
    hit_normal = (o + reading * d - setup.centre) / setup.radius
    program.constraints += [disc, reading, -ca.dot(d, hit_normal), o[2]]
    program.c_lower += [[1e-8], [setup.laser_range[0]],
                        [np.cos(setup.max_incidence - ANGLE_MARGIN)],
                        [workspace.table_height + MARGIN]]
    program.c_upper += [[np.inf], [setup.laser_range[1]], [1.0], [np.inf]]
    program.blocks.append(row_model.symbolic_block(candidate, Q, data=[reading]))


def feasible(setup, workspace, candidate: Candidate, Q: np.ndarray):
    """``(candidate, Q, points)`` with the reading where the beam now meets the sphere
    (``points`` the laser origin [m]), or None when it misses, is out of the sensor's
    range or hits beyond the incidence limit."""
    kin = workspace.kinematics
    pose = kin.flange_poses(Q, workspace.p)[0]
    o = exact.matmul(pose[:3, :3], setup.offset) + pose[:3, 3]
    d = exact.matmul(pose[:3, :3], setup.axis / exact.norm(setup.axis))
    v = o - setup.centre
    b = exact.dot(d, v)
    disc = b * b - (exact.dot(v, v) - setup.radius**2)
    if disc <= 0:
        return None
    reading = -b - np.sqrt(disc)
    lo, hi = setup.laser_range
    normal = (o + reading * d - setup.centre) / setup.radius
    if not (lo <= reading <= hi and -exact.dot(d, normal) >= np.cos(setup.max_incidence) - 1e-9):
        return None
    return Candidate(Q, distance=np.array([reading])), Q, o[None]


def measured_point(setup: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(point, t1, t2)`` [m]: the point the laser reads at mid-range along its nominal
    beam (flange frame) and the two directions normal to the beam, times that mid-range
    reading, which the planner's row model varies."""
    n0 = beam_direction(setup.axis)
    t1, t2 = tangent_basis(n0).T  # the beam's two coordinates (robocal_casadi.model.beam)
    stand_off = 0.5 * (setup.laser_range[0] + setup.laser_range[1])
    return setup.offset + stand_off * n0, stand_off * t1, stand_off * t2
