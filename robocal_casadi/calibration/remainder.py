"""What remains after calibration, beside what the instrument's own noise explains.

A residual is noise only as far as the instrument's noise accounts for it. ``measure``
compares the RMS the final model leaves on data it did not fit ("held out": the
validation data when given, else the cross-validation of the fit data, else, when no
fold can be trusted, the fit itself) with the RMS the instruments' noise alone gives
over the same per-measurement errors (``instruments.noise.expected_rms``).

Under noise alone the held-out mean square is about the noise's, times
``1 / (1 - p/n)`` for the ``p`` unknowns fitted to ``n`` residual entries, and spread
like a chi-square of ``n`` degrees of freedom. A ratio (held-out RMS over the noise's)
above ``sqrt(q / n / (1 - p/n))``, ``q`` the chi-square quantile at ``ALPHA``, is more
than noise; the limit never exceeds ``NOISE_CAP`` (a remainder three times the
instrument's noise is structure whatever the count). Then the remainder is not called a
noise floor: the model lacks what this robot does (``Remainder.lacking``), the share
``1 - 1/ratio^2`` of the remaining mean square, unless the calibrated estimates' own
uncertainty accounts for the rest: on validation data, ``estimation_rms`` gives the RMS that
uncertainty leaves on the same errors, and when noise and it together (in quadrature, at
the same limit) explain what remains, the cause is the readings (too few, or poorly spread),
not the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..common.units import Units
from ..instruments.noise import DECLARED, DEFAULT, InstrumentNoise, expected_rms
from .folds import FoldGrams, fold_schemes
from .unexplained import _chi2_quantile, _linearised

ALPHA = 1e-3  # false-alarm level of "more than noise"
NOISE_CAP = 3.0  # a remainder this many times the instrument's noise is never noise
BASES = ("validation", "cross-validation", "fit")


@dataclass(frozen=True)
class Remainder:
    """What the final model leaves, beside the instrument's noise.

    ``noise`` the instrument's noise (the first dataset's; ``source`` says whether every
    dataset declared it), ``instrument`` its name in words, ``noise_rms`` [m] the RMS over
    the per-measurement errors the noise alone gives, ``held_out`` [m] the RMS the model
    leaves there, on data of ``basis`` (one of ``BASES``), ``limit`` the largest ratio
    noise alone explains (module docstring); ``estimation`` [m] the RMS the calibrated
    estimates' own uncertainty gives on the same errors (validation data only; None where
    not computed).
    """

    noise: InstrumentNoise
    instrument: str
    noise_rms: float
    held_out: float
    basis: str
    limit: float
    estimation: float | None = None  # [m] what the estimates' own uncertainty gives there

    @property
    def ratio(self) -> float:
        """What remains, over the instrument's noise [1]."""
        return self.held_out / self.noise_rms if self.noise_rms > 0 else math.inf

    @property
    def is_noise(self) -> bool:
        """Whether the instrument's noise explains what remains."""
        return self.ratio <= self.limit

    @property
    def explained_by_estimates(self) -> bool:
        """Whether the noise together with the estimates' own uncertainty (too few or too
        weak readings, not a model that lacks something) explains what remains."""
        if self.is_noise or self.estimation is None:
            return False
        return self.held_out <= self.limit * math.hypot(self.noise_rms, self.estimation)

    @property
    def lacking(self) -> float:
        """The share of the remaining mean square the instrument's noise does not explain."""
        return max(0.0, 1.0 - 1.0 / self.ratio ** 2) if self.ratio > 0 else 0.0

    def to_json(self, units: Units) -> dict[str, Any]:
        """The ``unexplained`` entries of ``result.json`` it adds (file length unit)."""
        s, unit = units.length_scale, units.length
        return {"instrument_noise": {**self.noise.to_json(units), "instrument": self.instrument,
                                     "rms": self.noise_rms / s},
                "held_out": {"rms": self.held_out / s, "unit": unit, "basis": self.basis},
                "ratio": self.ratio, "noise_limit": self.limit, "is_noise": self.is_noise,
                "estimation": None if self.estimation is None else {
                    "rms": self.estimation / s, "unit": unit,
                    "explains_the_rest": self.explained_by_estimates}}

    def noise_words(self, s: float, u: str) -> str:
        """``the tracker's noise (0.028 mm, a default ...)``; ``s`` [m] per unit ``u``."""
        kind = "declared" if self.noise.source == DECLARED else (
            "a default: declare instrument_noise in the dataset file"
            if self.noise.source == DEFAULT else self.noise.source)
        return f"the {self.instrument}'s noise ({self.noise_rms / s:.3g} {u}, {kind})"

    def sentence(self, units: Units, variables: tuple[str, ...] = ()) -> str:
        """What remains in one sentence: a noise floor, or what the model still lacks
        (and, when given, the ``variables`` it follows)."""
        s, u = units.length_scale, units.length
        where = {"validation": "on the validation data", "cross-validation": "held out",
                 "fit": "in the fit"}[self.basis]
        if self.is_noise:
            return (f"{self.held_out / s:.3g} {u} remain {where}, within what "
                    f"{self.noise_words(s, u)} explains: a noise floor")
        if self.explained_by_estimates:
            assert self.estimation is not None
            return (f"{self.held_out / s:.3g} {u} remain {where}, about {self.ratio:.2g} times "
                    f"{self.noise_words(s, u)}; the calibrated estimates' own uncertainty "
                    f"({self.estimation / s:.3g} {u} there) explains the rest: more or "
                    f"better-spread readings, not a richer model, would lower it")
        most = "most" if self.lacking >= 0.5 else "part"
        follows = (f"; it varies with {', '.join(variables[:4])}" if variables else
                   "; the diagnosis's tests name no variable it follows (an effect they do "
                   "not describe, or motion the robot does not repeat)")
        return (f"{self.held_out / s:.3g} {u} remain {where}, about {self.ratio:.2g} times "
                f"{self.noise_words(s, u)}: the model still lacks {most} of what this robot "
                f"does{follows}")

    def floor_words(self, floor: float, s: float, u: str) -> str:
        """How to name ``floor`` [m], what would remain with a structure fitted (in unit
        ``u``, ``s`` [m] each): a noise floor only where the instrument's noise explains it."""
        if floor <= self.limit * self.noise_rms:
            return f"the noise floor is about {floor / s:.3g} {u}"
        return (f"with it fitted, {floor / s:.3g} {u} would still remain, about "
                f"{floor / self.noise_rms:.2g} times {self.noise_words(s, u)}")


