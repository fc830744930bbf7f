"""Checked reading of YAML files and their fields.

Every reader in the package goes through these helpers so that a bad value is reported
the same way everywhere: the file, the key path, what was expected and what was found.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError

_FLOAT_TEXT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def load_yaml(path: str | Path, *, what: str = "file") -> dict:
    """Read a YAML mapping; a missing file, bad YAML or a non-mapping is an ``InputError``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} not found", file=path)
    try:
        content = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else None
        raise InputError(f"not valid YAML ({getattr(error, 'problem', error)})", file=path,
                         where=where) from None
    if not isinstance(content, dict):
        raise InputError("expected a YAML mapping at the top level", file=path)
    return content


def number(value: Any, *, file: str | Path | None, where: str) -> float:
    """A finite float; booleans, strings, NaN and infinities are refused."""
    if isinstance(value, str) and _FLOAT_TEXT.fullmatch(value.strip()):
        # YAML 1.1 reads 1e-3 (no dot) as text; people write it, so accept it.
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {value!r}", file=file, where=where)
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"expected a finite number, got {value}", file=file, where=where)
    return value


def vector(value: Any, length: int, *, file: str | Path | None, where: str) -> list[float]:
    """A list of ``length`` finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise InputError(f"expected a list of {length} numbers, got {value!r}", file=file,
                         where=where)
    return [number(v, file=file, where=f"{where}[{i}]") for i, v in enumerate(value)]


def require(mapping: dict, key: str, *, file: str | Path | None, where: str = "") -> Any:
    """``mapping[key]`` or an ``InputError`` naming the missing key."""
    if key not in mapping:
        path = f"{where}.{key}" if where else key
        raise InputError("missing required key", file=file, where=path)
    return mapping[key]
