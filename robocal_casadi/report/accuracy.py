"""Accuracy in the spirit of ISO 9283: statistics of the error magnitude, before and after.

ISO 9283 states a robot's positioning accuracy from the distances between commanded and
attained positions; here the distances are the calibration's per-measurement errors
(the 3-D position error for tracker data, the data's own error for other kinds), and
the statistics are the mean, RMS, 99th percentile and maximum of their magnitude [m].

``delivered`` says what each output file delivers: ``robot_calibrated.yaml`` carries the
geometry only, so a controller loading it gets the geometric model's accuracy; the
effects (``effects_calibrated.yaml``) add their share where they are applied
(``robocal compensate`` and ``robocal fk`` with ``--with-effects``, or the controller's own
compensation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..results import CalibrationResult, DatasetResiduals
from .numbers import MODELS, pooled


@dataclass(frozen=True)
class Accuracy:
    """Mean, RMS, 99th percentile and maximum of ``|error|`` [m] over ``count`` errors."""

    count: int
    mean: float
    rms: float
    p99: float
    max: float

    @staticmethod
    def of(errors: np.ndarray) -> Accuracy:
        magnitude = np.abs(np.asarray(errors, dtype=float))
        if magnitude.size == 0:
            nan = float("nan")
            return Accuracy(0, nan, nan, nan, nan)
        return Accuracy(int(magnitude.size), float(magnitude.mean()),
                        float(np.sqrt(np.mean(magnitude**2))),
                        float(np.percentile(magnitude, 99)), float(magnitude.max()))


@dataclass(frozen=True)
class AccuracyRow:
    """One line of the summary: the data (``role``) under one model."""

    role: str  # "fit" | "validation"
    model: str  # "nominal" | "geometric" | "final"
    accuracy: Accuracy


def groups(result: CalibrationResult) -> list[tuple[str, tuple[DatasetResiduals, ...]]]:
    """``[("fit", residuals), ("validation", residuals)]``, validation only when given."""
    out = [("fit", tuple(result.residuals))]
    if result.validation_residuals:
        out.append(("validation", tuple(result.validation_residuals)))
    return out


def accuracy_rows(result: CalibrationResult) -> list[AccuracyRow]:
    """Every model on the fitting data and, when given, on the held-out data."""
    rows = []
    for role, residuals in groups(result):
        for model in MODELS:
            rows.append(AccuracyRow(role, model, Accuracy.of(pooled(residuals, model))))
    return rows


def effects_differ(result: CalibrationResult) -> bool:
    """True when the final model differs from the geometric one (effects were added)."""
    return bool(result.effects)


def judged_on(result: CalibrationResult) -> tuple[str, tuple[DatasetResiduals, ...]]:
    """The data the delivered accuracy is judged on: held-out when given, else the fit."""
    return groups(result)[-1]


@dataclass(frozen=True)
class Delivered:
    """What one output gives the controller, and the accuracy it delivers."""

    output: str
    contents: str
    model: str
    accuracy: Accuracy


def delivered(result: CalibrationResult) -> list[Delivered]:
    """The accuracy each output delivers, on held-out data when there is some."""
    _, residuals = judged_on(result)
    stats = {m: Accuracy.of(pooled(residuals, m)) for m in MODELS}
    written = _written_errors(result)
    model = "geometric" if result.delivered is None else result.delivered.model
    contents = ("calibrated geometry only: joint offsets, link lengths and twists, base and "
                "tool; load it into the controller or the offline programming system")
    if model in ("nominal", "instrument_only"):
        contents = ("the nominal geometry: calibrating did not do better than "
                    + ("leaving the robot as designed" if model == "nominal" else
                       "calibrating the mounted instrument alone"))
    elif model != "geometric":
        contents += (f" ({model.replace('_', ' ')} model, the best geometry-only model on "
                     f"held-out data)")
    out = [Delivered("the robot's nominal model (no calibration)",
                     "the robot file as designed", "nominal", stats["nominal"]),
           Delivered("robot_calibrated.yaml", contents, "geometric",
                     Accuracy.of(written) if written is not None else stats["geometric"])]
    if effects_differ(result):
        out.append(Delivered("robot_calibrated.yaml with effects_calibrated.yaml",
                             "geometry plus the effects found; the effects take hold where they "
                             "are applied: robocal compensate and robocal fk with "
                             "--with-effects, or the controller's own compensation; without "
                             "them robocal fk and compensate use the geometry alone", "final",
                             stats["final"]))
    return out


def _written_errors(result: CalibrationResult) -> np.ndarray | None:
    """Per-measurement errors [m] of robot_calibrated.yaml as written, on the data the
    delivered accuracy is judged on (``job.run.measured``), or None."""
    errors = {} if result.delivered is None else result.delivered.errors
    role, _ = judged_on(result)
    return errors.get(role)


def recommended(result: CalibrationResult) -> str:
    """``"geometric"`` or ``"final"``: the model to deliver.

    The result's own ``recommended`` when it carries one; otherwise ``"geometric"`` when
    held-out data show the model with effects doing worse than the geometric one.
    """
    given = getattr(result, "recommended", None)
    if given in ("geometric", "final"):
        return given
    if not result.effects:
        return "geometric"
    if result.validation is not None and \
            result.validation.rms_final > result.validation.rms_geometric:
        return "geometric"
    return "final"
