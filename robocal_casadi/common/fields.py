"""Checked reading of YAML files and their fields.

Every reader in the package goes through these helpers so that a bad value is reported
the same way everywhere: the file, the key path, what was expected and what was found.
"""

from __future__ import annotations

import errno
import math
import re
import reprlib
import stat
from pathlib import Path
from typing import IO, Any, Literal, overload

import yaml

from ..errors import InputError
from .output import resolved_path

_FLOAT_TEXT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


# Bounds on what a YAML file may make the reader do. Robot, dataset and job files are a
# few kilobytes; these only stop files built to exhaust memory or the stack.
MAX_YAML_BYTES = 4 * 2**20  # a YAML file larger than this is refused before reading
MAX_TABLE_BYTES = 256 * 2**20  # likewise a data table
MAX_DEPTH = 100  # nesting of lists and mappings
MAX_EXPANDED = 100_000  # values in the document once every alias (*name) is expanded
_MERGE_TAG = "tag:yaml.org,2002:merge"
MAX_NAME_BYTES = 255  # one component of a path (most file systems)
MAX_PATH_CHARACTERS = 4096  # a whole path (Linux PATH_MAX)


class _StrictLoader(yaml.SafeLoader):
    """``SafeLoader`` that refuses a key written twice in one mapping (PyYAML keeps the
    last) and nesting deeper than ``MAX_DEPTH``. Merge keys (``<<: *defaults``) work as
    YAML defines them: the mapping's own keys win over merged ones."""

    _depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested more than {MAX_DEPTH} levels deep",
                    self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == _MERGE_TAG:
                continue
            try:
                key = self.construct_object(key_node, deep=True)
                hash(key)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None, None, "a mapping key must be a plain value", key_node.start_mark
                ) from None
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {cut(key)} (first on line {seen[key] + 1})",
                    key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


class _ExpansionError(Exception):
    """The document's aliases expand too far, or one refers to a value holding it."""


def _expanded_size(node, sizes: dict, open_nodes: set) -> int:
    """Values in ``node`` with every alias expanded (each shared node counted once per
    use); memoised, so the cost is the size of the file, not of the expansion."""
    key = id(node)
    if key in sizes:
        return sizes[key]
    if key in open_nodes:
        raise _ExpansionError("an alias (*name) refers to a value that contains it")
    open_nodes.add(key)
    total = 1
    if isinstance(node, yaml.SequenceNode):
        total += sum(_expanded_size(item, sizes, open_nodes) for item in node.value)
    elif isinstance(node, yaml.MappingNode):
        total += sum(_expanded_size(k, sizes, open_nodes) + _expanded_size(v, sizes, open_nodes)
                     for k, v in node.value)
    open_nodes.discard(key)
    if total > MAX_EXPANDED:
        raise _ExpansionError(f"aliases (*name) expand the file to more than {MAX_EXPANDED:,} "
                              "values")
    sizes[key] = total
    return total


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxtuple, _SHORT.maxdict = 2, 4, 4, 3
_SHORT.maxstring, _SHORT.maxlong, _SHORT.maxother = 40, 30, 30


