"""What ``robot_calibrated.yaml`` holds, and whether calibrating helps at all.

A controller runs geometry alone. The geometry fitted together with effects belongs with
those effects (``effects_calibrated.yaml``); alone it is usually worse than a plain
geometric calibration, because the effects absorbed part of what the geometry would
otherwise have taken. So the geometry-only model is chosen among candidates:

* ``geometric``: the geometric calibration, robot and instrument fitted without effects;
* ``final_geometry``: the geometry of the model with effects, the effects stripped;
* ``projected``: the geometry that best reproduces the model with effects (tool poses at
  the fit readings, with the data's payload and temperature) over the calibrated region.

The candidate with the smallest held-out RMS wins (validation data when given; without
them the geometric fit, which is the best geometry-only model on the fit data). Then the
whole calibration is set against doing nothing: the ``nominal`` robot, and the nominal
robot with only the mounted instrument (probe, reflector, laser) calibrated,
``instrument_only``. When held-out data (or, without them, a linear cross-validation of
the fit data over the same folds the diagnosis uses) show the calibrated robot no
better, that is what is recommended, and the job exits with status 3.

Every RMS here is [m]; the held-out RMS of a candidate is computed with its placements
(tracker frame, sockets, sphere) fitted again on the held-out data, as validation does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..calibration.evaluation import held_out
from ..calibration.folds import FoldGrams, fold_schemes
from ..calibration.identification import evaluate, models_for
from ..calibration.problem import Problem
from ..calibration.solver import solve
from ..model.robot import Robot
from ..results import (  # noqa: F401 (the records, re-exported)
    DOING_NOTHING,
    Candidate,
    Delivery,
)

GEOMETRY_ONLY = ("geometric", "final_geometry", "projected")
# Held-out RMS values closer than this [m] (or this share of them) are a tie, and a tie
# never refuses a calibration: equal models (data without error, a robot on its drawing)
# differ only in the last digits of their sums.
TIE = 1e-9
TIE_SHARE = 1e-9


def choose(result, datasets: Sequence, validation: Sequence = ()) -> Delivery:
    """The delivery of a ``CalibrationResult`` for its fit ``datasets`` and held-out
    ``validation`` datasets (see the module docstring)."""
    geometry = _geometry_candidates(result, datasets)
    nothing = _nothing_candidates(result, datasets)
    if validation:
        geometry = [_held_out(c, validation, datasets) for c in geometry]
        nothing = [_held_out(c, validation, datasets) for c in nothing]
        basis = "held-out data"
    else:
        nothing = _cross_validated(result, datasets, nothing)
        basis = "cross-validation"
    best = _best_geometry(geometry, bool(validation))
    calibrated = _calibrated_rms(result, best, datasets, bool(validation))
    scores = {c.name: c.held_out_rms for c in nothing if c.held_out_rms is not None}
    candidates = tuple(geometry) + tuple(nothing)
    if calibrated is not None and scores:
        name, rms = min(scores.items(), key=lambda item: item[1])
        if rms < calibrated - max(TIE, TIE_SHARE * calibrated):
            reason = (f"the {basis} show the calibrated robot no better than the "
                      f"{name.replace('_', ' ')} one ({_length(result, calibrated)} against "
                      f"{_length(result, rms)} RMS): robot_calibrated.yaml holds the nominal "
                      f"geometry")
            return Delivery(name, name, basis, candidates, reason, calibrated, scores)
    reason = _geometry_reason(result, best, geometry, bool(validation))
    return Delivery(result.recommended, best.name, basis, candidates, reason, calibrated, scores)


# ----------------------------------------------------------------------------- candidates


def _geometry_candidates(result, datasets: Sequence) -> list[Candidate]:
    """The geometry-only candidates with their fit RMS."""
    robot = result.robot_nominal
    geometric_robot = robot.with_parameters(
        np.array([p.estimate for p in result.parameters_geometric], dtype=float))
    mounted_final = {name: value for name, (value, _) in result.mounted.items()}
    out = [_scored("geometric", geometric_robot, dict(result.mounted_geometric), datasets)]
    if result.effect_models and len(result.effect_values):
        final_robot = robot.with_parameters(
            np.array([p.estimate for p in result.parameters], dtype=float))
        out.append(_scored("final_geometry", final_robot, mounted_final, datasets))
        from .projection import projected_geometry

        projected = projected_geometry(result, final_robot, geometric_robot)
        if projected is not None:
            out.append(_scored("projected", projected, mounted_final, datasets))
    return out


def _nothing_candidates(result, datasets: Sequence) -> list[Candidate]:
    """The nominal robot with the file's instrument, and with the instrument calibrated."""
    robot = result.robot_nominal
    problem = Problem(robot, models_for(datasets), ())
    x = problem.initial()
    x_nominal = solve(problem, x, problem.mask("placement")).x
    out = [Candidate("nominal", robot, _mounted_of(problem, x_nominal),
                     problem.rms(x_nominal))]
    if problem.mask("mounted").any():
        x_instrument = solve(problem, x_nominal, problem.mask("mounted", "placement")).x
        out.append(Candidate("instrument_only", robot, _mounted_of(problem, x_instrument),
                             problem.rms(x_instrument)))
    return out


def _mounted_of(problem: Problem, x: np.ndarray) -> dict[str, float]:
    names = problem.unknowns.names
    return {names[i]: float(x[i]) for i in np.flatnonzero(problem.mask("mounted"))}


def _scored(name: str, robot: Robot, mounted: dict[str, float], datasets) -> Candidate:
    problem, x = evaluate(robot, list(datasets), (), mounted)
    return Candidate(name, robot, mounted, problem.rms(x))


