"""Typed, immutable results of a calibration, and ``result.json`` (docs/formats.md#result-file).

Values are SI inside; ``to_json`` converts to the robot file's units (lengths in its
length unit, angles in its angle unit, residual RMS in its length unit).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .common.units import Units, display_units, to_file_units
from .model.robot import Robot

if TYPE_CHECKING:
    from .effects.base import Effect


class Remainder(Protocol):
    """What the final model leaves beside the instrument's noise, as the result records use
    it (the record itself, ``calibration.remainder.Remainder``, lives with the engine that
    measures it; the records here import nothing from the engine)."""

    @property
    def is_noise(self) -> bool: ...

    def to_json(self, units: Units) -> dict[str, Any]: ...

    def sentence(self, units: Units, variables: tuple[str, ...] = ()) -> str: ...

    def floor_words(self, floor: float, s: float, u: str) -> str: ...


DOMINATED_SHARE = 0.5  # data share of an estimate below which the prior dominates it


class Decision(Enum):
    """What diagnosis decided about one candidate in one round.

    ``ADDED``: the model takes it; ``IMPLAUSIBLE``: supported by the numbers but refused,
    its estimate outside what real robots show (it stands in for something else);
    ``CONFOUNDED``: as good an explanation as a rival of another effect type, the data
    cannot tell them apart; ``TAKEN_OUT``: added in an earlier round and removed, no longer
    paying its way with the effects found later; ``COVERED``: added, then removed once a
    learned map over the same joints was in (the map covers what it explained, it no
    longer pays beside it); ``NOT_PAYING``: it does not lower the
    errors enough for its parameters (or not on held-out data, or the geometry absorbs it,
    or another candidate did better this round).
    """

    ADDED = "added"
    IMPLAUSIBLE = "refused as implausible"
    CONFOUNDED = "confounded"
    TAKEN_OUT = "taken out"
    COVERED = "covered by the learned map"
    NOT_PAYING = "not paying"


class DiagnosisRecord(Protocol):
    """One candidate as diagnosis tested it (``calibration.diagnosis.CandidateTest``):
    the fields the report and the terminal read; ``as_dict`` gives every recorded number
    by name, ``decision`` the reason in words, ``outcome`` the decision itself."""

    @property
    def effect(self) -> str: ...

    @property
    def joints(self) -> tuple[int, ...]: ...

    @property
    def label(self) -> str: ...

    @property
    def decision(self) -> str: ...

    @property
    def outcome(self) -> Decision: ...

    def as_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class ParameterEstimate:
    """One geometric parameter: ``nominal``, ``estimate``, ``std`` in SI of ``quantity``.

    ``identifiable`` is False for parameters held at nominal, with ``reason`` saying why.
    """

    name: str
    quantity: str  # "length" [m] | "angle" [rad] | "none"
    nominal: float
    estimate: float
    std: float | None
    identifiable: bool
    reason: str | None = None

    def to_json(self, units: Units) -> dict:
        scale = units.scale(self.quantity)
        entry = {"name": self.name, "nominal": to_file_units(self.nominal, scale),  # as typed
                 "estimate": self.estimate / scale,
                 "std": None if self.std is None else self.std / scale,
                 "unit": units.unit_name(self.quantity), "identifiable": self.identifiable}
        if self.reason:
            entry["reason"] = self.reason
        return entry


@dataclass(frozen=True)
class Identifiability:
    """What the data can tell: from the column-scaled Jacobian at the start point.

    ``singular_values`` of the scaled Jacobian restricted to the robot parameters after
    the placement unknowns are projected out, largest first; ``identifiable`` the chosen
    parameters; ``unidentifiable`` maps each other parameter to the reason;
    ``combinations`` lists base-parameter relations (text) among dependent ones.
    """

    candidates: tuple[str, ...]
    identifiable: tuple[str, ...]
    unidentifiable: dict[str, str]
    singular_values: np.ndarray
    condition_number: float
    combinations: tuple[str, ...] = ()
    # Held at nominal because the data barely see them (not an exact dependency): their
    # errors stay as large as their tolerances.
    practical: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The ``result.json`` block: what is identifiable, why the rest is not, the
        combinations and the singular values."""
        return {"identifiable": list(self.identifiable),
                "not_identifiable": dict(self.unidentifiable),
                "combinations": list(self.combinations),
                "singular_values": [float(v) for v in self.singular_values]}

    def __repr__(self) -> str:
        return (f"Identifiability({len(self.identifiable)} of {len(self.candidates)} identifiable, "
                f"condition_number={self.condition_number:.4g})")


# Why the held-out set outweighs the fit data's own cross-validation where they disagree.
HELD_OUT_DECIDE = ("The held-out data decide over the cross-validation of the fit data (which "
                   "favoured the effects): they were measured apart from the fit and took no "
                   "part in choosing or fitting the model, while the folds come from the same "
                   "readings the diagnosis chose the effects on")


