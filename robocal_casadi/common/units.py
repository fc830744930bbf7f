"""Units declared by files (``units: {length: mm | m, angle: deg | rad}``).

Everything inside the package is SI (metres, radians); files are converted on the way
in and on the way out so that a user's file round-trips in its own units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any

from ..errors import InputError
from .fields import check_keys, cut, mapping, require

LENGTH_SCALE = {"m": 1.0, "mm": 1e-3}
DECIMAL_SCALE = {1e-3: Decimal("0.001")}  # the scales that are exact decimal shifts
ANGLE_SCALE = {"rad": 1.0, "deg": math.pi / 180.0}


@dataclass(frozen=True)
class Units:
    """A file's units. ``length`` is ``m`` or ``mm``; ``angle`` is ``rad`` or ``deg``."""

    length: str = "m"
    angle: str = "rad"

    @property
    def length_scale(self) -> float:
        """Metres per file length unit."""
        return LENGTH_SCALE[self.length]

    @property
    def angle_scale(self) -> float:
        """Radians per file angle unit."""
        return ANGLE_SCALE[self.angle]

    def scale(self, quantity: str) -> float:
        """SI units per file unit for ``quantity`` in {'length', 'angle', 'none'}."""
        if quantity == "length":
            return self.length_scale
        if quantity == "angle":
            return self.angle_scale
        return 1.0

    def unit_name(self, quantity: str) -> str:
        """The file's unit name for ``quantity`` ('' for dimensionless)."""
        return {"length": self.length, "angle": self.angle}.get(quantity, "")

    def as_dict(self) -> dict[str, str]:
        return {"length": self.length, "angle": self.angle}


SI = Units("m", "rad")


def display_units(units: Units) -> Units:
    """The units people read (terminal lines, reports): lengths in mm whatever the file uses
    (errors and corrections are millimetre-sized; one unit on every page and in every
    terminal block), angles in the file's angle unit."""
    return Units("mm", units.angle)


def parse_units(value: Any, *, file: str | Path | None, key: str = "units") -> Units:
    """Read a ``units`` mapping; missing or unknown names are an ``InputError``."""
    if not isinstance(value, dict):
        raise InputError(
            "expected a mapping like {length: mm, angle: deg}", file=file, where=key
        )
    length = value.get("length")
    angle = value.get("angle")
    if not isinstance(length, str) or length not in LENGTH_SCALE:
        raise InputError(
            f"unknown length unit {cut(length)}; expected one of {sorted(LENGTH_SCALE)}",
            file=file,
            where=f"{key}.length",
        )
    if not isinstance(angle, str) or angle not in ANGLE_SCALE:
        raise InputError(
            f"unknown angle unit {cut(angle)}; expected one of {sorted(ANGLE_SCALE)}",
            file=file,
            where=f"{key}.angle",
        )
    return Units(length, angle)


def units_of(content: dict, *, file: str | Path | None, key: str = "units"):
    """The file's ``units`` mapping as ``Units``; wrong types and unknown keys refused."""
    value = mapping(require(content, key, file=file), file=file, where=key,
                    hint="like {length: mm, angle: deg}")
    check_keys(value, ("length", "angle"), file=file, where=key)
    for name, known in (("length", LENGTH_SCALE), ("angle", ANGLE_SCALE)):
        if name not in value:
            raise InputError(f"missing required key; expected one of {sorted(known)}",
                             file=file, where=f"{key}.{name}")
        if value[name] is None:
            raise InputError(f"no {name} unit given; expected one of {sorted(known)}",
                             file=file, where=f"{key}.{name}")
        if not isinstance(value[name], str):
            raise InputError(f"unknown {name} unit {cut(value[name])}; expected one of "
                             f"{sorted(known)}", file=file, where=f"{key}.{name}")
    return parse_units(value, file=file, key=key)


def to_file_units(value: float, scale: float) -> float:
    """``value`` [SI] in file units (``value / scale``), written as the user would type it.

    Of two decimals, the one with fewer digits: the shortest that converts back to exactly
    ``value`` (a value read from a mm file, -0.5722999999999999 m, is written -572.3, not
    -572.2999999999999), and, for mm, ``value``'s own shortest decimal with the point moved
    three places (a value typed in metres, -0.5723 m, is written -572.3, not
    -572.3000000000001; it reads back within one unit in the last place).
    """
    if scale == 1.0:
        return float(value)
    exact = exact_file_units(value, scale)
    if scale not in DECIMAL_SCALE or not math.isfinite(value):
        return exact
    shifted = float(Decimal(repr(float(value))) / DECIMAL_SCALE[scale])
    return shifted if _digits(shifted) < _digits(exact) else exact


def exact_file_units(value: float, scale: float) -> float:
    """``value / scale`` as the shortest decimal that converts back to exactly ``value``
    [SI] (``value / scale`` itself where none does): what a file that must read back bit
    for bit holds (a simulated truth)."""
    plain = value / scale
    if scale == 1.0:
        return float(value)
    for digits in range(1, 18):
        candidate = float(f"{plain:.{digits}g}")
        if candidate * scale == value:
            return candidate
    return plain


def snapped(value: float, scale: float) -> float:
    """``value`` [SI] moved (by at most a unit in the last place) to what its decimal in a
    file of ``scale`` reads back as (``exact_file_units``): a value a file states exactly."""
    return float(value) if scale == 1.0 else exact_file_units(float(value), scale) * scale


def _digits(number: float) -> int:
    """Significant digits of ``number``'s shortest decimal."""
    return len(Decimal(repr(number)).normalize().as_tuple().digits)
