"""Measurements the robot can really make, one ``Candidate`` per bar/artifact placement
or per reading, drawn at random from what the robot reaches, by how the measurement
model says the robot takes a reading (``reach``):

* seated in sockets (the cross bar, an artifact): the artifact placed with a random position and
  yaw (tilt up to ``max_tilt``) above the worktable, every socket touched by the probe in
  ``touches`` different configurations solved by inverse kinematics within the limits.
* aiming a beam (laser on a sphere): a surface point of the sphere, a beam direction within
  ``max_incidence`` of its normal and a stand-off within the sensor's ``laser_range``;
  the flange pose that puts the laser origin and beam there.
* any configuration (tracker): random configurations within the limits whose target is above the
  table and, when the dataset gives the instrument position, faces it (the flange z axis
  within ``visibility_cone`` of the direction from the target to the instrument).

All positions [m], world frame; joints [rad or m].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal_casadi.errors import InputError
from robocal_casadi.transforms import rot_x, rot_z

from .reach import Workspace
from .setup import PlanSetup


@dataclass(frozen=True)
class Candidate:
    """One bar/artifact placement or one reading.

    ``joints`` (k x dof) the readings of its rows; ``points`` the socket touched by each
    row (touch kinds); ``sockets`` world position [m] of every socket of the placement;
    ``distance`` (k,) [m] the laser reading the nominal robot would give (sphere).
    """

    joints: np.ndarray
    points: tuple[str, ...] = ()
    sockets: dict[str, np.ndarray] = field(default_factory=dict)
    distance: np.ndarray | None = None

    def __repr__(self) -> str:
        extra = f", sockets={sorted(self.sockets)}" if self.sockets else ""
        return f"Candidate(rows={len(self.joints)}{extra})"


def reach_radius(setup: PlanSetup) -> float:
    """An upper bound [m] on the distance from joint 1's frame to the instrument point."""
    total = 0.0
    for joint in setup.robot.joints:
        total += abs(joint.a) + abs(joint.d)
        if not joint.revolute and joint.limits is not None:
            total += max(abs(joint.limits[0]), abs(joint.limits[1]))
    return total + float(np.linalg.norm(setup.offset))


def generate(setup: PlanSetup, workspace: Workspace, count: int, rng: np.random.Generator,
             progress=None) -> list[Candidate]:
    """Up to ``count`` feasible candidates for ``setup``'s instrument (fewer only if rare)."""
    maker = {"sockets": _touches, "beam": _sphere, "configuration": _tracker}[setup.model.reach]
    return maker(setup, workspace, count, rng, progress)


def _shoulder(workspace: Workspace) -> np.ndarray:
    """World position [m] of the joint-1 frame after joint 1 (the reach sphere's centre)."""
    return workspace.kinematics.joint_frames(np.zeros(workspace.dof), workspace.p)[0].full()[:3, 3]


# ---------------------------------------------------------------------- touch kinds


def _touches(setup, workspace, count, rng, progress) -> list[Candidate]:
    layout = setup.layout  # socket name -> position in the artifact frame [m]
    names = sorted(layout)
    span = max(np.linalg.norm(layout[a] - layout[b]) for a in names for b in names)
    radius = reach_radius(setup)
    if span >= 2 * radius:
        raise InputError(
            f"the artifact spans {span / setup.units.length_scale:g} {setup.units.length}, more "
            f"than the robot's whole reach ({2 * radius / setup.units.length_scale:g} "
            f"{setup.units.length} across); it cannot be placed within reach",
            file=setup.path, where=setup.size_key)
    centroid = np.mean([layout[n] for n in names], axis=0)
    found: list[Candidate] = []
    attempts = 0
    batch = 48
    while len(found) < count and attempts < 40 * max(count, 10):
        attempts += batch
        centres = workspace.kinematics.points(workspace.random_joints(rng, batch), setup.offset,
                                              workspace.p)
        placements = [_random_placement(setup, c, rng) for c in centres]
        # sockets in the world for each placement, each touched `touches` times, 2 seeds each
        world_points, owners = [], []
        for k, T in enumerate(placements):
            for name in names:
                world = T[:3, :3] @ (layout[name] - centroid) + T[:3, 3]
                for _ in range(setup.touches * 2):
                    world_points.append(world)
                    owners.append((k, name))
        targets = np.array(world_points)
        solved = workspace.solve_points(targets, setup.offset,
                                        workspace.random_joints(rng, len(targets)))
        ok = solved.ok & workspace.clear_of_table(solved.joints, targets)
        for k, T in enumerate(placements):
            rows, points, sockets = [], [], {}
            complete = True
            for name in names:
                sockets[name] = T[:3, :3] @ (layout[name] - centroid) + T[:3, 3]
                good = [i for i, o in enumerate(owners) if o == (k, name) and ok[i]]
                if len(good) < setup.touches:
                    complete = False
                    break
                chosen = rng.choice(good, size=setup.touches, replace=False)
                rows += [solved.joints[i] for i in chosen]
                points += [name] * setup.touches
            if complete and all(sockets[n][2] > workspace.table_height for n in names):
                found.append(Candidate(np.array(rows), tuple(points), sockets))
        if progress is not None:
            progress.update(min(len(found), count), "feasible placements")
    if len(found) < max(1, min(count, 4)):
        raise InputError(
            f"no placement of the artifact ({span / setup.units.length_scale:g} "
            f"{setup.units.length} across) above the worktable (z > "
            f"{workspace.table_height / setup.units.length_scale:g} {setup.units.length}) lets "
            f"the probe reach every socket within the joint limits "
            f"({len(found)} found in {attempts} tries)",
            file=setup.path, where=setup.size_key)
    return found[:count]