def noise_limit(entries: int, fitted: int) -> float:
    """The largest held-out RMS over the noise's RMS that noise alone gives at level
    ``ALPHA`` with ``entries`` residual entries and ``fitted`` unknowns (at most
    ``NOISE_CAP``)."""
    if entries <= max(fitted, 0) + 1:
        return NOISE_CAP
    inflation = 1.0 / (1.0 - fitted / entries)
    return min(NOISE_CAP, math.sqrt(_chi2_quantile(entries, ALPHA) / entries * inflation))


def _noise_of(models) -> tuple[InstrumentNoise, str]:
    """The first model's noise and instrument name; the source says ``declared`` only when
    every dataset declares its noise, ``default`` when none does."""
    sources = {m.instrument_noise.source for m in models}
    first = models[0].instrument_noise
    source = first.source if len(sources) == 1 else "declared for some datasets"
    names = {m.instrument_name for m in models}
    name = models[0].instrument_name if len(names) == 1 else "instruments"
    return InstrumentNoise(first.a, first.b_per_m, source), name


def cross_validated(problem, x: np.ndarray, free: np.ndarray, *, seed: int = 0
                    ) -> float | None:
    """The held-out RMS [m] per measurement of the model at ``x`` (linearised, ``free``
    refitted on each training fold of units held out at random); None when the data
    allow no such folds."""
    schemes = [s for s in fold_schemes(problem, 5, seed) if not s.extrapolating]
    if not schemes:
        return None
    lin = _linearised(problem, x, free, seed)
    fold = schemes[0].fold[lin.keep]
    if not np.any(fold >= 0):
        return None
    grams = FoldGrams(np.column_stack([lin.U, lin.r]), fold)
    sse = grams.held_out_sse(list(range(lin.U.shape[1])))
    if not np.isfinite(sse):
        return None
    n_errors = sum(len(m.errors(np.zeros(m.residual_size()))) for m in problem.models)
    scale = len(lin.keep) / len(lin.r_all)
    return math.sqrt(sse / (n_errors * scale))


