"""How the planner works with an artifact (``planning/``): the set-up (the probe, the
socket layout in the artifact's own frame, the touches per socket and the largest tilt),
candidates (the artifact placed with a random position and yaw, tilt up to
``max_tilt``, above the worktable, every socket touched by the probe in ``touches``
configurations solved by inverse kinematics within the limits), and the probe kept on
its socket while refining."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...common import exact
from ...errors import InputError
from ...model.transforms import rot_x, rot_z
from ..planning import Candidate, reach_radius
from .reader import ArtifactTouches

LAYOUT_ROUNDING = 1e-9  # socket layout positions are kept to this share of its size


def setup_fields(dataset: ArtifactTouches, options: Any, *, bar: bool = False,
                 size_key: str = "artifact.distances") -> dict:
    """The plan set-up's fields of an artifact dataset; ``options`` reads the
    ``planning`` block (``planning.setup.PlanningOptions``); ``bar``: the cross bar,
    each socket touched once."""
    touches = 1 if bar else int(options.option("touches_per_socket", 4, 1.0))
    if touches < 1:
        raise InputError("must be at least 1", file=dataset.path,
                         where="planning.touches_per_socket")
    return dict(offset=np.asarray(dataset.probe, float), layout=artifact_layout(dataset, bar),
                distances=dataset.distances, perpendicular=dataset.perpendicular,
                touches=touches, max_tilt=options.option("max_tilt", np.radians(45.0),
                                                         options.units.angle_scale),
                size_key=size_key)


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

    # Imported here: scipy.optimize takes half a second to import, and only this layout needs it.
    from scipy.optimize import least_squares

    rng = np.random.default_rng(0)
    fits = []
    for _ in range(5):
        start = rng.normal(scale=scale, size=(len(names), 3))
        start[:, 2] = 0.0
        fits.append(least_squares(residual, start.ravel(), xtol=1e-15, ftol=1e-15, gtol=1e-15))
    # the first fit that meets the constraints as well as the best one: costs of fits
    # that all meet them differ only by rounding, which must not choose among them
    least = min(fit.cost for fit in fits)
    best = next(fit for fit in fits if fit.cost <= least + (LAYOUT_ROUNDING * scale) ** 2)
    X = best.x.reshape(-1, 3)
    constraint = residual(best.x)[: len(dataset.distances) + len(dataset.perpendicular)]
    if np.max(np.abs(constraint)) > 1e-9 * max(scale, 1.0):
        raise InputError("the known distances and perpendicularities contradict each other: no "
                         "rigid artifact has them", file=dataset.path, where="artifact")
    X -= X.mean(axis=0)
    # rounded far below any machining tolerance: the fit's last bits depend on the
    # processor, and every placement of the plan is built on these positions
    quantum = LAYOUT_ROUNDING * scale
    X = np.round(X / quantum) * quantum
    return {n: X[index[n]] for n in names}


# long: one placement's draw, seat and checks in the order an operator would make them,
# with the random priorities of every touch drawn first so a reach decision shifts no draw.
def candidates(setup, workspace, count, rng, progress) -> list[Candidate]:
    layout = setup.layout  # socket name -> position in the artifact frame [m]
    names = sorted(layout)
    span = max(exact.norm(layout[a] - layout[b]) for a in names for b in names)
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
        # which touches of a socket are kept: the first by a random priority drawn for
        # every touch, so how many touches were reached does not change what is drawn
        # next (the same stream whichever rounding decided a touch)
        priority = rng.random(len(placements) * len(names) * setup.touches * 2)
        # sockets in the world for each placement, each touched `touches` times, 2 seeds each
        world_points, owners = [], []
        for k, T in enumerate(placements):
            for name in names:
                world = exact.matmul(T[:3, :3], layout[name] - centroid) + T[:3, 3]
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
                sockets[name] = exact.matmul(T[:3, :3], layout[name] - centroid) + T[:3, 3]
                good = [i for i, o in enumerate(owners) if o == (k, name) and ok[i]]
                if len(good) < setup.touches:
                    complete = False
                    break
                chosen = sorted(good, key=lambda i: (priority[i], i))[:setup.touches]
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
    R = exact.chain(rot_z(tilt_axis), rot_x(tilt), rot_z(-tilt_axis), rot_z(yaw))[:3, :3]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = position
    return T


def refine(program, setup, workspace, row_model, candidate, Q) -> None:
    """Seated in sockets (bars and artifacts): the probe stays on its socket."""
    program.blocks.append(row_model.symbolic_block(candidate, Q))
    for k, name in enumerate(candidate.points):
        program.constrain(
            workspace.kinematics.point(Q[:, k], row_model.p, setup.offset)
            - candidate.sockets[name], np.zeros(3), np.zeros(3))


def feasible(setup, workspace, candidate: Candidate, Q: np.ndarray):
    """``(candidate, Q, points)`` with the touches re-seated in their sockets by inverse
    kinematics (``points`` the sockets [m]), or None when one cannot be."""
    targets = np.array([candidate.sockets[n] for n in candidate.points])
    solved = workspace.solve_points(targets, setup.offset, Q)
    if not solved.ok.all():
        return None
    return candidate, solved.joints, targets
