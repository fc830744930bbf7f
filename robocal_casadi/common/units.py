"""Units declared by files (``units: {length: mm | m, angle: deg | rad}``).

Everything inside the package is SI (metres, radians); files are converted on the way
in and on the way out so that a user's file round-trips in its own units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from .fields import check_keys, cut, mapping, require

LENGTH_SCALE = {"m": 1.0, "mm": 1e-3}
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