@dataclass(frozen=True)
class EffectFinding:
    """An effect added by diagnosis: parameters in ``unit`` (the effect's own; ``units``
    names a parameter's unit where it differs, as a lumped term ``c6_m7`` [rad kg/Nm]
    does), evidence as numbers."""

    name: str
    joints: tuple[int, ...]
    parameters: dict[str, float]
    unit: str
    evidence: dict[str, float]
    std: dict[str, float | None] = field(default_factory=dict)
    summary: str = ""
    units: dict[str, str] = field(default_factory=dict)

    def unit_of(self, parameter: str) -> str:
        """The unit ``parameter``'s value really has."""
        return self.units.get(parameter, self.unit)

    def to_json(self, units: Units | None = None) -> dict:
        """The ``result.json`` entry; evidence lengths (``cv_rms_*``, [m] inside) in ``units``."""
        scale = units.length_scale if units is not None else 1.0
        evidence = {k: float(v) / (scale if k.startswith("cv_rms") else 1.0)
                    for k, v in self.evidence.items()}
        return {"name": self.name, "joints": list(self.joints),
                "parameters": {k: float(v) for k, v in self.parameters.items()},
                "std": {k: None if v is None or not np.isfinite(v) else float(v)
                        for k, v in self.std.items()},
                "unit": self.unit,
                "units": {k: self.unit_of(k) for k in self.parameters},
                "evidence": evidence}


@dataclass(frozen=True)
class PriorSummary:
    """How the estimate weighed data against the prior (see ``prior``): the tolerances
    or a fleet's population prior (``use``).

    ``rule`` is ``"prior"`` (maximum a posteriori) or ``"fraction"`` (least squares with
    weak parameters held); ``noise`` [m] the residual's standard deviation estimated from
    distinct readings (NaN when they leave no degree of freedom); per prior parameter its
    ``tolerance`` [SI of ``quantities``] and the data's share of its estimate (1: data
    alone, 0: prior alone).
    """

    rule: str
    noise: float
    tolerance: dict[str, float] = field(default_factory=dict)
    data_share: dict[str, float] = field(default_factory=dict)
    quantities: dict[str, str] = field(default_factory=dict)
    # the prior's centre [SI] per parameter, and which prior it was: an object with
    # ``to_json()`` (``calibration.population_prior.PriorUse``; None: the tolerance prior)
    centre: dict[str, float] = field(default_factory=dict)
    use: Any = None

    @property
    def dominated(self) -> tuple[str, ...]:
        """Parameters whose estimate owes more to the prior than to the data."""
        return tuple(n for n, s in self.data_share.items()
                     if np.isfinite(s) and s < DOMINATED_SHARE)

    def entry(self, name: str, units: Units) -> dict:
        """``tolerance`` (file units), ``data_share`` and ``prior_dominated`` of ``name``."""
        if name not in self.tolerance:
            return {}
        share = self.data_share.get(name, float("nan"))
        return {"tolerance": self.tolerance[name] / units.scale(self.quantities[name]),
                "data_share": float(share) if np.isfinite(share) else None,
                "prior_dominated": name in self.dominated}

    def to_json(self, units: Units) -> dict:
        source = {"source": "tolerance", "belongs": None} if self.use is None else \
            self.use.to_json()
        return {"rule": self.rule,
                "noise": self.noise / units.length_scale if np.isfinite(self.noise) else None,
                "unit": units.length, "dominated": list(self.dominated), **source}


@dataclass(frozen=True)
class SphereEstimate:
    """A sphere's centre [m] (base frame) with standard errors, and its radius [m]."""

    label: str
    role: str  # "fit" | "validation"
    centre: tuple[float, float, float]
    centre_std: tuple[float | None, ...] | None
    radius: float

    def to_json(self, units: Units) -> dict:
        s = units.length_scale
        return {"dataset": self.label, "role": self.role,
                "centre": [c / s for c in self.centre],
                "centre_std": None if self.centre_std is None else
                [None if c is None else c / s for c in self.centre_std],
                "radius": self.radius / s, "unit": units.length}


PERCENTILES = (50, 95, 99)


def error_statistics(errors: np.ndarray, scale: float = 1.0) -> dict:
    """RMS, percentiles and maximum of the error lengths ``errors`` [m], divided by ``scale``."""
    e = np.abs(np.asarray(errors, float)) / scale
    if not e.size:
        return {"count": 0}
    out = {"count": int(e.size), "rms": float(np.sqrt(np.mean(e**2)))}
    for p in PERCENTILES:
        out[f"p{p}"] = float(np.percentile(e, p))
    out["max"] = float(e.max())
    return out


def _per_dataset(residuals, units: Units) -> list[dict]:
    """Per dataset: RMS at each stage and the final model's percentiles and maximum."""
    s = units.length_scale
    out = []
    for r in residuals:
        rms = {f"rms_{stage}": error_statistics(getattr(r, f"errors_{stage}"), s).get("rms")
               for stage in ("nominal", "geometric", "final")}
        out.append({"dataset": r.label, "kind": r.kind, **rms,
                    "final": error_statistics(r.errors_final, s)})
        if r.placement_frame:
            out[-1]["validation_frame"] = r.placement_frame
    return out


@dataclass(frozen=True)
class RmsSummary:
    """RMS of the per-measurement errors [m]: nominal, geometric, final."""

    rms_nominal: float
    rms_geometric: float
    rms_final: float

    def to_json(self, units: Units) -> dict:
        s = units.length_scale
        return {"unit": units.length, "rms_nominal": self.rms_nominal / s,
                "rms_geometric": self.rms_geometric / s, "rms_final": self.rms_final / s}


