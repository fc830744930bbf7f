"""Numbers for the report: error statistics and display formatting in the file's units.

Errors arrive in SI [m]; everything shown is in the robot file's units
(``result.units``): lengths in mm or m, angles in deg or rad, joint readings of
prismatic joints in the length unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..measurement import MODELS as MEASUREMENT_MODELS
from ..results import DatasetResiduals
from ..robot import Robot
from ..units import Units

MODELS = ("nominal", "geometric", "final")
MODEL_TITLES = {"nominal": "nominal robot", "geometric": "geometric calibration",
                "final": "with effects"}

ERROR_NOUN = {kind: model.error_title for kind, model in MEASUREMENT_MODELS.items()}


def format_number(value: float | None, digits: int = 4) -> str:
    """``value`` with ``digits`` significant digits; '-' for None or NaN."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if value == 0:
        return "0"
    return f"{value:.{digits}g}"


def format_fixed(value: float, decimals: int = 4) -> str:
    """``value`` with at most ``decimals`` decimals, trailing zeros removed (a parameter value)."""
    if not math.isfinite(value):
        return str(value)
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def parameter_decimals(units: Units, quantity: str) -> int:
    """Decimals that resolve a micrometre or a microradian in the file's units."""
    if quantity == "length":
        return 4 if units.length == "mm" else 7
    if quantity == "angle":
        return 5 if units.angle == "deg" else 7
    return 6


def rms(errors: np.ndarray) -> float:
    """Root mean square of ``errors``; NaN when empty."""
    errors = np.asarray(errors, dtype=float)
    return float(np.sqrt(np.mean(errors**2))) if errors.size else float("nan")


def percentile_abs(errors: np.ndarray, q: float) -> float:
    """The ``q``-th percentile of ``|errors|``; NaN when empty."""
    errors = np.asarray(errors, dtype=float)
    return float(np.percentile(np.abs(errors), q)) if errors.size else float("nan")


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of one error set [m]: RMS, 95th and 99th percentile and max of ``|e|``."""

    count: int
    rms: float
    p95: float
    p99: float
    max: float

    @staticmethod
    def of(errors: np.ndarray) -> ErrorStats:
        errors = np.asarray(errors, dtype=float)
        worst = float(np.max(np.abs(errors))) if errors.size else float("nan")
        return ErrorStats(int(errors.size), rms(errors), percentile_abs(errors, 95),
                          percentile_abs(errors, 99), worst)


def errors_of(residuals: DatasetResiduals, model: str) -> np.ndarray:
    """The per-measurement errors [m] of ``residuals`` under ``model`` (see ``MODELS``)."""
    return np.asarray(getattr(residuals, f"errors_{model}"), dtype=float)


def pooled(residuals: tuple[DatasetResiduals, ...], model: str) -> np.ndarray:
    """All errors [m] of several datasets under ``model``, concatenated."""
    if not residuals:
        return np.zeros(0)
    return np.concatenate([errors_of(r, model) for r in residuals])


def error_noun(residuals: tuple[DatasetResiduals, ...]) -> str:
    """What the errors measure, in words, for one kind of data; 'error' for a mix."""
    kinds = {r.kind for r in residuals}
    if len(kinds) == 1:
        return ERROR_NOUN.get(kinds.pop(), "error")
    return "error"


def row_count(residuals: DatasetResiduals) -> int:
    """Data rows of a dataset: the joint table's length, else the highest mapped row + 1."""
    if residuals.joints is not None:
        return int(len(residuals.joints))
    mapped = np.asarray(residuals.rows)
    return int(mapped.max() + 1) if mapped.size and mapped.max() >= 0 else 0


def joint_reading_unit(robot: Robot, joint: int, units: Units) -> tuple[float, str]:
    """``(SI per display unit, unit name)`` of joint ``joint``'s reading (0-based)."""
    if robot.joints[joint].revolute:
        return units.angle_scale, units.angle
    return units.length_scale, units.length


def quantity_of_placement(name: str) -> str:
    """The quantity of a placement or mounted unknown, read from its name's last part."""
    last = name.rsplit(".", 1)[-1].rsplit("_", 1)[-1].lower()
    if last in ("rx", "ry", "rz", "roll", "pitch", "yaw"):
        return "angle"
    if last in ("nx", "ny", "nz") or "direction" in name.lower():
        return "none"
    return "length"


def display_units(units: Units) -> Units:
    """The units the report shows: lengths in mm whatever the file uses (errors and
    corrections are millimetre-sized), angles in the file's angle unit."""
    return Units("mm", units.angle)