def _random_placement(setup, position, rng) -> np.ndarray:
    """An artifact pose centred on ``position`` [m] (a point the probe reaches), random
    yaw and a tilt up to ``max_tilt``."""
    yaw = rng.uniform(-np.pi, np.pi)
    tilt_axis = rng.uniform(-np.pi, np.pi)
    tilt = rng.uniform(0.0, setup.max_tilt)
    R = (rot_z(tilt_axis) @ rot_x(tilt) @ rot_z(-tilt_axis) @ rot_z(yaw))[:3, :3]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = position
    return T


# ---------------------------------------------------------------------- sphere and laser


def _sphere(setup, workspace, count, rng, progress) -> list[Candidate]:
    centre, radius = setup.centre, setup.radius
    lo, hi = setup.laser_range
    distance_to_shoulder = np.linalg.norm(centre - _shoulder(workspace))
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
        normals = _unit(rng.normal(size=(batch, 3)))
        normals[:, 2] = np.abs(normals[:, 2]) * np.sign(rng.uniform(-0.3, 1.0, batch))
        normals = _unit(normals)
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


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tilted(n: np.ndarray, angle: float, rng) -> np.ndarray:
    """``n`` rotated by ``angle`` [rad] about a random axis perpendicular to it."""
    helper = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    phi = rng.uniform(-np.pi, np.pi)
    side = np.cos(phi) * u + np.sin(phi) * v
    return np.cos(angle) * n + np.sin(angle) * side


# ---------------------------------------------------------------------- tracker


def visible(setup, poses: np.ndarray) -> np.ndarray:
    """True where the target faces the instrument (within ``visibility_cone``) for flange
    ``poses`` (N x 4 x 4); all True when no instrument position is known."""
    if setup.instrument is None:
        return np.ones(len(poses), dtype=bool)
    targets = poses[:, :3, :3] @ setup.offset + poses[:, :3, 3]
    towards = _unit(setup.instrument - targets)
    return np.einsum("ni,ni->n", poses[:, :3, 2], towards) > np.cos(setup.visibility_cone)


def _tracker(setup, workspace, count, rng, progress) -> list[Candidate]:
    found: list[np.ndarray] = []
    attempts = 0
    batch = 256
    kin = workspace.kinematics
    while len(found) < count and attempts < 400 * max(count, 10):
        attempts += batch
        Q = workspace.random_joints(rng, batch)
        poses = kin.flange_poses(Q, workspace.p)
        targets = poses[:, :3, :3] @ setup.offset + poses[:, :3, 3]
        ok = workspace.clear_of_table(Q, targets) & visible(setup, poses)
        found += [q for q in Q[ok]]
        if progress is not None:
            progress.update(min(len(found), count), "feasible configurations")
    if len(found) < max(1, min(count, 4)):
        raise InputError(
            "no configuration within the joint limits puts the target above the worktable "
            f"facing the instrument ({len(found)} found in {attempts} tries)",
            file=setup.path, where="instrument" if setup.instrument is not None else "target")
    return [Candidate(q[None, :]) for q in found[:count]]