@dataclass(frozen=True)
class RejectedReading:
    """A unit of data set aside as a gross error (``calibration.outliers``).

    ``line`` is the data table's line of the reading (for a placement set aside whole,
    that of the touch that looks wrong, ``suspect`` naming the candidates); ``lines``
    every line set aside with it, ``rows`` their 0-based rows (the order they were taken
    in), ``position`` where the point measured lay (base frame; the mean of a
    placement's touches). ``residual`` [m] is the length of its error under the model
    fitted without it, ``threshold`` [m] the length noise reaches there at the
    false-alarm rate; ``role`` ``"fit"`` or ``"validation"``.
    """

    dataset: str
    table: str
    line: int
    lines: tuple[int, ...]
    rows: tuple[int, ...]
    residual: float
    threshold: float
    reading: str  # "tracker point" | "laser reading" | "touch" | "placement"
    suspect: str = ""
    role: str = "fit"
    position: tuple[float, float, float] | None = None  # [m] base frame, the point measured
    path: str = ""  # the dataset file as given (tells apart files of one name)

    def to_json(self, units: Units) -> dict:
        s = units.length_scale
        out = {"dataset": self.dataset, "line": self.line, "residual": self.residual / s,
               "threshold": self.threshold / s, "unit": units.length, "table": self.table,
               "lines": list(self.lines), "reading": self.reading, "role": self.role,
               "position": None if self.position is None else [v / s for v in self.position]}
        if self.suspect:
            out["suspect"] = self.suspect
        return out

    def sentence(self, units: Units) -> str:
        """One line: where, what, and by how much."""
        s = units.length_scale
        what = self.reading + (f" ({self.suspect})" if self.suspect else "")
        return (f"{self.table} line {self.line}: {what}, error {self.residual / s:.4g} "
                f"{units.length} against a threshold of {self.threshold / s:.4g} {units.length}")


@dataclass(frozen=True)
class StructureTest:
    """One variable against one geometric parameter: the numbers of its test
    (``calibration.unexplained``)."""

    variable: str
    parameter: str
    columns: int  # free columns after projection
    statistic: float  # n log(RSS0 / RSS1)
    threshold: float  # chi-square quantile it must exceed
    rss_drop: float  # relative

    @property
    def significant(self) -> bool:
        return self.statistic > self.threshold

    def __repr__(self) -> str:
        return (f"StructureTest({self.parameter} ~ {self.variable}: {self.statistic:.4g} "
                f"vs {self.threshold:.4g}, rss -{100 * self.rss_drop:.3g}%)")


@dataclass(frozen=True)
class Unexplained:
    """A structured residual the model does not explain (``calibration.unexplained``).

    ``rms`` [m] is the structured part (per-measurement RMS, as the fit RMS; at most the
    fit RMS), ``share`` its fraction of the remaining mean square, ``variables`` the
    variables it follows, strongest first, ``parameters`` the geometric parameter that
    varies with each (the likeliest carrier, not a diagnosis), ``noise_floor`` [m] the
    held-out RMS once the structure is fitted. ``curve`` holds per data row the strongest
    variable's value (SI, or the column's own unit) and the RMS [m] of the row's residual
    entries before
    and after removing the structure, for a plot.
    """

    rms: float
    share: float
    variables: tuple[str, ...]
    parameters: tuple[str, ...]
    noise_floor: float
    tests: tuple[StructureTest, ...] = field(repr=False, default=())
    curve: dict[str, np.ndarray] = field(repr=False, default_factory=dict)

    def to_json(self, length_scale: float, unit: str) -> dict[str, Any]:
        """The result file's form: rms in the file's length unit."""
        return {"rms": self.rms / length_scale, "unit": unit, "share": self.share,
                "variables": list(self.variables)}

    def sentence(self, length_scale: float, unit: str, remainder: Remainder | None = None
                 ) -> str:
        """One sentence for a person, in the file's length unit; with ``remainder``, what
        would remain is called a noise floor only where the instrument's noise explains it."""
        pairs = [f"{p} with {v}" for v, p in zip(self.variables, self.parameters)]
        floor = (f"the noise floor is about {self.noise_floor / length_scale:.3g} {unit}"
                 if remainder is None else
                 remainder.floor_words(self.noise_floor, length_scale, unit))
        return (f"a structured residual of {self.rms / length_scale:.3g} {unit} RMS "
                f"({100 * self.share:.3g}% of what remains) follows {', '.join(self.variables)}"
                f" (it behaves like {'; '.join(pairs)}); no effect in the library explains "
                f"it; {floor}")




@dataclass(frozen=True)
class CandidateFigures:
    """One geometry-only model the delivery weighed (``job.choice``): its RMS [m]
    on the fit data and on held-out data (None without any)."""

    name: str
    fit: float
    held_out: float | None