def _held_out(candidate: Candidate, validation: Sequence, datasets: Sequence) -> Candidate:
    """``candidate`` with its RMS [m] on the ``validation`` data; the stations they share
    with the fit ``datasets`` keep the placement those give for this candidate."""
    problem, x = held_out(candidate.robot, list(validation), (), candidate.mounted,
                          anchors=datasets)
    return Candidate(candidate.name, candidate.robot, candidate.mounted, candidate.fit_rms,
                     problem.rms(x))


# ----------------------------------------------------------------------------- decisions


def _best_geometry(geometry: list[Candidate], held_out: bool) -> Candidate:
    """The geometry-only candidate with the smallest held-out RMS; without held-out data,
    the geometric fit (the best geometry-only model on the fit data by construction)."""
    if not held_out:
        return geometry[0]
    return min(geometry, key=lambda c: (c.held_out_rms, GEOMETRY_ONLY.index(c.name)))


def _calibrated_rms(result, best: Candidate, datasets: Sequence,
                    held_out: bool) -> float | None:
    """Held-out RMS [m] of the best calibrated model the user can take: the delivered
    geometry, or the model with effects where it is recommended and better."""
    if held_out:
        values = [best.held_out_rms]
        if result.recommended == "final" and result.effects and result.validation is not None:
            values.append(result.validation.rms_final)
        return float(min(v for v in values if v is not None))
    return _linear_cv(result, datasets, best.robot, best.mounted,
                      ("robot", "mounted", "placement"), free_robot=result.covariance_names)


def _length(result, value: float | None) -> str:
    """``value`` [m] in the robot file's length unit, with the unit."""
    if value is None:
        return "not measured"
    units = result.units
    return f"{value / units.length_scale:.4g} {units.length}"


def _geometry_reason(result, best: Candidate, geometry: list[Candidate], held_out: bool) -> str:
    if not held_out:
        return ("no held-out data: robot_calibrated.yaml holds the geometric calibration, the "
                "best geometry-only model on the fit data")
    others = ", ".join(f"{c.name.replace('_', ' ')} {_length(result, c.held_out_rms)}"
                       for c in geometry if c is not best and c.held_out_rms is not None)
    return (f"robot_calibrated.yaml holds the {best.name.replace('_', ' ')} model, the best "
            f"geometry-only model on the held-out data ({_length(result, best.held_out_rms)} RMS"
            + (f"; {others}" if others else "") + ")")


# ----------------------------------------------------------------------------- cross-validation


def _cross_validated(result, datasets: Sequence, nothing: list[Candidate]) -> list[Candidate]:
    """``nothing`` with held-out RMS from a linear cross-validation of the fit data."""
    out = []
    for candidate in nothing:
        keys = ("placement",) if candidate.name == "nominal" else ("mounted", "placement")
        rms = _linear_cv(result, datasets, candidate.robot, candidate.mounted, keys)
        out.append(Candidate(candidate.name, candidate.robot, candidate.mounted,
                             candidate.fit_rms, rms))
    return out


def _linear_cv(result, datasets, robot: Robot, mounted: dict[str, float],
               keys: tuple[str, ...], free_robot: Sequence[str] = ()) -> float | None:
    """Held-out RMS [m] over the fit data's random folds (units dealt into folds, as the
    diagnosis uses) after fitting the unknowns of ``keys`` (robot ones: ``free_robot``
    only), linearised at the model's own fit; the tolerance prior is kept in every fold
    when the calibration used one. None when the data allow no folds."""
    problem, x = evaluate(robot, list(datasets), (), mounted)
    schemes = [s for s in fold_schemes(problem) if not s.extrapolating]
    if not schemes:
        return None
    free = problem.mask(*[k for k in keys if k != "robot"])
    if "robot" in keys and free_robot:
        free[problem.unknowns.indices(list(free_robot))] = True
    columns = np.flatnonzero(free)
    J = problem.jacobian(x)[:, columns]
    r = problem.residual(x)
    Z = np.column_stack([J, -r])
    fold = schemes[0].fold
    prior_rows = _prior_rows(result, problem, x, columns)
    if prior_rows is not None:
        Z = np.vstack([Z, prior_rows])
        fold = np.concatenate([fold, -np.ones(len(prior_rows), dtype=int)])
    grams = FoldGrams(Z, fold)
    held = fold >= 0
    entries = int(held[: len(r)].sum())
    sse = grams.held_out_sse(range(len(columns)))
    if not np.isfinite(sse) or entries == 0:
        return None
    return _as_error_rms(problem, float(sse), entries)


def _prior_rows(result, problem: Problem, x: np.ndarray, columns: np.ndarray):
    """The tolerance prior as rows of ``[columns, -residual]`` (None without a prior)."""
    prior = result.prior
    if prior is None or not prior.tolerance or not np.isfinite(prior.noise):
        return None
    sigma = prior.noise
    start = problem.initial()
    rows = []
    position = {int(c): k for k, c in enumerate(columns)}
    for name, tolerance in prior.tolerance.items():
        if name not in problem.unknowns:
            continue
        i = problem.unknowns.index(name)
        if i not in position or tolerance <= 0:
            continue
        row = np.zeros(len(columns) + 1)
        row[position[i]] = sigma / tolerance
        row[-1] = -(x[i] - start[i]) * sigma / tolerance
        rows.append(row)
    return np.array(rows) if rows else None


def _as_error_rms(problem: Problem, sse: float, entries: int) -> float:
    """Held-out squared residual sum as the RMS of the per-measurement errors [m].

    A tracker point is three residual entries and one error (its length), so the mean
    square error per measurement is the sum over its entries."""
    errors = sum(len(e) for e in problem.errors(problem.initial()))
    per_error = problem.size / max(errors, 1)
    return float(np.sqrt(sse / entries * per_error))
