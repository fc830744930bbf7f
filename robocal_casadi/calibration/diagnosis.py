"""Diagnosis: trace what the geometric residual still holds to effects the model lacks.

After the geometric fit, every candidate effect (each effect type on each joint; thermal
drift once per ``temperature`` or ``time`` column) is tested against the residual:

1. Visible? The effect's Jacobian columns, times a typical parameter size
   (``Effect.typical``), must move the measurements by more than 1e-9 m RMS.
2. Not absorbed? Each column, scaled to unit length, is projected out of the span of
   the unknowns already free (identifiable geometry, mounted instrument, placements,
   effects added before). A column whose remaining norm is below 1e-3 is something the
   model can already do (e.g. a cosine of a joint that hardly moves looks like its
   ``theta`` offset); it is held at zero. A candidate with nothing left is no finding.
3. Supported? From the Gauss-Newton linearisation at the current solution: the residual
   sum of squares with the effect's remaining columns added gives the drop of the
   Bayesian information criterion ``BIC = n log(RSS/n) + k log n`` (n residuals, k
   parameters added), and cross-validation gives the held-out error before and after on
   every fold scheme of ``folds``: units dealt at random (data rows; whole placements for
   artifacts and bars, whose own socket positions are fitted on the held-out part, as in
   validation), and the extrapolating schemes that hold out contiguous ranges of each
   joint, clusters of configurations and whole datasets. All come from per-fold Gram
   matrices, so testing every candidate costs one Jacobian.
   The held-out RMS must fall by at least ``MIN_GAIN`` (1%): an effect too small to
   matter is not worth the risk of carrying it outside the fit region.
4. Does it extrapolate? The held-out squared error summed over the extrapolating schemes
   must drop, and no single scheme may grow it by more than ``EXTRAPOLATION_TOLERANCE``:
   an effect that only fits the region it was fitted in (a periodic term bending to the
   shape of a residual over a short range of its joint) fails here.
5. Plausible? The estimate must lie in the range real robots with the joint's drive show
   (``_implausible``, ``Robot.drive``, effects.drives); for gear trains:
   a compliance is positive and below 1e-4 rad/Nm, a periodic error below about 0.05 deg,
   a gear-ratio error below 0.2%, a thermal coefficient that of a metal. An estimate
   outside stands in for something the library does not name; it is reported, not added.
6. Separable? A candidate whose columns the geometry nearly imitates (relative remaining
   norm below ``IMITATED``) is not added; nor is one that a rival of another type explains
   just as well (each explains more than ``CONFOUNDED`` of the other's share, with a
   held-out error within ``RIVAL_MARGIN``) unless, on the data that separate the two
   (``_Screening.separation``: the units where each one's columns differ most from what
   the other can make, held out, the rest fitted), its held-out RMS is ``MIN_GAIN`` below
   both that with neither and that with the rival (or the rival does not pay there).
   Otherwise the data cannot tell which is the cause, and the decision names the rival
   with those figures.

The candidate with the largest BIC drop among those passing 3-6 is added and everything
is re-identified jointly with the nonlinear solver; it is kept if the refitted model still
passes. This repeats until no candidate is supported. All effects of one type found over
the rounds form one finding (e.g. ``joint_compliance`` on joints 2 and 3). Its evidence
(``rms_drop`` relative, ``bic_drop``, ``cv_rms_before``/``cv_rms_after`` [m]) is what it
adds to the final model: with several types found, each is left out of the final model in
turn and the rest re-identified, so no effect is credited with what another one explains.

What no candidate explains is tested for structure afterwards (``unexplained``).

The screening is unweighted least squares even when the refits use ``loss='huber'``.
Data that carry their own flange poses (pendant readings) see no joint effect and are
not diagnosed.

Residual RMS values are over the per-measurement errors [m] of
docs/formats.md#result-file (for tracker data the 3-D point error), as ``Problem.rms``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..common.memory import release_freed
from ..common.progress import note, reports_stages, stage
from ..common.units import display_units
from ..effects import EFFECTS, data_columns
from ..effects.base import Effect
from ..effects.drives import drives_allowing
from ..results import Decision, EffectFinding, Identifiability
from .folds import FoldGrams, FoldScheme, entry_units, fold_schemes, separating_scheme
from .problem import Problem
from .solver import Loss, Method, Solution, solve

BIC_THRESHOLD = 10.0
ABSORBED = 1e-3  # relative remaining column norm below which the geometry holds the effect
INVISIBLE = 1e-9  # [m] RMS change of a typical-size effect below which the data do not see it
FOLDS = 5
IMITATED = 0.01  # relative remaining norm below which the geometry nearly imitates a column
CONFOUNDED = 0.9  # share of each other's explained residual two rival effects both explain
MIN_GAIN = 0.01  # an effect must lower the held-out RMS by at least this fraction
RIVAL_MARGIN = 1.1  # a rival whose held-out error is within 10% is as good an explanation
EXTRAPOLATION_TOLERANCE = 0.02  # a held-out region's squared error may grow this much
MAX_ROUNDS = 8


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True)
class CandidateTest:
    """One candidate tested in one round, with its numbers: ``outcome`` is the
    ``Decision``, ``decision`` its reason in words (``as_dict``: every field but
    ``outcome`` by name).

    ``parameters`` counts the columns kept after the identifiability check, ``held`` names
    those the geometry absorbs; ``remaining_norm`` is the smallest relative norm among
    the kept columns after projection (1 = orthogonal to the model). ``rss_drop``
    (relative) and ``bic_drop`` are from the linearisation, or from the nonlinear refit
    when ``decision`` is ``added`` or ``rejected after refit``; ``cv_rms_*`` [m] are
    held-out RMS values of the per-measurement errors.
    """

    round: int
    effect: str
    joints: tuple[int, ...]
    parameters: int
    held: tuple[str, ...]
    remaining_norm: float
    rss_drop: float
    bic_drop: float
    cv_rms_before: float
    cv_rms_after: float
    decision: str
    extrapolation: float = float("nan")  # held-out SSE after / before, extrapolating folds
    worst_region: str = ""  # the extrapolating scheme the candidate helps least
    estimate: tuple[tuple[str, float], ...] = ()  # screened parameter values (SI)
    label: str = ""  # the candidate as the effect names it (e.g. a coupling's driver)
    outcome: Decision = Decision.NOT_PAYING
    # refused for a size absurd on its joints' drives only: per joint (1-based) the other
    # drives that would make it plausible, nearest first (``effects.drives.drives_allowing``)
    drives: tuple[tuple[int, tuple[str, ...]], ...] = ()
    # refused as confounded: each rival that stands, with the held-out squared error on the
    # units where the two differ most with the candidate and with the rival, relative to
    # neither (nan: no data separate them; ``_Screening.separation``)
    rivals: tuple[tuple[str, float, float], ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """Every recorded number and word by name (the fields but ``outcome``)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "outcome"}

    def __repr__(self) -> str:
        return (f"CandidateTest(round {self.round}: {self.effect}{list(self.joints)}, "
                f"k={self.parameters}, bic_drop={self.bic_drop:.4g}, cv_rms "
                f"{self.cv_rms_before:.4g} -> {self.cv_rms_after:.4g} m, extrapolating folds "
                f"x{self.extrapolation:.3g}: {self.decision})")