@dataclass(frozen=True)
class Delivered:
    """What each output file delivers, measured from the files as written
    (``job.run.measured``).

    ``model`` is the candidate ``robot_calibrated.yaml`` holds (``geometric``,
    ``nominal``, ...), ``robot_file`` its RMS [m] by role (``fit``, ``validation``),
    ``errors`` its per-measurement errors [m] by role, ``mounted`` the instrument values
    [SI] that go with it; ``with_effects`` the RMS [m] by role of the model with
    ``effects_calibrated.yaml`` (None when no effects are delivered); ``basis`` and
    ``reason`` what the choice rested on and why; ``candidates`` every geometry-only
    model it weighed.
    """

    model: str
    robot_file: dict[str, float]
    with_effects: dict[str, float] | None
    mounted: dict[str, float]
    errors: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    basis: str = ""
    reason: str = ""
    candidates: tuple[CandidateFigures, ...] = ()

    def to_json(self, units: Units, quantities: dict[str, str]) -> dict:
        """The ``result.json`` block in the robot file's units, with what each output
        applies; ``quantities`` names the quantity of each mounted value (default length)."""
        s, unit = units.length_scale, units.length

        def scaled(block: dict[str, float]) -> dict:
            return {role: value / s for role, value in block.items()} | {"unit": unit}

        mounted = {name: value / units.scale(quantities.get(name, "length"))
                   for name, value in self.mounted.items()}
        out: dict[str, Any] = {"robot_calibrated.yaml": {
            "applies": "the calibrated geometry only (robocal fk, robocal compensate, a "
                       "controller's DH table)",
            "model": self.model, **scaled(self.robot_file), "mounted": mounted}}
        out["chosen_by"] = self.basis
        out["reason"] = self.reason
        if self.candidates:
            out["candidates"] = {
                c.name: {"fit": c.fit / s, "held_out": None if c.held_out is None else
                         c.held_out / s, "unit": unit} for c in self.candidates}
        if self.with_effects:
            out["effects_calibrated.yaml"] = {
                "applies": "the calibrated geometry with the identified effects (robocal fk "
                           "and robocal compensate --with-effects)",
                **scaled(self.with_effects)}
        return out


# Where a predicted accuracy holds (``PredictedAccuracy.region_kind``), and its sample size.
SAMPLES = 400
DATA_RANGES = "joint ranges of the fit data"
DECLARED = "declared work cell"
PARTLY_DECLARED = "declared work cell, other joints the ranges of the fit data"
MEASURED = "poses of the fit data"
BAND = (0.1, 0.9)  # quantiles of one robot's RMS over the work cell a prediction gives
BAND_SEED = 9283  # the band's draws are seeded: a prediction is repeatable
BAND_DRAWS = 20000  # draws of the parameter error behind a band (quantile error ~0.5%)


BOX_RATIO = 2.0  # the box figure is stated beside the poses' when they differ by more


@dataclass(frozen=True)
class ErrorFigures:
    """RMS, 95th percentile and maximum [m] of a predicted tool-position error over the
    poses of a region."""

    rms: float
    p95: float
    max: float

    @staticmethod
    def of(errors: np.ndarray) -> ErrorFigures:
        errors = np.asarray(errors, dtype=float)
        return ErrorFigures(float(np.sqrt(np.mean(errors**2))), float(np.percentile(errors, 95)),
                            float(errors.max()))

    def to_json(self, length_scale: float) -> dict:
        return {"rms": self.rms / length_scale, "p95": self.p95 / length_scale,
                "max": self.max / length_scale}


@dataclass(frozen=True)
class Unseen:
    """A parameter the data barely see: ``name``, the RMS [m] its remaining uncertainty
    puts on the tool over the box of joint ranges (``rms``: how much of the box figure it
    carries), and what it would take to see it (``remedy``, words)."""

    name: str
    rms: float
    remedy: str

    def to_json(self, length_scale: float) -> dict:
        return {"parameter": self.name, "rms": self.rms / length_scale, "to_see_it": self.remedy}


