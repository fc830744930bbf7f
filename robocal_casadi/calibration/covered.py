"""No stand-ins beside a learned map: the physical effects it covers are judged again.

A learned map (``learned``) comes last, over the joints the unexplained structure follows.
A physical effect diagnosis added before it on one of those joints (a periodic error or
play of joint 2 beside a map over q2) may have taken only a sliver of the pattern the map
now holds whole: named as a fact about the robot, it would be a stand-in. Each such effect
is judged again, one diagnosis unit at a time (the effect on one joint, as it was tested),
with the map in the model:

- the model without it is refitted (geometry and the other effects, least squares as in
  diagnosis), and a map is learned for it on the same fold schemes
  (``learned.map_folds``: each fold's map trained on its training rows);
- it stays when, against that model with its own map, it still pays by the rules diagnosis
  adds effects by: a BIC drop above the threshold (each side's fit with its map trained on
  every row), the held-out RMS of the random folds lower by ``MIN_GAIN``, the summed
  held-out squared error of the extrapolating folds lower, and no extrapolating scheme grown
  beyond its tolerance. When the model without it takes no map that pays, nothing covers it
  and it stays;
- of the effects that no longer pay, the one that helps least goes (the largest held-out
  ratio with / without it; ratios within ``TIE`` relative count equal, the one added last
  going first), and the others are judged again without it.

What goes is recorded (``Decision.COVERED``) with the figures that decided it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..common.units import display_units
from ..effects import EFFECTS, is_learned
from ..effects.base import Effect
from ..results import Decision, EffectFinding
from .diagnosis import (
    BIC_THRESHOLD,
    MIN_GAIN,
    CandidateTest,
    embed,
    finding_summary,
    joined_extras,
    sibling_problem,
)
from .learned import MapFolds, map_folds
from .problem import Problem
from .solver import Loss, Method, Solution, solve

TIE = 1e-9  # held-out ratios closer than this (relative) count as equal


@dataclass(frozen=True)
class _Unit:
    """One diagnosis unit of an added effect (``owner``, in the problem's effects): the
    ``unit`` tested on its own, and the other units ``owner`` is merged from."""

    owner: Effect
    unit: Effect
    others: tuple[Effect, ...]


@dataclass(frozen=True)
class Covered:
    """The model once the stand-ins a map covers are out: ``problem`` and its least-squares
    ``solution``, the findings revised, and the records of what went."""

    problem: Problem
    solution: Solution
    added: tuple[EffectFinding, ...]
    removed: tuple[CandidateTest, ...]


def units_beside(problem: Problem, declared: int, joints: Sequence[int]) -> list[_Unit]:
    """The units of the physical effects diagnosis added (``problem.effects`` after the
    first ``declared``) that act on one of ``joints``, in the order added. An effect whose
    parameters the diagnosis units do not split exactly is left out (it cannot be taken
    apart)."""
    extras = joined_extras(problem)
    out = []
    for owner in problem.effects[declared:]:
        if is_learned(owner.name) or owner.name not in EFFECTS:
            continue
        names = owner.parameter_names()
        units = [u for u in EFFECTS[owner.name].candidates(problem.robot, extras)
                 if u.parameter_names() and set(u.parameter_names()) <= set(names)]
        split = sorted(n for u in units for n in u.parameter_names())
        if split != sorted(names):
            continue
        for unit in units:
            if set(unit.joints) & set(joints):
                out.append(_Unit(owner, unit, tuple(u for u in units if u is not unit)))
    return out


def _without(problem: Problem, solution: Solution, gone: _Unit, method: Method,
             loss: Loss) -> tuple[Problem, Solution]:
    """``problem`` without the unit ``gone`` (its owner rebuilt from the others, or left
    out), refitted by least squares from ``solution`` on the same free unknowns."""
    effects = []
    for effect in problem.effects:
        if effect is not gone.owner:
            effects.append(effect)
        elif gone.others:
            column = getattr(gone.unit, "column", None)
            extras = joined_extras(problem)
            data = {column: extras[column]} if column else extras
            effects.append(EFFECTS[effect.name].merged(list(gone.others), problem.robot, data))
    target = sibling_problem(problem, tuple(effects))
    x = embed(problem, solution.x, target)
    names = [n for n in (problem.unknowns.names[i] for i in np.flatnonzero(solution.free))
             if n in target.unknowns]
    free = np.zeros(len(target.unknowns), dtype=bool)
    free[target.unknowns.indices(names)] = True
    return target, solve(target, x, free, method=method, loss=loss)


@dataclass(frozen=True)
class _Judged:
    """One unit judged beside the map: why it no longer pays ('' when it does) and its
    numbers."""

    reason: str
    ratio: float  # held-out RMS of the random folds, with / without it (each with a map)
    bic_drop: float
    fit_drop: float  # relative fall of the fit's squared error it brings
    cv_without: float  # [m] held-out RMS without it, with its map
    cv_with: float  # [m] held-out RMS with it, with the map
    extrapolation: float  # summed held-out SSE of the extrapolating schemes, with / without
    worst: str


def judge(kept: MapFolds, without: MapFolds, parameters: int, n: int,
          bic_threshold: float = BIC_THRESHOLD) -> _Judged:
    """Whether a unit of ``parameters`` unknowns pays beside the map: ``kept`` the model
    with it, ``without`` the model without it (each with the map its folds choose), ``n``
    the residual entries (see the module)."""
    bic = n * math.log(without.fit_sse / max(kept.fit_sse, 1e-300)) \
        - parameters * math.log(n)
    cv_with, cv_without = kept.random_rms(), without.random_rms()
    ratio = cv_with / cv_without if cv_without > 0 else math.nan
    pairs = [(name, tolerance, a, b) for (name, extrapolating, tolerance), a, b
             in zip(kept.schemes, kept.with_map, without.with_map) if extrapolating and b > 0]
    total = sum(p[2] for p in pairs) / sum(p[3] for p in pairs) if pairs else math.nan
    worst, grown, tolerance = max(((p[0], p[2] / p[3], p[1]) for p in pairs),
                                  key=lambda p: p[1] / (1.0 + p[2]), default=("", 0.0, 0.0))
    reason = ""
    if without.reason:
        pass  # no map pays without it: nothing covers what it explains, it stays
    elif not bic > bic_threshold:
        reason = f"BIC drop {bic:.3g} beside the map"
    elif not ratio <= 1.0 - MIN_GAIN:
        reason = f"held-out RMS {ratio - 1:+.2%} beside the map (needs -{MIN_GAIN:.0%})"
    elif np.isfinite(total) and (total >= 1.0 or grown > 1.0 + tolerance):
        reason = (f"does not extrapolate beside the map (held out {worst}: squared error "
                  f"x{grown:.3g}; all extrapolating folds x{total:.3g})")
    return _Judged(reason, ratio, bic, 1.0 - kept.fit_sse / without.fit_sse, cv_without,
                   cv_with, float(total), worst)


def without_stand_ins(problem: Problem, solution: Solution, declared: int,
                      joints: tuple[int, ...], added: tuple[EffectFinding, ...],
                      round_: int, *, method: Method = "lm", loss: Loss = "linear",
                      bic_threshold: float = BIC_THRESHOLD) -> Covered:
    """``problem`` at ``solution`` (the diagnosed model, its first ``declared`` effects
    declared) without the physical effects a map over ``joints`` covers; ``added`` its
    findings, ``round_`` the round the removals are recorded in (see the module)."""
    removed: list[CandidateTest] = []
    n = len(solution.residual)
    while True:
        units = units_beside(problem, declared, joints)
        kept = map_folds(problem, solution.x, joints) if units else None
        if kept is None:
            break
        failing = []
        for order, unit in enumerate(units):
            smaller, refit = _without(problem, solution, unit, method, loss)
            alone = map_folds(smaller, refit.x, joints)
            if alone is None:
                continue
            judged = judge(kept, alone, len(unit.unit.parameter_names()), n, bic_threshold)
            if judged.reason:
                failing.append((judged, order, unit, smaller, refit))
        if not failing:
            break
        top = max(j.ratio for j, *_ in failing)
        judged, _, unit, problem, solution = max(
            (f for f in failing if f[0].ratio >= top - TIE * abs(top)), key=lambda f: f[1])
        removed.append(_record(unit.unit, judged, joints, round_))
    if not removed:
        return Covered(problem, solution, added, ())
    return Covered(problem, solution, _revised(added, problem, solution), tuple(removed))


def _record(unit: Effect, judged: _Judged, joints: tuple[int, ...], round_: int
            ) -> CandidateTest:
    """What went and why, as diagnosis records its tests (``cv_rms_before``: held-out RMS
    [m] without it, with its map; ``cv_rms_after``: with it and the map)."""
    over = ", ".join(f"q{j}" for j in joints)
    return CandidateTest(
        round=round_, effect=unit.name, joints=unit.joints,
        parameters=len(unit.parameter_names()), held=(), remaining_norm=float("nan"),
        rss_drop=judged.fit_drop, bic_drop=judged.bic_drop, cv_rms_before=judged.cv_without,
        cv_rms_after=judged.cv_with,
        decision=f"removed: the learned map over {over} covers what it explained "
                 f"({judged.reason})",
        extrapolation=judged.extrapolation, worst_region=judged.worst, label=unit.label,
        outcome=Decision.COVERED)


def _revised(added: tuple[EffectFinding, ...], problem: Problem,
             solution: Solution) -> tuple[EffectFinding, ...]:
    """The findings of the model left: those whose parameters all went are dropped, the
    others take their values from ``solution`` (and, when some went, their sentence)."""
    units = display_units(problem.robot.units)
    out = []
    for found in added:
        values = {n: float(solution.x[problem.unknowns.index(n)])
                  for n in found.parameters if n in problem.unknowns}
        if not values:
            continue
        effect = next(e for e in problem.effects if e.name == found.name
                      and set(values) <= set(e.parameter_names()))
        joints = tuple(sorted({j for n in values
                               if (j := effect.parameter_joint(n)) is not None}))
        summary = found.summary if len(values) == len(found.parameters) else \
            finding_summary(effect, values, (), found.evidence, units)
        out.append(replace(found, parameters=values, joints=joints or found.joints,
                           std={n: found.std.get(n) for n in values}, summary=summary))
    return tuple(out)
