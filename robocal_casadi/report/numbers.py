"""Numbers for the report: error statistics and display formatting in the file's units.

Errors arrive in SI [m]; everything shown is in the robot file's units
(``result.units``): lengths in mm or m, angles in deg or rad, joint readings of
prismatic joints in the length unit.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..common.units import Units, display_units  # noqa: F401  (the report imports it from here)
from ..instruments import INSTRUMENTS
from ..model.robot import Robot
from ..results import DatasetResiduals

MODELS = ("nominal", "geometric", "final")
MODEL_TITLES = {"nominal": "nominal robot", "geometric": "geometric calibration",
                "final": "with effects"}

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
        kind = kinds.pop()
        return INSTRUMENTS[kind].model.error_title if kind in INSTRUMENTS else "error"
    return "error"


def dataset_name(residuals: DatasetResiduals) -> str:
    """The dataset's name as a reader knows it (its file's stem), without the role prefix
    the calibration keys held-out data by (``validation:``): the role is shown beside it."""
    return residuals.label.removeprefix("validation:")


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


def format_at_resolution(value: float, resolution: float, *, sign: bool = False) -> str:
    """``value`` rounded to the decimal place of ``resolution`` (both in one unit, > 0):
    a value below the resolution prints as ``0``, never as ``+2.49e-14``. ``sign`` puts a
    ``+`` before positive values; '-' for a value that is not finite."""
    if not math.isfinite(value):
        return "-"
    if not (math.isfinite(resolution) and resolution > 0):
        return "0" if value == 0 else f"{value:{'+' if sign else ''}.3g}"
    places = -math.floor(math.log10(resolution))
    rounded = round(value, places)
    if rounded == 0:
        return "0"
    return f"{rounded:{'+' if sign else ''}.{max(places, 0)}f}"


def resolution_of(spread: float, digits: int = 3) -> float:
    """The resolution of a number printed with ``digits`` significant digits: one unit of
    its last digit (NaN for a spread that is zero or not finite)."""
    if not (math.isfinite(spread) and spread > 0):
        return math.nan
    return 10.0 ** (math.floor(math.log10(spread)) - digits + 1)


_TERM = re.compile(r"([+-](?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\*([A-Za-z_][\w./\[\]-]*)")


def relation_in_units(relation: str, left: str, quantity_of: Callable[[str], str],
                      units: Units) -> str:
    """A relation ``+c*name ...`` saying what a change of ``left`` acts like, with the
    coefficients in SI (``name``'s unit per ``left``'s unit: m/rad for a length standing in
    for an angle), rewritten for the report's ``units`` (mm/rad with lengths in mm)."""
    source = units.scale(quantity_of(left))

    def convert(match: re.Match) -> str:
        name = match.group(2)
        factor = float(match.group(1)) * source / units.scale(quantity_of(name))
        return f"{factor:+.4g}*{name}"

    return _TERM.sub(convert, relation)