@dataclass(frozen=True)
class PredictedAccuracy:
    """Predicted tool-position error over ``region`` [m]: ``rms``, ``p95``, ``max``;
    ``structured`` [m] the part from what the model does not describe (``s``, RMS over
    the poses); ``region`` the joint ranges (per joint ``[low, high]``, rad or m); ``band``
    [m] the ``BAND`` quantiles of one robot's RMS over the region (module docstring).
    ``nominal``: the nominal robot's predicted error over the same poses, for "calibrated
    or not" read on one region. Where the region is the measured poses, ``box`` is the
    prediction over the box of joint ranges they span and ``unseen`` the parameters that
    carry the difference (stated when the two differ by more than ``BOX_RATIO``); else,
    where the figure is more than ``BOX_RATIO`` times the delivered file's ``held_out``
    RMS, ``unseen`` the parameters that carry the figure."""

    rms: float
    p95: float
    max: float
    structured: float
    region: tuple[tuple[float, float], ...]
    samples: int = SAMPLES
    errors: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)  # per pose [m]
    region_kind: str = DATA_RANGES  # DATA_RANGES, DECLARED, PARTLY_DECLARED or MEASURED
    band: tuple[float, float] | None = None
    nominal: ErrorFigures | None = None
    box: PredictedAccuracy | None = None
    unseen: tuple[Unseen, ...] = ()
    held_out: float | None = None  # [m] the delivered file's held-out RMS, when given

    def to_json(self, length_scale: float, unit: str, angle_unit: str = "rad") -> dict:
        out: dict[str, Any] = {"rms": self.rms / length_scale, "p95": self.p95 / length_scale,
               "max": self.max / length_scale, "structured": self.structured / length_scale,
               "rms_band": (None if self.band is None else
                            [self.band[0] / length_scale, self.band[1] / length_scale]),
               "rms_band_quantiles": list(BAND),
               "unit": unit,
               "region": {"kind": self.region_kind, "samples": self.samples,
                          "joints_rad_or_m": [list(r) for r in self.region]},
               "nominal": None if self.nominal is None else self.nominal.to_json(length_scale)}
        if self.box is not None:
            out["box"] = self.box.to_json(length_scale, unit, angle_unit)
            out["box_differs"] = self.box_differs
        out["unseen"] = [u.to_json(length_scale) for u in self.unseen]
        return out

    @property
    def held_out_differs(self) -> bool:
        """The figure is more than ``BOX_RATIO`` times the delivered file's held-out RMS."""
        return self.held_out is not None and self.rms > BOX_RATIO * self.held_out

    @property
    def box_differs(self) -> bool:
        """The box of joint ranges gives a figure more than ``BOX_RATIO`` from this one."""
        if self.box is None or self.rms <= 0:
            return False
        ratio = self.box.rms / self.rms
        return bool(ratio > BOX_RATIO or ratio < 1 / BOX_RATIO)

    @property
    def region_words(self) -> str:
        """Where the prediction holds, for sentences."""
        return {DECLARED: "the declared work cell",
                PARTLY_DECLARED: "the declared work cell (other joints: the ranges the data "
                                 "cover)",
                MEASURED: "the poses the data cover"}.get(
            self.region_kind, "the whole box of joint ranges the data cover")

    @property
    def band_words(self) -> str:
        """The band in words (its quantiles as a probability), for sentences."""
        return f"{round(100 * (BAND[1] - BAND[0]))}% of robots calibrated like this"

    def sentence(self, length_scale: float, unit: str) -> str:
        """The terminal's statement: the figure over the region with the nominal robot's
        beside it, then, where it differs by more than ``BOX_RATIO``, the box figure and
        what carries the difference (one line each)."""
        s = length_scale
        band = "" if self.band is None else (
            f" ({self.band[0] / s:.3g} to {self.band[1] / s:.3g} for {self.band_words})")
        nominal = "" if self.nominal is None else (
            f"; nominal robot over the same poses: RMS {self.nominal.rms / s:.4g} {unit}")
        text = (f"predicted tool-position error over {self.region_words}: RMS "
                f"{self.rms / s:.4g}{band}, 95% {self.p95 / s:.4g}, max "
                f"{self.max / s:.4g} {unit}{nominal}")
        if self.box_differs and self.box is not None:
            text += "\n" + self.box_sentence(s, unit)
        elif self.held_out_differs and self.unseen:
            text += "\n" + self.held_out_sentence(s, unit)
        return text

    def held_out_sentence(self, length_scale: float, unit: str) -> str:
        """Why the figure is more than ``BOX_RATIO`` times the held-out RMS, in words."""
        s = length_scale
        named = "; ".join(f"{u.name} ({u.rms / s:.3g} {unit}): {u.remedy}" for u in self.unseen)
        return (f"more than {BOX_RATIO:g} times the held-out RMS ({(self.held_out or 0) / s:.4g} "
                f"{unit}): the uncertainty these data leave in {named}")

    def box_sentence(self, length_scale: float, unit: str) -> str:
        """The box figure and the parameters that carry its difference, in words."""
        s, box = length_scale, self.box
        if box is None:
            return ""
        nominal = "" if box.nominal is None else f", nominal robot {box.nominal.rms / s:.4g}"
        text = (f"over {box.region_words} (every joint combination within the measured "
                f"ranges): RMS {box.rms / s:.4g} {unit}{nominal}")
        if self.unseen:
            named = "; ".join(f"{u.name} ({u.rms / s:.3g} {unit}): {u.remedy}"
                              for u in self.unseen)
            return text + f"; carried by what these data do not see: {named}"
        return text + ("; the data determine the robot only near the measured poses: "
                       "measure more of the work cell (other poses, another placement of "
                       "the instrument)")

    def __repr__(self) -> str:
        return (f"PredictedAccuracy(rms={self.rms:.4g} m, p95={self.p95:.4g} m, "
                f"max={self.max:.4g} m)")