def cut(value: Any, limit: int = 60) -> str:
    """A short ``repr`` of ``value`` for messages, whatever its size: long text, huge
    numbers and deep or shared structures are cut, never expanded in full."""
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _describe(value: Any) -> str:
    """A short name of what a YAML value is, for messages."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, (int, float)):
        return f"a number ({cut(value)})"
    if isinstance(value, str):
        return f"text ({cut(value)})"
    if isinstance(value, list):
        text = cut(value)
        return f"a list ({text})" if "..." not in text else f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


def _checked_file(path: Path, what: str, limit: int) -> None:
    """Refuse ``path`` unless it is an existing regular file of at most ``limit`` bytes."""
    try:
        mode = path.stat()
    except FileNotFoundError:
        raise InputError(f"{what} not found", file=path) from None
    except OSError as error:
        reason = "a loop of symbolic links" if error.errno == errno.ELOOP else error.strerror
        raise InputError(f"cannot read the {what} ({reason})", file=path) from None
    except ValueError:  # a NUL in the name
        raise InputError(f"{what} not found", file=path) from None
    if stat.S_ISDIR(mode.st_mode):
        raise InputError(f"expected a {what}, found a folder", file=path)
    if not stat.S_ISREG(mode.st_mode):
        raise InputError(f"expected a {what}, found a device, pipe or socket", file=path)
    if mode.st_size > limit:
        raise InputError(f"the {what} has {mode.st_size:,} bytes, more than the "
                         f"{limit // 2**20} MiB a {what} may have", file=path)


def open_checked(path: Path, *, what: str = "file", limit: int = MAX_YAML_BYTES) -> IO[str]:
    """``path`` opened as UTF-8 text for reading as a stream (a byte-order mark dropped,
    line endings left to the reader: ``newline=""``), after the checks of ``read_text``
    that need no reading; decoding errors surface while reading."""
    _checked_file(path, what, limit)
    try:
        return path.open("r", encoding="utf-8-sig", newline="")
    except OSError as error:
        raise InputError(f"cannot read the {what} ({error.strerror})", file=path) from None


def read_text(path: Path, *, what: str = "file", limit: int = MAX_YAML_BYTES) -> str:
    """The UTF-8 text of ``path`` (a leading byte-order mark dropped); an ``InputError``
    for a missing file, a folder, a device or pipe, a file larger than ``limit`` bytes
    (checked before reading), an unreadable file or bytes that are not UTF-8."""
    _checked_file(path, what, limit)
    try:
        with path.open("rb") as handle:
            data = handle.read(limit + 1)
    except OSError as error:
        raise InputError(f"cannot read the {what} ({error.strerror})", file=path) from None
    if len(data) > limit:  # grew while we looked
        raise InputError(f"the {what} is larger than the {limit // 2**20} MiB a {what} may "
                         "have", file=path)
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
    """Read a YAML mapping; a missing file, bad YAML, a key written twice, nesting or
    aliases beyond the bounds above, or a top level that is not a mapping is an
    ``InputError`` naming the file (and the line)."""
    path = Path(path)
    text = read_text(path, what=what)
    try:
        loader = _StrictLoader(text)
    except yaml.reader.ReaderError as error:  # a control character, found before parsing
        line = text[:error.position].count("\n") + 1
        raise InputError(f"not valid YAML (the control character {error.character:#06x} may "
                         f"not appear in a YAML file)", file=path, where=f"line {line}") from None
    try:
        node = loader.get_single_node()
        if node is not None:
            _expanded_size(node, {}, set())
        content = loader.construct_document(node) if node is not None else None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else None
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        problem = problem if len(problem) <= 200 else problem[:197] + "..."
        if problem.startswith(("duplicate key", "a mapping key", "nested more")):
            raise InputError(problem, file=path, where=where) from None
        raise InputError(f"not valid YAML ({problem})", file=path, where=where) from None
    except _ExpansionError as error:
        raise InputError(str(error), file=path) from None
    except (ValueError, OverflowError) as error:  # e.g. an integer of more than 4,300 digits
        raise InputError(f"a value that cannot be read ({cut(str(error), 120)})",
                         file=path) from None
    finally:
        loader.dispose()
    if content is None:
        raise InputError(f"the {what} is empty; expected a YAML mapping of keys", file=path)
    if not isinstance(content, dict):
        raise InputError(f"expected a YAML mapping of keys at the top level, got "
                         f"{_describe(content)}", file=path)
    bad = [k for k in content if not isinstance(k, str)]
    if bad:
        raise InputError(f"key {cut(bad[0])} is not a name", file=path)
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
    """A file name given in a YAML file: non-empty text, short enough for a file system
    and without NUL (else an ``InputError`` naming ``file`` and ``where``, the name cut)."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"expected a file name, got {_describe(value)}", file=file, where=where)
    name = value.strip()
    parts = re.split(r"[/\\]", name)
    longest = max(len(part.encode("utf-8", "surrogatepass")) for part in parts)
    if len(name) > MAX_PATH_CHARACTERS or longest > MAX_NAME_BYTES:
        raise InputError(f"a file name of {len(name):,} characters ({cut(name, 40)}): too long for "
                         f"a file (at most {MAX_NAME_BYTES} bytes per folder level, "
                         f"{MAX_PATH_CHARACTERS} in all)", file=file, where=where)
    if "\x00" in name:
        raise InputError(f"a NUL character in the file name {cut(name, 40)}", file=file,
                         where=where)
    return name


def resolved(path: Path) -> Path:
    """``path`` with links followed; a loop of links leaves the name as written."""
    return resolved_path(path)


@overload
def referenced_file(content: dict, key: str, *, file: Path, allow_outside: bool = False,
                    required: Literal[True] = True) -> Path: ...
@overload
def referenced_file(content: dict, key: str, *, file: Path, allow_outside: bool = False,
                    required: bool) -> Path | None: ...
def referenced_file(content: dict, key: str, *, file: Path, allow_outside: bool = False,
                    required: bool = True) -> Path | None:
    """The file a YAML file names under ``key`` (``data: points.csv``), relative to the
    naming file's folder. It must lie in that folder or below it (after following
    links): an absolute path or ``../`` could read any file on the machine, so it needs
    ``allow_outside`` (``--allow-outside-data``). None when optional and absent."""
    if content.get(key) is None and not required:
        return None
    name = file_name(require(content, key, file=file), file=file, where=key)
    target = file.parent / name
    if not allow_outside:
        folder = resolved_path(file.parent)
        resolved = resolved_path(target)
        if resolved != folder and folder not in resolved.parents:
            raise InputError(f"{cut(name)} lies outside the folder of {file.name}; a {key} "
                             "table must be in that folder or below it (give "
                             "--allow-outside-data to read it anyway)", file=file, where=key)
    return target


def number(value: Any, *, file: str | Path | None, where: str) -> float:
    """A finite float; booleans, strings, NaN and infinities are refused."""
    if isinstance(value, str) and _FLOAT_TEXT.fullmatch(value.strip()):
        # YAML 1.1 reads 1e-3 (no dot) as text; people write it, so accept it.
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {_describe(value)}", file=file, where=where)
    try:
        value = float(value)
    except OverflowError:  # an integer of hundreds of digits
        raise InputError(f"{cut(value)} is too large for a number", file=file,
                         where=where) from None
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
