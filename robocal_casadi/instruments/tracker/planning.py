"""How the planner works with a tracker (``planning/``): the set-up (the reflector, where
the tracker stands and the cone it sees the reflector in), candidates at any
configuration within the limits whose target is above the table and faces the tracker
(the flange z axis within ``visibility_cone`` of the direction to the instrument, when
the dataset gives the instrument position), and the same kept while refining."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ...common import exact
from ...errors import InputError
from ..planning import ANGLE_MARGIN, MARGIN, Candidate, unit
from .reader import TrackerPoints


def setup_fields(dataset: TrackerPoints, options: Any) -> dict:
    """The plan set-up's fields of a tracker dataset; ``options`` reads the ``planning``
    block (``planning.setup.PlanningOptions``)."""
    return dict(offset=np.asarray(dataset.target, float), instrument=dataset.instrument,
                visibility_cone=options.option("visibility_cone", np.radians(60.0),
                                               options.units.angle_scale))


def visible(setup, poses: np.ndarray) -> np.ndarray:
    """True where the target faces the instrument (within ``visibility_cone``) for flange
    ``poses`` (N x 4 x 4); all True when no instrument position is known."""
    if setup.instrument is None:
        return np.ones(len(poses), dtype=bool)
    targets = exact.matmul(poses[:, :3, :3], setup.offset) + poses[:, :3, 3]
    towards = unit(setup.instrument - targets)
    return (poses[:, :3, 2] * towards).sum(axis=1) > np.cos(setup.visibility_cone)


def candidates(setup, workspace, count, rng, progress) -> list[Candidate]:
    found: list[np.ndarray] = []
    attempts = 0
    batch = 256
    kin = workspace.kinematics
    while len(found) < count and attempts < 400 * max(count, 10):
        attempts += batch
        Q = workspace.random_joints(rng, batch)
        poses = kin.flange_poses(Q, workspace.p)
        targets = exact.matmul(poses[:, :3, :3], setup.offset) + poses[:, :3, 3]
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


def refine(program, setup, workspace, row_model, candidate, Q) -> None:
    """Any configuration (tracker): the target above the table, facing the instrument."""
    kin, p = workspace.kinematics, row_model.p
    q = Q[:, 0]
    world = kin.point(q, p, setup.offset)
    program.blocks.append(row_model.symbolic_block(candidate, Q))
    program.constrain(world[2], [workspace.table_height + MARGIN], [np.inf])
    if setup.instrument is not None:
        T = kin.flange_pose(q, p)
        towards = setup.instrument - world
        program.constrain(ca.dot(T[:3, 2], towards) / ca.norm_2(towards),
                          [np.cos(setup.visibility_cone - ANGLE_MARGIN)], [1.0])


def feasible(setup, workspace, candidate: Candidate, Q: np.ndarray):
    """``(candidate, Q, points)`` (``points`` the targets [m]), or None when a target
    no longer faces the instrument."""
    kin = workspace.kinematics
    points = kin.points(Q, setup.offset, workspace.p)
    if not visible(setup, kin.flange_poses(Q, workspace.p)).all():
        return None
    return candidate, Q, points