def measure(problem, x: np.ndarray, free: np.ndarray, *, validation_models=(),
            validation_rms: float | None = None, cv_rms: float | None = None,
            estimation: float | None = None) -> Remainder | None:
    """What the final model (``problem`` at ``x``, ``free`` fitted) leaves beside the
    instruments' noise. ``validation_models`` and ``validation_rms`` [m]: the held-out
    data's models and the final RMS there, when given (they are the basis); ``cv_rms``
    [m]: a held-out RMS of the final model known already (a learned map's folds);
    ``estimation`` [m]: what the estimates' uncertainty gives on the validation data
    (``estimation_rms``). None when no dataset uses the robot."""
    if not any(m.uses_robot for m in problem.models):
        return None
    fitted = int(np.count_nonzero(free))
    held: float | None
    if validation_models and validation_rms is not None:
        models, held, basis = list(validation_models), validation_rms, "validation"
        fitted = sum(len(m.placement) for m in models)
    else:
        models = list(problem.models)
        held = cv_rms if cv_rms is not None else cross_validated(problem, x, free)
        basis = "cross-validation"
        if held is None:
            held, basis = problem.rms(x), "fit"
    assert held is not None
    entries = int(sum(np.count_nonzero(m.entry_noise()) for m in models))
    noise, name = _noise_of(models)
    return Remainder(noise, name, expected_rms(models), float(held), basis,
                     noise_limit(entries, fitted),
                     estimation if basis == "validation" else None)


def estimation_rms(problem, x: np.ndarray, free: np.ndarray, covariance: np.ndarray,
                   held_out, x_held: np.ndarray) -> float | None:
    """The RMS [m] over ``held_out``'s per-measurement errors that the uncertainty of the
    estimates of ``problem`` (at ``x``, ``free`` fitted, ``covariance`` [SI^2] over the
    free unknowns in order) gives, its placements fitted again as validation does:
    ``diag(J C J^T)`` per residual entry with ``J`` the held-out problem's Jacobian over
    the robot, effect and mounted unknowns, the part its own placements can take up
    projected out. None where it cannot be formed (no such unknowns, a covariance that is
    not finite)."""
    order = np.flatnonzero(free)
    estimated = problem.mask("robot", "effects", "mounted")[order]
    names = [problem.unknowns.names[i] for i in order[estimated]]
    theirs = held_out.unknowns.names
    shared = [k for k, n in enumerate(names) if n in theirs]
    if not shared:
        return None
    C = np.asarray(covariance, float)[np.ix_(estimated, estimated)][np.ix_(shared, shared)]
    if not np.all(np.isfinite(C)):
        return None
    columns = np.array([theirs.index(names[k]) for k in shared])
    J = held_out.jacobian(x_held, columns)
    placement = held_out.free_placement()
    if placement.any():
        basis = np.linalg.qr(held_out.jacobian(x_held, placement))[0]
        J = J - basis @ (basis.T @ J)
    variance = np.clip(np.sum((J @ C) * J, axis=1), 0.0, None)
    squares, start = [], 0
    for model in held_out.models:
        size = model.residual_size()
        squares.append(model.errors(np.sqrt(variance[start:start + size])) ** 2)
        start += size
    if start != len(variance) or not squares:
        return None
    total = np.concatenate(squares)
    return float(np.sqrt(np.mean(total))) if total.size else None