@dataclass(frozen=True)
class Diagnosis:
    """What diagnosis added and everything it tested.

    ``problem`` is the final identification problem (declared effects plus the added
    ones) and ``solution`` its joint solution; ``x_final`` its unknowns (``problem``'s
    layout, SI).
    """

    added: tuple[EffectFinding, ...]
    tested: tuple[CandidateTest, ...]
    problem: Problem
    solution: Solution
    rounds: int
    seconds: float
    effects: tuple[Effect, ...] = field(default=())

    @property
    def x_final(self) -> np.ndarray:
        return self.solution.x

    def __repr__(self) -> str:
        lines = [f"Diagnosis({len(self.tested)} candidate tests in {self.rounds} round(s), "
                 f"{self.seconds:.3g} s)"]
        if not self.added:
            lines.append("  nothing added: no candidate effect is supported by the data")
        for finding in self.added:
            lines.append(f"  {finding.name} {list(finding.joints)}: {finding.summary}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- candidates


@dataclass(frozen=True)
class _Candidate:
    effect: str
    joints: tuple[int, ...]
    names: tuple[str, ...]  # parameter names in the problem
    typical: float
    column: str | None = None  # thermal: which data column
    unit: Effect | None = None  # the one-unit effect tested (a joint, a pair, a column)


def joined_extras(problem: Problem) -> dict[str, np.ndarray]:
    """Extra columns present in every dataset, joined; ``payload`` if any dataset has it."""
    datasets = [m.dataset for m in problem.models]
    out: dict[str, np.ndarray] = {}
    for column in data_columns():
        if all(column in d.extras for d in datasets):
            values = np.concatenate([np.asarray(d.extras[column], dtype=float) for d in datasets])
            if np.all(np.isfinite(values)) and np.ptp(values) > 0:
                out[column] = values
    if any("payload" in d.extras for d in datasets):
        out["payload"] = np.concatenate([np.asarray(d.extras.get("payload", np.zeros(d.rows)),
                                                    dtype=float) for d in datasets])
    return out


def _candidates(problem: Problem, extras: dict) -> tuple[list[_Candidate], list[Effect]]:
    """Per-joint candidates and the full effects that hold all their parameters."""
    robot = problem.robot
    taken = set(problem.unknowns.names)
    candidates: list[_Candidate] = []
    effects: list[Effect] = []
    readings = [m.dataset.joints for m in problem.models
                if m.uses_robot and m.dataset.joints is not None]
    Q = np.vstack(readings) if readings else np.zeros((0, robot.dof))
    for cls in EFFECTS.values():
        groups: dict[str | None, list[Effect]] = {}
        for unit in cls.candidates(robot, extras):
            names = unit.parameter_names()
            if not names or set(names) & taken or not unit.sampled_well(Q):
                continue
            column = getattr(unit, "column", None)
            candidates.append(_Candidate(cls.name, unit.joints, names, unit.typical, column, unit))
            groups.setdefault(column, []).append(unit)
        effects += [cls.merged(units, robot, extras) for units in groups.values()]
    return candidates, effects


# ----------------------------------------------------------------------------- problems


def sibling_problem(problem: Problem, effects: Sequence[Effect]) -> Problem:
    """A problem over the same models with ``effects``, in the same placement frames:
    the models ``problem`` placed keep their references (the tracker's reference
    rotation), so placement values carry over by name unchanged."""
    return Problem(problem.robot, problem.models, effects, kinematics=problem.kinematics)


def embed(source: Problem, x: np.ndarray, target: Problem) -> np.ndarray:
    """``x`` of ``source`` in ``target``'s layout by name (unknowns ``source`` lacks: zero)."""
    out = np.zeros(len(target.unknowns))
    for i, name in enumerate(source.unknowns.names):
        if name in target.unknowns:
            out[target.unknowns.index(name)] = x[i]
    return out


def _residual_and_jacobian(problem: Problem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return problem.residual(x), problem.jacobian(x)


def _mask_of(problem: Problem, names) -> np.ndarray:
    mask = np.zeros(len(problem.unknowns), dtype=bool)
    mask[problem.unknowns.indices(list(names))] = True
    return mask


# ----------------------------------------------------------------------------- folds


def residual_groups(model) -> np.ndarray:
    """For each residual entry of ``model``, the unit cross-validation holds out together.

    Tracker and sphere data: the data row. Artifact and bar data: the placement (pose),
    since socket positions are per placement (``MeasurementModel.residual_groups``).
    """
    return np.asarray(model.residual_groups())


# ----------------------------------------------------------------------------- screening


@dataclass(frozen=True)
class _Screen:
    candidate: _Candidate
    kept: tuple[str, ...]
    held: tuple[str, ...]
    remaining: float
    rss_drop: float
    bic_drop: float
    cv_after: float
    decision: str
    held_out: tuple[float, ...] = ()  # per fold scheme, held-out SSE after
    values: tuple[tuple[str, float], ...] = ()  # estimated parameters (SI)
    P: np.ndarray | None = None  # the kept columns, unit-scaled and projected


def _pivoted(columns: np.ndarray, threshold: float) -> tuple[list[int], list[float]]:
    """Greedy pivoted Gram-Schmidt: columns whose remaining norm exceeds ``threshold``."""
    A = columns.copy()
    chosen, norms = [], []
    available = list(range(A.shape[1]))
    while available:
        remaining = np.linalg.norm(A[:, available], axis=0)
        best = int(np.argmax(remaining))
        if remaining[best] <= threshold:
            break
        k = available.pop(best)
        chosen.append(k)
        norms.append(float(remaining[best]))
        u = A[:, k] / remaining[best]
        A -= np.outer(u, u @ A)
    return chosen, norms


STACK_BLOCK = 2048  # rows of a Jacobian restacked at once over its own buffer


def _stacked(J: np.ndarray, columns: Sequence[int], r: np.ndarray, owned: bool) -> np.ndarray:
    """``[J[:, columns], r]`` (n x (k + 1)), every value copied unchanged.

    When ``J`` is ``owned`` (nobody else reads it afterwards), C-ordered and at least as
    wide, the stack is written over ``J``'s own buffer, a block of rows at a time: row
    ``i`` of the stack starts at ``i (k + 1) <= i m``, so a block only ever overwrites rows
    already read, and the largest matrix of the diagnosis is not held twice. Otherwise the
    columns are copied one by one into a new array (no temporary of them all)."""
    n, m = J.shape
    width = len(columns) + 1
    if owned and width <= m and J.flags.c_contiguous and J.flags.writeable:
        flat = J.reshape(-1)
        chosen = np.asarray(columns, dtype=int)
        for start in range(0, n, STACK_BLOCK):
            stop = min(start + STACK_BLOCK, n)
            block = np.empty((stop - start, width))
            block[:, :-1] = J[start:stop, chosen]
            block[:, -1] = r[start:stop]
            flat[start * width:stop * width] = block.reshape(-1)
        return flat[:n * width].reshape(n, width)
    Z = np.empty((n, width))
    for k, column in enumerate(columns):
        Z[:, k] = J[:, column]
    Z[:, -1] = r
    return Z


class _Screening:
    """Everything one round needs from one residual and Jacobian."""

    def __init__(self, problem: Problem, r: np.ndarray, J: np.ndarray | list[np.ndarray],
                 free: np.ndarray, candidates: Sequence[_Candidate],
                 schemes: Sequence[FoldScheme], n_errors: int, free_columns: bool = False):
        """``J``: the Jacobian, or a list holding it (taken out, so that it is freed once
        its columns are copied). ``free_columns``: ``J`` holds the ``free`` columns only
        (no ``candidates``); it is then scaled in place."""
        owned = isinstance(J, list)  # a list hands J over: no one else reads it afterwards
        if isinstance(J, list):
            J = J.pop()
        release_freed()  # what earlier steps freed, before the stacked columns are formed
        self.problem, self.r, self.n_errors = problem, r, n_errors
        self.n = len(r)
        self.rss = float(r @ r)
        self.free_index = np.flatnonzero(free)
        self.candidates = list(candidates)
        names = sorted({n for c in candidates for n in c.names},
                       key=problem.unknowns.index)
        self.effect_index = {n: problem.unknowns.index(n) for n in names}
        # Z = [A, E, r] is the one copy of J's columns: A (the free columns) and E (the
        # candidates') are views of it, each scaled in place.
        a = len(self.free_index)
        sources = np.arange(a) if free_columns else self.free_index
        Z = _stacked(J, [*sources, *(self.effect_index[n] for n in names)], r, owned)
        del J  # its columns are copied: freed here unless the caller holds it (or Z reuses it)
        A = Z[:, :a]
        norms = np.linalg.norm(A, axis=0)
        norms[norms == 0] = 1.0
        A /= norms
        self.A = A
        self.gram_A = self.A.T @ self.A
        E = Z[:, a:-1]
        self.raw_norm = dict(zip(names, np.linalg.norm(E, axis=0)))
        E_norms = np.where(np.linalg.norm(E, axis=0) > 0, np.linalg.norm(E, axis=0), 1.0)
        E /= E_norms
        self.E = E
        self.column_of = {n: len(self.free_index) + k for k, n in enumerate(names)}
        total = Z.T @ Z
        self.Z, self.total = Z, total  # kept for the folds that separate rivals
        self.schemes = list(schemes)
        self.base = list(range(len(self.free_index)))
        # Every fit adds a candidate's few columns to the free ones: factored once per fold.
        self.grams = [FoldGrams(Z, scheme.fold, total, base=self.base)
                      for scheme in self.schemes]
        self.held_out_before = self.held_out(self.base)
        self.cv_before = self._cv(self.held_out_before)
        self.r_perp = self.project(r)

    def project(self, columns: np.ndarray) -> np.ndarray:
        """``columns`` minus their least-squares fit by the free columns (normal equations
        of the unit-scaled, well-conditioned identifiable set)."""
        if not self.A.shape[1]:
            return columns.copy()
        coefficients = np.linalg.solve(self.gram_A, self.A.T @ columns)
        return columns - self.A @ coefficients

    def release_columns(self) -> None:
        """Drop the stacked columns (``A``, ``E``) once every candidate is screened: what
        is judged and refitted after that reads the fold Grams, ``r_perp`` and the
        screens' own columns, and the stack (the size of the Jacobian) is freed before
        the refits form Jacobians of their own."""
        self.A = self.E = self.Z = np.zeros((0, 0))

    def held_out(self, columns) -> tuple[float, ...]:
        """Held-out SSE [m^2] of every fold scheme after fitting ``columns``."""
        return tuple(g.held_out_sse(list(columns)) for g in self.grams)

    def _cv(self, held_out: Sequence[float]) -> float:
        """Held-out RMS [m] of the per-measurement errors on the random (``units``) folds."""
        for scheme, sse in zip(self.schemes, held_out):
            if not scheme.extrapolating and np.isfinite(sse):
                return math.sqrt(sse / self.n_errors)
        return float("nan")

    def bic_drop(self, rss_after: float, k: int) -> float:
        return self.n * math.log(self.rss / max(rss_after, 1e-300)) - k * math.log(self.n)

    def extrapolation(self, after: Sequence[float]) -> tuple[float, str, float]:
        """(total ratio, worst scheme, its ratio) of held-out SSE after/before over the
        extrapolating schemes; (nan, "", nan) when the data allow none."""
        pairs = [(s.name, b, a) for s, b, a in zip(self.schemes, self.held_out_before, after)
                 if s.extrapolating and np.isfinite(a) and b > 0]
        if not pairs:
            return float("nan"), "", float("nan")
        total = sum(a for _, _, a in pairs) / sum(b for _, b, _ in pairs)
        name, b, a = max(pairs, key=lambda p: p[2] / p[1] / (1.0 + self.tolerance(p[0])))
        return total, name, a / b

    def tolerance(self, scheme: str) -> float:
        """How much an effect may grow the held-out squared error of ``scheme``."""
        own = next((s.tolerance for s in self.schemes if s.name == scheme), None)
        return EXTRAPOLATION_TOLERANCE if own is None else own

    def screen(self, candidate: _Candidate) -> _Screen:
        names = candidate.names
        moves = [candidate.typical * self.raw_norm[n] / math.sqrt(self.n_errors) for n in names]
        nan = float("nan")
        if max(moves) < INVISIBLE:
            return _Screen(candidate, (), names, 0.0, 0.0, 0.0, nan, "no effect on these data")
        columns = np.column_stack([self.E[:, self.column_of[n] - len(self.free_index)]
                                   for n in names])
        projected = self.project(columns)
        visible = [k for k, m in enumerate(moves) if m >= INVISIBLE]
        chosen, remaining = _pivoted(projected[:, visible], ABSORBED)
        kept = tuple(names[visible[k]] for k in chosen)
        held = tuple(n for n in names if n not in kept)
        if not kept:
            return _Screen(candidate, (), held, 0.0, 0.0, 0.0, nan, "absorbed by the geometry")
        P = projected[:, [visible[k] for k in chosen]]
        coefficients = np.linalg.lstsq(P, self.r_perp, rcond=None)[0]
        after = self.r_perp - P @ coefficients
        rss_after = float(after @ after) + float(self.rss - self.r_perp @ self.r_perp)
        held_out = self.held_out(self.base + [self.column_of[n] for n in kept])
        bic = self.bic_drop(rss_after, len(kept))
        # A Gauss-Newton step moves the parameters against the residual's regression.
        values = tuple((n, float(-c / self.raw_norm[n])) for n, c in zip(kept, coefficients))
        decision = ""
        if min(remaining) < IMITATED:
            decision = "imitated by the geometry on these data"
        return _Screen(candidate, kept, held, min(remaining), 1 - rss_after / self.rss, bic,
                       self._cv(held_out), decision, held_out, values, P)

    def verdict(self, bic: float, held_out: Sequence[float], threshold: float) -> str:
        """'' when the numbers support the candidate, else the reason they do not."""
        if not bic > threshold:
            return "not supported"
        after = self._cv(held_out)
        if np.isfinite(self.cv_before) and not after < self.cv_before:
            return "not supported"
        if np.isfinite(self.cv_before) and after > (1.0 - MIN_GAIN) * self.cv_before:
            return (f"too small to matter (held-out RMS -{100 * (1 - after / self.cv_before):.2g}"
                    f"%, below {100 * MIN_GAIN:.2g}%)")
        total, worst, ratio = self.extrapolation(held_out)
        if np.isfinite(total) and (total >= 1.0 or ratio > 1.0 + self.tolerance(worst)):
            return (f"does not extrapolate (held out {worst}: squared error x{ratio:.3g}; "
                    f"all extrapolating folds x{total:.3g})")
        return ""

    def separation(self, s: _Screen, t: _Screen, entry_unit: np.ndarray) -> _Separation | None:
        """``s`` against its rival ``t`` on the data that tell them apart: the units where
        the part of each one's columns the other cannot make is largest
        (``folds.separating_scheme``; the columns alone choose them, not the residual) held
        out, the geometry and each effect fitted on the rest. None when the data leave too
        few units to hold any out (or the stacked columns are gone)."""
        if s.P is None or t.P is None or not self.Z.size:
            return None
        score = np.zeros(self.n)
        for own, other in ((s.P, t.P), (t.P, s.P)):
            Q, _ = np.linalg.qr(other)
            rest = own - Q @ (Q.T @ own)
            energy = np.sum(rest ** 2, axis=1)
            if energy.sum() > 0:
                score += energy / energy.sum()
        scheme = separating_scheme(entry_unit, score)
        if scheme is None:
            return None
        grams = FoldGrams(self.Z, scheme.fold, self.total, base=self.base)
        before = grams.held_out_sse(self.base)
        held = [grams.held_out_sse(self.base + [self.column_of[n] for n in x.kept])
                for x in (s, t)]
        units = int(len(np.unique(entry_unit[scheme.fold == 0])))
        return _Separation(before, held[0], held[1], units,
                           int(len(np.unique(entry_unit[entry_unit >= 0]))))

    def overlap(self, first: _Screen, second: _Screen) -> float:
        """Share of ``second``'s explained residual that ``first`` explains as well (0..1)."""
        if first.P is None or second.P is None:
            return 0.0
        Q, _ = np.linalg.qr(first.P)
        rest = second.P - Q @ (Q.T @ second.P)
        alone = float(second.rss_drop) * self.rss
        if alone <= 0:
            return 1.0
        coefficients = np.linalg.lstsq(rest, self.r_perp - Q @ (Q.T @ self.r_perp),
                                       rcond=None)[0]
        extra = float(np.sum((rest @ coefficients) ** 2))
        return float(np.clip(1.0 - extra / alone, 0.0, 1.0))


@dataclass(frozen=True)
class _Separation:
    """A candidate against a rival on the units where they differ most, held out: their
    squared error there [m^2] with neither, with the candidate and with the rival, and
    how many units were held out of how many."""

    before: float
    own: float
    rival: float
    held: int
    units: int

    def wins(self) -> bool:
        """By the held-out rule every effect is judged by: the candidate pays there (its
        held-out RMS lower by ``MIN_GAIN`` than with neither), and lower by ``MIN_GAIN``
        than with the rival too (or the rival does not pay there at all)."""
        gain = (1.0 - MIN_GAIN) ** 2  # on squared errors
        return self.own <= gain * self.before and (self.rival > gain * self.before
                                                   or self.own <= gain * self.rival)

    def words(self, rival: str) -> str:
        """The figures, for the record of a candidate still refused."""
        if not self.before > 0:
            return f"on the {self.held} of {self.units} units where they differ most, no error"
        return (f"on the {self.held} of {self.units} units where they differ most, held out "
                f"(fitted on the rest), the squared error is x{self.own / self.before:.3g} "
                f"with it and x{self.rival / self.before:.3g} with {rival} (against neither: "
                f"its held-out RMS there must be {MIN_GAIN:.0%} below both)")


def _implausible(effect: Effect, values: dict[str, float], robot=None) -> str:
    """'' when ``values`` (SI) are what real robots with ``robot``'s drives show for
    ``effect``, else why not."""
    return effect.implausibility(values, robot) or ""


def _label(candidate: _Candidate) -> str:
    """The candidate as its effect names it (a coupling shows its driving joint)."""
    if candidate.unit is not None:
        return candidate.unit.label
    return f"{candidate.effect}{list(candidate.joints)}"


def _total(held_out: Sequence[float]) -> float:
    """Held-out SSE [m^2] summed over the fold schemes (nan-free)."""
    return float(sum(v for v in held_out if np.isfinite(v)))


# ----------------------------------------------------------------------------- the loop


@dataclass
class _Step:
    candidate: _Candidate
    kept: tuple[str, ...]
    held: tuple[str, ...]
    rms_before: float
    rms_after: float
    cv_before: float
    cv_after: float
    bic_drop: float


@dataclass
class _Search:
    """The effect search between rounds: the problem holding every candidate (``big``),
    the current solution (``x``, residual ``r``, ``free`` unknowns), the candidates not
    yet added, the steps taken and every test recorded. ``jacobian`` holds the current
    Jacobian until a round's screening takes it out (so that it is freed once copied)."""

    big: Problem
    x: np.ndarray
    r: np.ndarray
    free: np.ndarray
    jacobian: list[np.ndarray]
    schemes: list[FoldScheme]
    n_errors: int
    effect_of: dict[_Candidate, Effect]
    remaining: list[_Candidate]
    steps: list[_Step] = field(default_factory=list)
    tested: list[CandidateTest] = field(default_factory=list)


@dataclass
class _Verdicts:
    """One round's decisions so far, per screen (by ``id``): the reason in words ('' while
    the candidate passes), the ``Decision`` where it is not ``NOT_PAYING``, and the numbers
    recorded (screening numbers, or the refit's for a candidate refitted)."""

    decisions: dict[int, str] = field(default_factory=dict)
    outcomes: dict[int, Decision] = field(default_factory=dict)
    numbers: dict[int, tuple] = field(default_factory=dict)
    drives: dict[int, tuple[tuple[int, tuple[str, ...]], ...]] = field(default_factory=dict)
    rivals: dict[int, tuple[tuple[str, float, float], ...]] = field(default_factory=dict)

    def implausible(self, s, effect: Effect, values: dict[str, float], robot, reason: str,
                    after_refit: bool = False) -> None:
        """Record ``s`` as refused for its size (``reason``), with the drives that would
        allow it."""
        self.decisions[id(s)] = (f"implausible{' after refit' if after_refit else ''} "
                                 f"({reason}): stands in for something else")
        self.outcomes[id(s)] = Decision.IMPLAUSIBLE
        self.drives[id(s)] = drives_allowing(effect, values, robot)


@dataclass(frozen=True)
class _Accepted:
    """The candidate a round added, with its joint refit."""

    screen: _Screen
    solution: Solution
    residual: np.ndarray
    free: np.ndarray
    bic_drop: float
    cv_before: float
    cv_after: float


@reports_stages(default=True)
def run(problem: Problem, geometric: Solution, identifiability: Identifiability | None = None,
        *, method: Method = "lm", loss: Loss = "linear", folds: int = FOLDS,
        bic_threshold: float = BIC_THRESHOLD, max_rounds: int = MAX_ROUNDS, seed: int = 0,
        progress: bool = True, available_columns=None) -> Diagnosis:
    """Diagnose the residual of ``geometric`` (a solution of ``problem``); see the module.

    ``identifiability`` is accepted for the caller's convenience; the free set is
    ``geometric.free``. ``method``/``loss`` go to ``solver.solve`` for the refits.
    ``available_columns``, when given, are the extra columns the model must be able to
    use elsewhere (e.g. in every validation dataset): an effect that reads a column
    missing there is not offered. ``progress`` shows each round, screening and refit
    with its elapsed time on standard error when it is a terminal.
    """
    del identifiability, progress  # progress: read by ``reports_stages``
    start = time.perf_counter()
    extras = _offered_extras(problem, available_columns)
    candidates, candidate_effects = _candidates(problem, extras)
    if not candidates or not any(model.uses_robot for model in problem.models):
        return Diagnosis((), (), problem, geometric, 0, time.perf_counter() - start)
    search = _set_up(problem, geometric, candidates, candidate_effects, folds, seed)
    rounds = _search(search, max_rounds, method, loss, bic_threshold)
    if not search.steps:
        return Diagnosis((), tuple(search.tested), problem, geometric, rounds,
                         time.perf_counter() - start)
    final, solution, effects, findings = _settled(problem, search, extras, rounds, method,
                                                  loss, bic_threshold)
    return Diagnosis(tuple(findings), tuple(search.tested), final, solution, rounds,
                     time.perf_counter() - start, effects)


def _offered_extras(problem: Problem, available_columns) -> dict[str, np.ndarray]:
    """The joined extra columns (``joined_extras``) without those ``available_columns``
    (when given) lacks."""
    extras = joined_extras(problem)
    if available_columns is not None:
        for column in data_columns():
            if column in extras and column not in available_columns:
                del extras[column]
    return extras


def _set_up(problem: Problem, geometric: Solution, candidates: list[_Candidate],
            candidate_effects: list[Effect], folds: int, seed: int) -> _Search:
    """The search's start: every candidate's parameters in one problem, at ``geometric``'s
    solution, with its residual, Jacobian and fold schemes."""
    with stage(f"diagnosis set-up ({len(candidates)} candidates)"):
        big = sibling_problem(problem, tuple(problem.effects) + tuple(candidate_effects))
        x = embed(problem, geometric.x, big)
        n_errors = sum(len(m.errors(np.zeros(m.residual_size()))) for m in big.models)
        schemes = fold_schemes(big, folds, seed)
        r, J = _residual_and_jacobian(big, x)
        jacobian = [J]
        del J
    effect_of = {c: next(e for e in candidate_effects if set(c.names) <= set(e.parameter_names()))
                 for c in candidates}
    free = _mask_of(big, [problem.unknowns.names[i] for i in np.flatnonzero(geometric.free)])
    return _Search(big, x, r, free, jacobian, schemes, n_errors, effect_of, list(candidates))


def _search(search: _Search, max_rounds: int, method: Method, loss: Loss,
            bic_threshold: float) -> int:
    """Rounds of screening and refitting until no candidate is added (or none is left);
    the number of rounds run."""
    rounds = 0
    for rounds in range(1, max_rounds + 1):
        with stage(f"diagnosis round {rounds} ({len(search.steps)} effect(s) added)"):
            accepted = _round(search, rounds, method, loss, bic_threshold)
            if accepted is not None:
                _take(search, accepted)
        if accepted is None or not search.remaining:
            break
    return rounds


def _take(search: _Search, accepted: _Accepted) -> None:
    """``accepted`` into the model: a step recorded, the solution moved on, the next
    round's Jacobian formed (after the round's own columns have gone with its screening)."""
    s, solution, big = accepted.screen, accepted.solution, search.big
    search.steps.append(_Step(s.candidate, s.kept, s.held, big.rms(search.x),
                              big.rms(solution.x), accepted.cv_before, accepted.cv_after,
                              accepted.bic_drop))
    search.x, search.r, search.free = solution.x, accepted.residual, accepted.free
    search.jacobian.append(big.jacobian(solution.x))
    search.remaining = [c for c in search.remaining if c is not s.candidate]


def _round(search: _Search, rounds: int, method: Method, loss: Loss,
           bic_threshold: float) -> _Accepted | None:
    """One round: screen every remaining candidate, judge them, refit the strongest
    passing ones until one holds; every test recorded in ``search.tested``."""
    screening, screens = _screen_all(search, bic_threshold)
    verdicts = _Verdicts()
    _judge_screens(screening, screens, search, verdicts, bic_threshold)
    passing = sorted((s for s in screens if not verdicts.decisions[id(s)]),
                     key=lambda s: -s.bic_drop)
    confounded = _confounded(screening, screens, passing, search, bic_threshold, verdicts)
    screening.release_columns()
    accepted = None
    for s in passing:
        if confounded.get(id(s)):
            verdicts.decisions[id(s)] = confounded[id(s)]
            verdicts.outcomes[id(s)] = Decision.CONFOUNDED
            continue
        accepted = _refit(search, screening, s, verdicts, method, loss, bic_threshold)
        if accepted is not None:
            break
    for s in passing:
        if not verdicts.decisions[id(s)]:
            verdicts.decisions[id(s)] = "supported, weaker than the one added"
    search.tested += _records(screening, screens, verdicts, rounds)
    return accepted


def _confounded(screening: _Screening, screens: list[_Screen], passing: list[_Screen],
                search: _Search, bic_threshold: float, verdicts: _Verdicts) -> dict[int, str]:
    """Why each of ``passing`` is refused as confounded with a rival (by ``id``; none for
    those that are not): a rival explains what it explains as well (``_rivals``), and on
    the data that separate the two (``_Screening.separation``) it does not beat that
    rival. Rivals it beats there are not rivals. The rivals that stand, with the squared
    errors on the separating units relative to neither (nan: no such data), go to
    ``verdicts.rivals``."""
    out: dict[int, str] = {}
    entry_unit: np.ndarray | None = None
    for s in passing:
        reasons, standing = [], []
        for t in _rivals(screening, screens, s, bic_threshold):
            if entry_unit is None:
                entry_unit = entry_units(search.big)
            split = screening.separation(s, t, entry_unit)
            name = _label(t.candidate)
            if split is None or not split.before > 0:
                reasons.append(f"{name} (no data separate them)")
                standing.append((name, math.nan, math.nan))
            elif not split.wins():
                reasons.append(f"{name} ({split.words(name)})")
                standing.append((name, split.own / split.before, split.rival / split.before))
        if reasons:
            out[id(s)] = (f"confounded with {'; '.join(reasons)}: these data cannot tell them "
                          f"apart")
            verdicts.rivals[id(s)] = tuple(standing)
    return out


def _screen_all(search: _Search, bic_threshold: float) -> tuple[_Screening, list[_Screen]]:
    """The round's screening and every remaining candidate's screen."""
    with stage(f"screening {len(search.remaining)} candidates"):
        # The screening takes J out of the list and copies the columns it needs: J is
        # then freed (an argument would stay alive during the call).
        screening = _Screening(search.big, search.r, search.jacobian, search.free,
                               search.remaining, search.schemes, search.n_errors)
        screens = []
        for k, candidate in enumerate(search.remaining):
            note(f"{k + 1}/{len(search.remaining)} {_label(candidate)}")
            screens.append(_unless_supported(screening.screen(candidate), bic_threshold))
    return screening, screens


def _judge_screens(screening: _Screening, screens: list[_Screen], search: _Search,
                   verdicts: _Verdicts, bic_threshold: float) -> None:
    """Each screen's decision from its linearised numbers and the plausibility of its
    estimate ('' for those that pass), and the numbers recorded for it."""
    for s in screens:
        verdicts.decisions[id(s)] = s.decision or screening.verdict(
            s.bic_drop, s.held_out, bic_threshold)
        if not verdicts.decisions[id(s)]:
            effect = search.effect_of[s.candidate]
            reason = _implausible(effect, dict(s.values), search.big.robot)
            if reason:
                verdicts.implausible(s, effect, dict(s.values), search.big.robot, reason)
    verdicts.numbers.update({id(s): (s.rss_drop, s.bic_drop, s.cv_after, s.held_out)
                             for s in screens})


def _rivals(screening: _Screening, screens: list[_Screen], s: _Screen,
            bic_threshold: float) -> list[_Screen]:
    """Supported candidates of another effect type that explain what ``s`` explains
    as well as it does, and it theirs (``CONFOUNDED``, ``RIVAL_MARGIN``)."""
    return [t for t in screens if t is not s and t.P is not None
            and t.candidate.effect != s.candidate.effect
            and t.bic_drop > bic_threshold
            and _total(t.held_out) <= RIVAL_MARGIN * _total(s.held_out)
            and screening.overlap(s, t) > CONFOUNDED
            and screening.overlap(t, s) > CONFOUNDED]


def _refit(search: _Search, screening: _Screening, s: _Screen, verdicts: _Verdicts,
           method: Method, loss: Loss, bic_threshold: float) -> _Accepted | None:
    """``s`` refitted jointly with the model and judged again on its own numbers; the
    accepted candidate, or None with the reason in ``verdicts``."""
    big = search.big
    trial_free = search.free | _mask_of(big, s.kept)
    with stage(f"refit with {_label(s.candidate)}"):
        solution = solve(big, search.x, trial_free, method=method, loss=loss)
        # The refit's own held-out numbers, on the same folds (its free columns only:
        # the whole Jacobian is formed once a candidate is added).
        r_new = big.residual(solution.x)
        refit = _Screening(big, r_new, big.jacobian(solution.x, trial_free), trial_free, [],
                           search.schemes, search.n_errors, free_columns=True)
    rss_new = float(r_new @ r_new)
    bic = screening.bic_drop(rss_new, len(s.kept))
    verdicts.numbers[id(s)] = (1 - rss_new / screening.rss, bic, refit.cv_before,
                               refit.held_out_before)
    verdict = screening.verdict(bic, refit.held_out_before, bic_threshold)
    if not verdict:
        values = {n: float(solution.x[big.unknowns.index(n)]) for n in s.kept}
        reason = _implausible(search.effect_of[s.candidate], values, big.robot)
        if reason:
            verdicts.implausible(s, search.effect_of[s.candidate], values, big.robot, reason,
                                 after_refit=True)
            verdict = verdicts.decisions[id(s)]
    if verdict:
        verdicts.decisions[id(s)] = f"rejected after refit: {verdict}"
        return None
    verdicts.decisions[id(s)] = "added"
    verdicts.outcomes[id(s)] = Decision.ADDED
    return _Accepted(s, solution, r_new, trial_free, bic, screening.cv_before, refit.cv_before)


def _records(screening: _Screening, screens: list[_Screen], verdicts: _Verdicts,
             rounds: int) -> list[CandidateTest]:
    """The round's tests as recorded: each screen with its decision and numbers."""
    out = []
    for s in screens:
        rss_drop, bic, after, held_out = verdicts.numbers[id(s)]
        total, worst, _ = screening.extrapolation(held_out) if held_out else (
            float("nan"), "", float("nan"))
        out.append(CandidateTest(
            round=rounds, effect=s.candidate.effect, joints=s.candidate.joints,
            parameters=len(s.kept), held=s.held, remaining_norm=s.remaining,
            rss_drop=rss_drop, bic_drop=bic, cv_rms_before=screening.cv_before,
            cv_rms_after=after, decision=verdicts.decisions[id(s)] or "not supported",
            extrapolation=total, worst_region=worst, estimate=s.values,
            label=_label(s.candidate),
            outcome=verdicts.outcomes.get(id(s), Decision.NOT_PAYING),
            drives=verdicts.drives.get(id(s), ()), rivals=verdicts.rivals.get(id(s), ())))
    return out


def _settled(problem: Problem, search: _Search, extras: dict, rounds: int, method: Method,
             loss: Loss, bic_threshold: float
             ) -> tuple[Problem, Solution, tuple[Effect, ...], list[EffectFinding]]:
    """The final model with the effects added, each candidate added paying its way with
    the others in (those that no longer do taken out, the weakest first, and recorded),
    and their findings."""
    big, x, free, steps = search.big, search.x, search.free, search.steps
    schemes, n_errors = search.schemes, search.n_errors
    with stage("diagnosis: the final model and what each added candidate pays"):
        final, solution, effects = _final(problem, big, x, free, steps, extras, method, loss)
        evidence = _evidence(final, solution, _each(steps), schemes, n_errors, method, loss)
    # A candidate added early can stand in for one found later (a coupling taking part of
    # a gear-ratio error before the gear ratio is in; a low harmonic, or the same effect
    # on another joint, taking a sliver of a higher harmonic's pattern): each must still
    # pay its way with the others in the model, or it goes, the weakest first. Judged per
    # candidate added, so a stand-in of the same effect type as the finding goes too.
    while len(steps) > 1:
        failing = {key: reason for key, numbers in evidence.items()
                   if (reason := _no_longer_supported(numbers, bic_threshold))}
        if not failing:
            break
        weakest = min(failing, key=lambda key: evidence[key]["bic_drop"])
        dropped = _each(steps)[weakest]
        search.tested.append(_removal(dropped, evidence[weakest], failing[weakest], rounds + 1))
        taken_out = _mask_of(big, [n for step in dropped for n in step.kept])
        x = x.copy()
        x[taken_out] = 0.0
        free = free & ~taken_out
        steps = [step for step in steps if step not in dropped]
        with stage(f"diagnosis: the model without {_label(dropped[0].candidate)}"):
            final, solution, effects = _final(problem, big, x, free, steps, extras, method,
                                              loss)
            evidence = _evidence(final, solution, _each(steps), schemes, n_errors, method,
                                 loss)
    groups = _groups(steps)
    if len(groups) != len(steps):  # a type found on several candidates: its evidence whole
        with stage("diagnosis: the evidence of each effect"):
            evidence = _evidence(final, solution, groups, schemes, n_errors, method, loss)
    else:
        evidence = {key: evidence[_key(group[0])] for key, group in groups.items()}
    return final, solution, effects, _findings(final, solution, groups, evidence)


def _key(step: _Step) -> tuple[str, str | None]:
    """One added candidate's key: its effect type and label (unique among the steps)."""
    return (step.candidate.effect, _label(step.candidate))


def _each(steps: list[_Step]) -> dict[tuple[str, str | None], list[_Step]]:
    """Each added candidate on its own (``_key``), in the order added."""
    return {_key(step): [step] for step in steps}


def _unless_supported(screen: _Screen, bic_threshold: float) -> _Screen:
    """``screen`` without its projected columns unless its BIC drop passes the threshold:
    only such candidates are ever compared with each other (``_Screening.overlap``)."""
    if screen.P is None or screen.bic_drop > bic_threshold:
        return screen
    return replace(screen, P=None)


def _no_longer_supported(numbers: dict, bic_threshold: float) -> str:
    """Why an added effect no longer pays its way in the final model ('' when it does),
    from its leave-one-out ``numbers`` (``_evidence``)."""
    if not numbers["bic_drop"] > bic_threshold:
        return f"BIC drop {numbers['bic_drop']:.3g} with the other effects in"
    before, after = numbers["cv_rms_before"], numbers["cv_rms_after"]
    if np.isfinite(before) and not after <= (1.0 - MIN_GAIN) * before:
        return (f"held-out RMS {after / before - 1:+.2%} with the other effects in "
                f"(needs -{MIN_GAIN:.0%})")
    return ""


def _removal(group: list[_Step], numbers: dict, reason: str, round_: int) -> CandidateTest:
    """The record of an added effect taken out again (``decision`` says why)."""
    first = group[0].candidate
    return CandidateTest(
        round=round_, effect=first.effect,
        joints=tuple(sorted({j for step in group for j in step.candidate.joints})),
        parameters=sum(len(step.kept) for step in group),
        held=tuple(n for step in group for n in step.held), remaining_norm=float("nan"),
        rss_drop=float(numbers["rms_drop"]), bic_drop=float(numbers["bic_drop"]),
        cv_rms_before=float(numbers["cv_rms_before"]),
        cv_rms_after=float(numbers["cv_rms_after"]),
        decision=f"removed: stood in for effects found later ({reason})",
        label=", ".join(_label(step.candidate) for step in group), outcome=Decision.TAKEN_OUT)


def _final(problem: Problem, big: Problem, x: np.ndarray, free: np.ndarray,
           steps: list[_Step], extras: dict, method: Method, loss: Loss):
    """The problem with the declared and the added effects only, solved jointly."""
    units: dict[tuple[str, str | None], list[Effect]] = {}
    for step in steps:
        key = (step.candidate.effect, step.candidate.column)
        units.setdefault(key, []).append(step.candidate.unit)  # type: ignore[arg-type]
    added: list[Effect] = []
    for (name, column), group in units.items():
        data = {column: extras[column]} if column else extras
        added.append(EFFECTS[name].merged(group, problem.robot, data))
    effects = tuple(problem.effects) + tuple(added)
    final = sibling_problem(problem, effects)
    x_final = embed(big, x, final)
    free_final = _mask_of(final, [big.unknowns.names[i] for i in np.flatnonzero(free)])
    solution = solve(final, x_final, free_final, method=method, loss=loss)
    return final, solution, tuple(added)


# ----------------------------------------------------------------------------- findings


def _groups(steps: list[_Step]) -> dict[tuple[str, str | None], list[_Step]]:
    """The steps of each effect type (thermal: per column), in the order first found."""
    groups: dict[tuple[str, str | None], list[_Step]] = {}
    for step in steps:
        groups.setdefault((step.candidate.effect, step.candidate.column), []).append(step)
    return groups


def _evidence(final: Problem, solution: Solution, groups: dict, schemes,
              n_errors: int, method: Method, loss: Loss) -> dict:
    """Per effect type: what it adds to the final model with everything else in it.

    With one type added this is its path from the geometric model (the steps' numbers).
    With several, each is left out of the final model in turn (its parameters zero, the
    rest re-identified), so one effect is not credited with what another one found.
    """
    out = {}
    if len(groups) == 1:
        (key, group), = groups.items()
        first, last = group[0], group[-1]
        return {key: {"rms_drop": 1.0 - last.rms_after / first.rms_before,
                      "bic_drop": float(sum(s.bic_drop for s in group)),
                      "cv_rms_before": first.cv_before, "cv_rms_after": last.cv_after}}
    r = solution.residual
    cv_final = _Screening(final, r, final.jacobian(solution.x), solution.free, [], schemes,
                          n_errors).cv_before
    rms_final, rss_final = final.rms(solution.x), float(r @ r)
    for key, group in groups.items():
        kept = _mask_of(final, [n for s in group for n in s.kept])
        x = solution.x.copy()
        x[kept] = 0.0
        without = solve(final, x, solution.free & ~kept, method=method, loss=loss)
        cv_without = _Screening(final, without.residual, final.jacobian(without.x),
                                without.free, [], schemes, n_errors).cv_before
        rss_without = float(without.residual @ without.residual)
        n = len(r)
        out[key] = {"rms_drop": 1.0 - rms_final / final.rms(without.x),
                    "bic_drop": n * math.log(rss_without / max(rss_final, 1e-300))
                    - int(kept.sum()) * math.log(n),
                    "cv_rms_before": cv_without, "cv_rms_after": cv_final}
    return out


def _findings(problem: Problem, solution: Solution, groups: dict,
              evidence: dict) -> list[EffectFinding]:
    units = display_units(problem.robot.units)  # the sentence is read: lengths in mm
    std = solution.std
    findings = []
    for key, group in groups.items():
        name = key[0]
        joints = tuple(sorted({j for s in group for j in s.candidate.joints}))
        kept = [n for s in group for n in s.kept]
        held = [n for s in group for n in s.held]
        values = {n: float(solution.x[problem.unknowns.index(n)]) for n in kept}
        errors: dict[str, float | None] = {n: float(std[problem.unknowns.index(n)])
                                           for n in kept}
        effect = next(e for e in problem.effects if e.name == name
                      and set(kept) <= set(e.parameter_names()))
        numbers = evidence[key]
        summary = finding_summary(effect, values, held, numbers, units)
        findings.append(EffectFinding(name=name, joints=joints, parameters=values,
                                      unit=effect.unit, evidence=dict(numbers), std=errors,
                                      summary=summary,
                                      units={n: effect.parameter_unit(n) for n in values}))
    return findings


def finding_summary(effect: Effect, values: dict[str, float], held: Sequence[str],
                    numbers: dict, units) -> str:
    """The sentence of one finding: ``effect`` at ``values`` (SI), the parameters ``held``
    at zero, and what it lowers the held-out RMS [m] from and to (``numbers``), lengths in
    the display ``units``."""
    scale = units.length_scale
    held_text = f" ({', '.join(held)} held at zero: the geometry absorbs them)" if held else ""
    return (f"{effect.describe(values, units)}{held_text}; adding it lowers the "
            f"cross-validated RMS of the fit data (folds of the fit readings held out in "
            f"turn) from {numbers['cv_rms_before'] / scale:.3g} {units.length} to "
            f"{numbers['cv_rms_after'] / scale:.3g} {units.length}")
