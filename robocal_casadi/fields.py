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
from .units import ANGLE_SCALE, LENGTH_SCALE, parse_units

_FLOAT_TEXT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


class _StrictLoader(yaml.SafeLoader):
    """``SafeLoader`` that refuses a key written twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            try:
                key = self.construct_object(key_node, deep=True)
                hash(key)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None, None, "a mapping key must be a plain value", key_node.start_mark
                ) from None
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first on line {seen[key] + 1})",
                    key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def _describe(value: Any) -> str:
    """A short name of what a YAML value is, for messages."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, (int, float)):
        return f"a number ({value!r})"
    if isinstance(value, str):
        text = repr(value)
        return f"text ({text if len(text) < 60 else text[:50] + '...'})"
    if isinstance(value, list):
        return f"a list ({value!r})" if len(repr(value)) < 60 else f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


def read_text(path: Path, *, what: str = "file") -> str:
    """The UTF-8 text of ``path`` (a leading byte-order mark dropped); an ``InputError``
    for a missing file, a folder, an unreadable file or bytes that are not UTF-8."""
    if path.is_dir():
        raise InputError(f"expected a {what}, found a folder", file=path)
    if not path.is_file():
        raise InputError(f"{what} not found", file=path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"cannot read the {what} ({error.strerror})", file=path) from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise InputError(f"not UTF-8 text (byte 0x{data[error.start]:02x}); save the {what} "
                         "as UTF-8", file=path, where=f"line {line}") from None
    if "\x00" in text:
        line = text[:text.index("\x00")].count("\n") + 1
        raise InputError(f"a NUL byte: this is not a text {what}", file=path, where=f"line {line}")
    return text


def load_yaml(path: str | Path, *, what: str = "file") -> dict:
    """Read a YAML mapping; a missing file, bad YAML, a key written twice or a top level
    that is not a mapping is an ``InputError`` naming the file (and the line)."""
    path = Path(path)
    text = read_text(path, what=what)
    try:
        content = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else None
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        if problem.startswith("duplicate key") or problem.startswith("a mapping key"):
            raise InputError(problem, file=path, where=where) from None
        raise InputError(f"not valid YAML ({problem})", file=path, where=where) from None
    if content is None:
        raise InputError(f"the {what} is empty; expected a YAML mapping of keys", file=path)
    if not isinstance(content, dict):
        raise InputError(f"expected a YAML mapping of keys at the top level, got "
                         f"{_describe(content)}", file=path)
    bad = [k for k in content if not isinstance(k, str)]
    if bad:
        raise InputError(f"key {bad[0]!r} is not a name", file=path)
    return content


FILE_KINDS = {"joints": "a robot file", "tracking": "a tracking job",
              "dataset": "a dataset file"}


def file_kind(content: dict) -> str | None:
    """What a YAML mapping looks like: a robot file, a tracking job or a dataset file."""
    if content.get("kind") == "tracking":
        return FILE_KINDS["tracking"]
    if "kind" in content:
        return FILE_KINDS["dataset"]
    if "joints" in content and "convention" in content:
        return FILE_KINDS["joints"]
    return None


def check_keys(mapping: dict, allowed, *, file: str | Path | None, where: str = "",
               expected: str | None = None) -> None:
    """Refuse keys of ``mapping`` not in ``allowed`` (a misspelt key is never ignored).

    ``expected`` (e.g. "a robot file") adds a hint when the mapping looks like another
    kind of file given in the wrong place."""
    if expected is not None:
        looks = file_kind(mapping)
        if looks is not None and looks != expected:
            raise InputError(f"this is {looks}, not {expected}", file=file)
    unknown = sorted(str(k) for k in mapping if k not in allowed)
    if unknown:
        at = f"{where}.{unknown[0]}" if where else unknown[0]
        raise InputError(f"unknown key(s) {unknown}; allowed: {sorted(allowed)}", file=file,
                         where=at)


def mapping(value: Any, *, file: str | Path | None, where: str, hint: str = "") -> dict:
    """``value`` if it is a mapping, else an ``InputError`` saying what was found."""
    if not isinstance(value, dict):
        raise InputError(f"expected a mapping{' ' + hint if hint else ''}, got "
                         f"{_describe(value)}", file=file, where=where)
    return value


def file_name(value: Any, *, file: str | Path | None, where: str) -> str:
    """A file name given in a YAML file: non-empty text."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"expected a file name, got {_describe(value)}", file=file, where=where)
    return value.strip()


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
            raise InputError(f"unknown {name} unit {value[name]!r}; expected one of "
                             f"{sorted(known)}", file=file, where=f"{key}.{name}")
    return parse_units(value, file=file, key=key)


def number(value: Any, *, file: str | Path | None, where: str) -> float:
    """A finite float; booleans, strings, NaN and infinities are refused."""
    if isinstance(value, str) and _FLOAT_TEXT.fullmatch(value.strip()):
        # YAML 1.1 reads 1e-3 (no dot) as text; people write it, so accept it.
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {_describe(value)}", file=file, where=where)
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"expected a finite number, got {value}", file=file, where=where)
    return value


def vector(value: Any, length: int, *, file: str | Path | None, where: str) -> list[float]:
    """A list of ``length`` finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise InputError(f"expected a list of {length} numbers, got {_describe(value)}",
                         file=file, where=where)
    return [number(v, file=file, where=f"{where}[{i}]") for i, v in enumerate(value)]


# Largest magnitudes accepted in any file, SI. Anything beyond is a typo or a unit
# mix-up that would only overflow the solvers (a 10 km link, a joint turned 1,600 times).
MAX_LENGTH = 1e4  # m
MAX_ANGLE = 1e4  # rad


def check_magnitude(value_si: float, quantity: str, *, file: str | Path | None, where: str,
                    shown: float | None = None, unit: str = "") -> float:
    """``value_si`` if its size is plausible for a ``quantity`` ('length' [m] or
    'angle' [rad]); otherwise an ``InputError`` quoting the value as written."""
    limit = MAX_LENGTH if quantity == "length" else MAX_ANGLE
    if abs(value_si) > limit:
        text = f"{shown if shown is not None else value_si:g}{' ' + unit if unit else ''}"
        what = "10 km" if quantity == "length" else f"{limit:g} rad"
        raise InputError(f"{text} is implausibly large for a {quantity} (more than {what}); "
                         "check the value and the units", file=file, where=where)
    return value_si


def quantity(value: Any, scale: float, kind: str, *, file: str | Path | None, where: str,
             unit: str = "") -> float:
    """A number in file units as SI (times ``scale``), checked with ``check_magnitude``."""
    raw = number(value, file=file, where=where)
    return check_magnitude(raw * scale, kind, file=file, where=where, shown=raw, unit=unit)


def quantities(value: Any, length: int, scale: float, kind: str, *,
               file: str | Path | None, where: str, unit: str = "") -> list[float]:
    """A list of ``length`` numbers in file units as SI, each checked for magnitude."""
    raw = vector(value, length, file=file, where=where)
    return [check_magnitude(v * scale, kind, file=file, where=f"{where}[{i}]", shown=v, unit=unit)
            for i, v in enumerate(raw)]


def require(mapping: dict, key: str, *, file: str | Path | None, where: str = "") -> Any:
    """``mapping[key]`` or an ``InputError`` naming the missing key."""
    if key not in mapping:
        path = f"{where}.{key}" if where else key
        raise InputError("missing required key", file=file, where=path)
    return mapping[key]
