"""The instrument's own noise: one reading's standard deviation per coordinate.

A dataset file may declare it (``instrument_noise:``, in the file's length unit): a
number, the standard deviation of each coordinate of one reading (each of a tracker
point's x, y, z; each coordinate of a touch; a laser's distance); a tracker may give
``{a: ..., b_per_m: ...}``, ``a + b_per_m * range`` with ``range`` the distance from the
tracker to the reflector in metres (how a tracker's uncertainty is specified). Without the
key, each measurement model offers a typical value for its instrument
(``MeasurementModel.default_noise``) and the record says it is a default.

What the noise means for the residual is the model's to say
(``MeasurementModel.entry_noise``): the standard deviation [m] of each residual entry the
instrument's noise alone would give. ``expected_rms`` turns that into the RMS over the
per-measurement errors (the figure the fit and held-out RMS values are), so what remains
after calibration compares with it directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common.fields import check_keys, cut, number
from ..common.units import Units
from ..errors import InputError

DECLARED = "declared"
DEFAULT = "default"
MAX_NOISE = 0.1  # [m] one reading's standard deviation beyond this is a unit mix-up
MAX_GROWTH = 1e-3  # [m per m] a tracker's uncertainty growing faster is a unit mix-up


@dataclass(frozen=True)
class InstrumentNoise:
    """One reading's standard deviation per coordinate: ``a + b_per_m * range`` [m],
    ``range`` [m] the distance from the instrument to the point it reads (tracker), zero
    for instruments whose noise does not grow with distance. ``source``: ``"declared"``
    (the dataset file) or ``"default"`` (the instrument's typical value)."""

    a: float  # [m]
    b_per_m: float = 0.0  # [m per m of range]
    source: str = DEFAULT

    def at(self, distance: np.ndarray | float) -> np.ndarray:
        """The standard deviation [m] at ``distance`` [m] from the instrument."""
        return self.a + self.b_per_m * np.asarray(distance, dtype=float)

    def to_json(self, units: Units) -> dict[str, Any]:
        """``{value, unit, source}`` in the file's length unit, ``b_per_m`` (length unit
        per metre) where the noise grows with range."""
        s = units.length_scale
        out: dict[str, Any] = {"value": self.a / s, "unit": units.length, "per": "coordinate",
                               "source": self.source}
        if self.b_per_m:
            out["b_per_m"] = self.b_per_m / s
        return out

    def words(self, units: Units) -> str:
        """The noise in the file's length unit, e.g. ``0.01 mm + 0.003 mm/m``."""
        s, u = units.length_scale, units.length
        text = f"{self.a / s:.3g} {u}"
        return text + (f" + {self.b_per_m / s:.3g} {u}/m" if self.b_per_m else "")


def declared(value: Any, units: Units, *, grows_with_range: bool,
             path: Path) -> InstrumentNoise | None:
    """The ``instrument_noise`` key in SI, or None when absent. A number (file length
    unit) > 0; where ``grows_with_range`` (a tracker) also ``{a, b_per_m}`` with ``a`` >
    0 and ``b_per_m`` >= 0. Anything else is an ``InputError`` naming the key."""
    if value is None:
        return None
    s, unit = units.length_scale, units.length
    if isinstance(value, dict):
        if not grows_with_range:
            raise InputError(f"expected one number (the standard deviation of a reading's "
                             f"coordinate, {unit}), got {cut(value)}; only a tracker's noise "
                             f"may grow with range", file=path, where="instrument_noise")
        check_keys(value, ("a", "b_per_m"), file=path, where="instrument_noise")
        if "a" not in value:
            raise InputError(f"missing required key (the noise at zero range, {unit})",
                             file=path, where="instrument_noise.a")
        a = _checked(value["a"], s, unit, path, "instrument_noise.a", MAX_NOISE)
        b = 0.0
        if value.get("b_per_m") is not None:
            b = _checked(value["b_per_m"], s, f"{unit}/m", path, "instrument_noise.b_per_m",
                         MAX_GROWTH, allow_zero=True)
        return InstrumentNoise(a, b, DECLARED)
    return InstrumentNoise(_checked(value, s, unit, path, "instrument_noise", MAX_NOISE),
                           0.0, DECLARED)


def _checked(value: Any, scale: float, unit: str, path: Path, where: str, limit: float,
             *, allow_zero: bool = False) -> float:
    raw = number(value, file=path, where=where)
    si = raw * scale
    if si < 0 or (si == 0 and not allow_zero):
        raise InputError(f"expected a standard deviation above 0 {unit}, got {cut(value)}",
                         file=path, where=where)
    if si > limit:
        raise InputError(f"{cut(value)} {unit} is no instrument's noise (above "
                         f"{limit / scale:g} {unit}): check the length unit", file=path,
                         where=where)
    return si


def expected_rms(models) -> float:
    """The RMS [m] over the per-measurement errors of ``models`` that the instruments'
    noise alone gives (each error's expected square is the sum of its entries'
    variances: the errors are lengths of blocks of residual entries)."""
    squares = [m.errors(m.entry_noise()) ** 2 for m in models]
    total = np.concatenate(squares) if squares else np.zeros(0)
    return float(np.sqrt(np.mean(total))) if total.size else float("nan")
