"""What the planner needs of an artifact set-up (``planning.setup``): the probe, the
socket layout in the artifact's own frame, the touches per socket and the largest tilt."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ...errors import InputError
from .reader import ArtifactTouches


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