@dataclass(frozen=True)
class ProfileCost:
    """A calibration restricted to a controller ``profile``: the robot ``parameters`` it
    leaves free, the ones the unrestricted calibration identified but the profile holds
    (``held``), and the unrestricted calibration's RMS (``fit``, ``validation``; [m])
    to compare with the restricted result's own."""

    profile: str
    parameters: tuple[str, ...]
    held: tuple[str, ...]
    fit: RmsSummary
    validation: RmsSummary | None

    def to_json(self, units: Units, fit: RmsSummary, validation: RmsSummary | None) -> dict:
        """The ``profile`` block of result.json: RMS with and without the restriction
        (robot file length unit) for the geometric and the final model."""
        s = units.length_scale

        def compare(restricted: RmsSummary, free: RmsSummary) -> dict:
            return {"unit": units.length,
                    "rms_geometric": restricted.rms_geometric / s,
                    "rms_geometric_unrestricted": free.rms_geometric / s,
                    "rms_final": restricted.rms_final / s,
                    "rms_final_unrestricted": free.rms_final / s}

        out = {"name": self.profile, "parameters": list(self.parameters),
               "held": list(self.held), "fit": compare(fit, self.fit)}
        if validation is not None and self.validation is not None:
            out["validation"] = compare(validation, self.validation)
        return out

    def sentence(self, units: Units, fit: RmsSummary, validation: RmsSummary | None) -> str:
        """One terminal line: what the profile costs."""
        s, unit = units.length_scale, units.length
        text = (f"profile {self.profile}: fit RMS {fit.rms_final / s:.4g} {unit} "
                f"(unrestricted {self.fit.rms_final / s:.4g})")
        if validation is not None and self.validation is not None:
            text += (f", validation RMS {validation.rms_final / s:.4g} {unit} (unrestricted "
                     f"{self.validation.rms_final / s:.4g})")
        held = ", ".join(self.held[:8]) + (" ..." if len(self.held) > 8 else "")
        return text + (f"; holds {held}" if self.held else "; holds nothing the data determine")


DOING_NOTHING = ("nominal", "instrument_only")  # recommendations that refuse a calibration


@dataclass(frozen=True)
class Candidate:
    """One model a controller could run (``job.choice``): ``robot`` (geometry only)
    with the ``mounted`` instrument values [SI] that belong to it; ``fit_rms`` and
    ``held_out_rms`` [m] (None where not measured)."""

    name: str
    robot: Robot = field(repr=False)
    mounted: dict[str, float] = field(repr=False)
    fit_rms: float
    held_out_rms: float | None = None

    def __repr__(self) -> str:
        held = "" if self.held_out_rms is None else f", held out {self.held_out_rms:.4g} m"
        return f"Candidate({self.name!r}, fit {self.fit_rms:.4g} m{held})"


@dataclass(frozen=True)
class Delivery:
    """What is delivered (``job.choice``): ``recommended`` (``final``, ``geometric``,
    ``nominal`` or ``instrument_only``), ``delivered`` the candidate robot_calibrated.yaml holds,
    the ``basis`` of the decision (``held-out data`` or ``cross-validation``), every
    ``candidates`` scored, the held-out RMS [m] of the calibrated model the user would
    otherwise take (``calibrated_rms``) and of doing nothing (``nothing_rms``), and the
    ``reason`` in words."""

    recommended: str
    delivered: str
    basis: str
    candidates: tuple[Candidate, ...]
    reason: str
    calibrated_rms: float | None = None
    nothing_rms: dict[str, float] = field(default_factory=dict)

    @property
    def refused(self) -> bool:
        """The calibration is not better than doing nothing (exit status 3)."""
        return self.recommended in DOING_NOTHING

    def candidate(self, name: str) -> Candidate:
        for candidate in self.candidates:
            if candidate.name == name:
                return candidate
        raise KeyError(f"no candidate {name!r}; have {[c.name for c in self.candidates]}")

    @property
    def robot(self) -> Robot:
        """The geometry ``robot_calibrated.yaml`` holds."""
        return self.candidate(self.delivered).robot

    def __repr__(self) -> str:
        return (f"Delivery(recommended={self.recommended!r}, delivered={self.delivered!r}, "
                f"basis={self.basis!r}, candidates={list(self.candidates)})")


@dataclass(frozen=True)
class ErrorTerm:
    """What one per-measurement error is: ``kind`` is ``"position"`` (a 3-D point error,
    components x, y, z), ``"surface"`` (signed distance from a surface), ``"distance"``
    (measured minus known length between ``points``), ``"perpendicular"`` (``AC.BD / L``
    for ``points`` A, C, B, D) or ``"error"``; ``pose`` is the placement id, -1 for none."""

    kind: str
    pose: int = -1
    points: tuple[str, ...] = ()


@dataclass(frozen=True)
class DatasetResiduals:
    """Per-measurement errors [m] of one dataset under each model, for reports.

    ``rows`` gives each error's data row (-1 for errors that belong to no single row,
    such as a bar-length error); ``joints`` (N x dof), ``extras`` and ``lines`` (the CSV
    line of each data row, None when unknown) are the dataset's.
    """

    label: str
    kind: str
    errors_nominal: np.ndarray
    errors_geometric: np.ndarray
    errors_final: np.ndarray
    rows: np.ndarray
    joints: np.ndarray | None
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    payload_com: np.ndarray | None = None  # [m], flange frame, where the dataset gives one
    # Signed parts of each error, per model ("nominal", "geometric", "final"): N x 3 [m],
    # x, y, z of a position error in ``frame``, column 0 alone (NaN after) for a scalar.
    components: dict[str, np.ndarray] = field(default_factory=dict)
    terms: tuple[ErrorTerm, ...] = ()  # what each error is (empty: not recorded)
    frame: str = ""  # frame of the position components: "instrument" or "base"
    lines: np.ndarray | None = None  # per data row, its line in the CSV table (1-based)
    # held-out data: how the instrument's placement was obtained ("station cell-A (fixed)"
    # or "fitted on these data"); empty for fit data
    placement_frame: str = ""

    def __repr__(self) -> str:
        rms = lambda e: float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")  # noqa: E731
        return (f"DatasetResiduals({self.label!r}, {len(self.errors_final)} errors, rms nominal "
                f"{rms(self.errors_nominal):.3g} m, final {rms(self.errors_final):.3g} m)")


