"""Front-door checks of API arguments: names, counts, numbers, shapes.

Each check returns the canonical value (a ``str`` from a fixed set, an ``int``, a float
array of the expected shape) or raises ``ArgumentError`` naming the argument, what is
valid and what was given; a misspelt name gets the closest valid one as a suggestion.
"""

from __future__ import annotations

import difflib
import math
import operator
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..errors import ArgumentError


def _shown(value: Any) -> str:
    text = repr(value) if isinstance(value, (str, int, float, bool, type(None))) else (
        f"a {type(value).__name__}")
    return text if len(text) <= 60 else text[:57] + "..."


Name = TypeVar("Name", bound=str)


def choice(value: Any, valid: Sequence[Name], argument: str) -> Name:
    """``value`` if it is one of ``valid``; otherwise the valid names and the closest."""
    for name in valid:
        if isinstance(value, str) and value == name:
            return name
    listed = ", ".join(repr(v) for v in valid)
    hint = ""
    if isinstance(value, str):
        close = difflib.get_close_matches(value.lower(), list(valid), n=1, cutoff=0.5)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ArgumentError(f"unknown name {_shown(value)}; expected one of {listed}{hint}",
                            argument=argument)
    raise ArgumentError(f"expected one of {listed}, got {_shown(value)}", argument=argument)


def count(value: Any, argument: str, *, minimum: int = 1) -> int:
    """A whole number ``>= minimum`` (``bool`` and fractional numbers refused)."""
    if isinstance(value, bool):
        raise ArgumentError(f"expected a whole number >= {minimum}, got {value!r}",
                            argument=argument)
    try:
        number = operator.index(value)
    except TypeError:
        if isinstance(value, float) and value.is_integer():
            number = int(value)
        else:
            raise ArgumentError(f"expected a whole number >= {minimum}, got {_shown(value)}",
                                argument=argument) from None
    if number < minimum:
        raise ArgumentError(f"expected a whole number >= {minimum}, got {number}",
                            argument=argument)
    return int(number)


def positive(value: Any, argument: str, *, allow_zero: bool = False) -> float:
    """A finite number ``> 0`` (``>= 0`` with ``allow_zero``)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, bool) or not math.isfinite(number) or number < 0 or (
            number == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ArgumentError(f"expected a finite number {bound}, got {_shown(value)}",
                            argument=argument)
    return number


def array(value: Any, shape: tuple[int, ...], argument: str, *, finite: bool = True
          ) -> np.ndarray:
    """``value`` as a float array of ``shape`` (finite unless ``finite=False``)."""
    try:
        result = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"expected numbers of shape {shape}, got {_shown(value)}",
                            argument=argument) from None
    if result.shape != shape:
        raise ArgumentError(f"expected shape {shape}, got shape {result.shape}",
                            argument=argument)
    if finite and not np.all(np.isfinite(result)):
        raise ArgumentError("expected finite numbers, got NaN or infinity", argument=argument)
    return result


def rotation_matrix(value: Any, argument: str, *, tolerance: float = 1e-6) -> np.ndarray:
    """A 3x3 rotation: orthonormal to ``tolerance`` with determinant +1."""
    R = array(value, (3, 3), argument)
    if not (np.allclose(R.T @ R, np.eye(3), atol=tolerance) and np.linalg.det(R) > 0):
        raise ArgumentError(f"expected a rotation matrix (orthonormal, determinant +1), got "
                            f"determinant {np.linalg.det(R):.6g}", argument=argument)
    return R


def path_argument(value: Any, argument: str, *, what: str = "a file path") -> Path:
    """``value`` (text or a path-like object) as a ``Path``; anything else, and empty
    text, is an ``ArgumentError`` saying what was given."""
    if isinstance(value, (str, os.PathLike)) and not isinstance(value, bytes):
        path = Path(value)
        if str(value).strip():
            return path
        raise ArgumentError(f"expected {what}, got empty text", argument=argument)
    raise ArgumentError(f"expected {what}, got {_shown(value)}", argument=argument)