@dataclass(frozen=True)
class CalibrationResult:
    """Everything a calibration produced. See ``to_json`` for ``result.json``."""

    datasets: tuple[str, ...]
    robot_nominal: Robot
    robot_calibrated: Robot
    parameters: tuple[ParameterEstimate, ...]
    identifiability: Identifiability
    condition_number: float
    effects: tuple[EffectFinding, ...]
    fit: RmsSummary
    validation: RmsSummary | None
    residuals: tuple[DatasetResiduals, ...]
    validation_residuals: tuple[DatasetResiduals, ...] = ()
    mounted: dict[str, tuple[float, float | None]] = field(default_factory=dict)
    mounted_quantities: dict[str, str] = field(default_factory=dict)  # name -> length | none
    placement: dict[str, float] = field(default_factory=dict)
    solver: dict[str, str | int | float] = field(default_factory=dict)
    effect_models: tuple[Effect, ...] = ()  # the effects fitted, values in ``effect_values``
    effect_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    diagnosis: tuple[DiagnosisRecord, ...] = ()  # every candidate tested, with its numbers
    selection: dict[str, tuple[int, ...]] = field(default_factory=dict)  # dropped units
    parameters_geometric: tuple[ParameterEstimate, ...] = ()  # the geometric fit's estimates
    unexplained: Unexplained | None = None  # None: what remains is consistent with noise
    recommended: str = "final"  # "final" | "geometric": the model held-out data support
    recommendation: str = ""  # why, in words
    prior: PriorSummary | None = None
    spheres: tuple[SphereEstimate, ...] = ()
    notes: tuple[str, ...] = ()  # what a reader of the numbers must know (e.g. repeated data)
    profile: ProfileCost | None = None  # when restricted to a controller's parameter set
    delivered: Delivered | None = None  # ``job.run.measured``: what each file delivers
    # The geometric fit's own instrument values [SI] and the posterior covariance [SI] of
    # its free robot and mounted parameters (``covariance_names``, in that order): what
    # the delivery and its predicted work-cell accuracy start from (``delivery``).
    mounted_geometric: dict[str, float] = field(default_factory=dict)
    covariance_names: tuple[str, ...] = ()
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    predicted_accuracy: PredictedAccuracy | None = None  # over the work cell
    delivery: Delivery | None = None  # what robot_calibrated.yaml holds, and why
    rejected: tuple[RejectedReading, ...] = ()  # units of data set aside as gross errors
    validation_all: RmsSummary | None = None  # held-out RMS over every reading (``validation``:
    # over the readings kept)
    remainder: Remainder | None = None  # what remains beside the instrument's noise

    @property
    def warning(self) -> str:
        """The first thing a person must read, or '' (held-out data reject the effects)."""
        if self.recommended != "geometric" or self.validation is None:
            return ""
        shown = display_units(self.units)
        s, unit = shown.length_scale, shown.length
        v = self.validation
        aside = self.held_out_set_aside
        kept = f", without the {aside} set aside as gross errors" if aside else ""
        return (f"the held-out data show the model with effects WORSE than the geometric one "
                f"(validation RMS {v.rms_final / s:.4g} vs {v.rms_geometric / s:.4g} {unit}"
                f"{kept}): the geometric model is recommended and is what "
                f"robot_calibrated.yaml holds. {HELD_OUT_DECIDE}")

    @property
    def held_out_set_aside(self) -> int:
        """Held-out readings set aside as gross errors (0 without held-out data)."""
        return sum(len(e.lines) for e in self.rejected if e.role == "validation")

    @property
    def units(self) -> Units:
        return self.robot_nominal.units

    def parameter(self, name: str) -> ParameterEstimate:
        for entry in self.parameters:
            if entry.name == name:
                return entry
        raise KeyError(f"no parameter {name!r}; names: {[p.name for p in self.parameters]}")

    def to_json(self) -> dict:
        """The ``result.json`` content (docs/formats.md#result-file), in the robot file's units."""
        units = self.units
        out: dict[str, Any] = {
            "datasets": list(self.datasets),
            "convention": self.robot_nominal.convention,
            "parameters": [self._parameter_json(p, units) for p in self.parameters],
            "condition_number": float(self.condition_number),
            "effects": [e.to_json(units) for e in self.effects],
            "fit": {**self.fit.to_json(units),
                    "datasets": _per_dataset(self.residuals, units)},
        }
        if self.validation is not None:
            out["validation"] = self._validation_json(self.validation, units)
        out["rejected"] = [e.to_json(units) for e in self.rejected]
        out["mounted"] = self._mounted_json(units)
        if self.prior is not None:
            out["prior"] = self.prior.to_json(units)
        if self.spheres:
            out["spheres"] = [s.to_json(units) for s in self.spheres]
        if self.notes:
            out["notes"] = list(self.notes)
        out["identifiability"] = self.identifiability.to_json()
        out["solver"] = {k: v for k, v in self.solver.items()
                         if isinstance(v, (int, float, str, bool))}
        out["recommended"] = self.recommended
        out["parameters_geometric"] = [p.to_json(units) for p in self.parameters_geometric]
        out["unexplained"] = self._unexplained_json(units)
        if self.selection:
            out["selection"] = {"dropped": {k: list(v) for k, v in self.selection.items()}}
        if self.profile is not None:
            out["profile"] = self.profile.to_json(units, self.fit, self.validation)
        if self.delivered is not None:
            out["delivered"] = self.delivered.to_json(units, self.mounted_quantities)
        if self.delivery is not None:
            out["recommendation"] = self.recommendation
        out["predicted_accuracy"] = (None if self.predicted_accuracy is None else
                                     self.predicted_accuracy.to_json(units.length_scale,
                                                                     units.length))
        return out

    def _unexplained_json(self, units: Units) -> dict | None:
        """The structure found (``rms``, ``share``, ``variables``; null and empty when none)
        beside what remains and the instrument's noise; None with neither."""
        if self.unexplained is None and self.remainder is None:
            return None
        out: dict[str, Any] = {"rms": None, "unit": units.length, "share": None,
                               "variables": []}
        if self.unexplained is not None:
            out = self.unexplained.to_json(units.length_scale, units.length)
        if self.remainder is not None:
            out.update(self.remainder.to_json(units))
        return out

    def _validation_json(self, validation: RmsSummary, units: Units) -> dict:
        """The held-out block: RMS over the readings kept (also as ``kept``) and over all
        of them, the count set aside, and per dataset."""
        every = self.validation_all or validation
        return {**validation.to_json(units), "kept": validation.to_json(units),
                "all": every.to_json(units),
                "rejected": sum(e.role == "validation" for e in self.rejected),
                "datasets": _per_dataset(self.validation_residuals, units)}

    def _mounted_json(self, units: Units) -> dict:
        """Each mounted instrument value with its standard error, in the file's units."""
        out = {}
        for name, (value, std) in self.mounted.items():
            quantity = self.mounted_quantities.get(name, "length")
            scale = units.scale(quantity)
            out[name] = {"estimate": value / scale, "std": None if std is None else std / scale,
                         "unit": units.unit_name(quantity),
                         **(self.prior.entry(name, units) if self.prior else {})}
        return out


    def _parameter_json(self, parameter: ParameterEstimate, units: Units) -> dict:
        entry = parameter.to_json(units)
        if self.prior is not None and parameter.identifiable:
            entry.update(self.prior.entry(parameter.name, units))
        return entry

    def _variables(self) -> tuple[str, ...]:
        return () if self.unexplained is None else self.unexplained.variables

    def __repr__(self) -> str:
        u = self.units
        s = u.length_scale
        lines = [
            f"CalibrationResult({', '.join(self.datasets)})",
            *([f"  WARNING: {self.warning}"] if self.warning else []),
            f"  identifiable parameters: {len(self.identifiability.identifiable)} of "
            f"{len(self.identifiability.candidates)}, condition number {self.condition_number:.4g}",
            f"  fit RMS [{u.length}]: nominal {self.fit.rms_nominal / s:.6g}, geometric "
            f"{self.fit.rms_geometric / s:.6g}, final {self.fit.rms_final / s:.6g}",
        ]
        if self.validation is not None:
            v = self.validation
            lines.append(f"  validation RMS [{u.length}]: nominal {v.rms_nominal / s:.6g}, "
                         f"geometric {v.rms_geometric / s:.6g}, final {v.rms_final / s:.6g}")
        for effect in self.effects:
            lines.append(f"  effect {effect.name} joints {list(effect.joints)}: {effect.summary}")
        lines.append(f"  recommended model: {self.recommended}")
        if self.unexplained is not None:
            lines.append("  unexplained: " + self.unexplained.sentence(s, u.length,
                                                                    self.remainder))
        if self.remainder is not None:
            lines.append("  remains: " + self.remainder.sentence(u, self._variables()))
        return "\n".join(lines)


def mean_square_shares(nominal: float, geometric: float, final: float,
                       findings: Sequence[EffectFinding]) -> dict[str, float] | None:
    """How the fit's mean square at nominal divides: removed by the geometry, by the
    physical effects, by a learned map, and what remains (fractions summing to 1), from
    the fit RMS values [m] (nominal, geometric, final). A learned finding records the fit
    RMS without it (``evidence["fit_rms_without"]``); None without effects or at a zero
    nominal error."""
    if not findings or not nominal > 0:
        return None
    mapped = next((f for f in findings if "fit_rms_without" in f.evidence), None)
    physical = float(mapped.evidence["fit_rms_without"]) if mapped is not None else final
    total = nominal ** 2
    return {"geometry": (nominal ** 2 - geometric ** 2) / total,
            "physical effects": (geometric ** 2 - physical ** 2) / total,
            "learned map": (physical ** 2 - final ** 2) / total,
            "remaining": final ** 2 / total}
