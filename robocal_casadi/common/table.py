"""CSV tables: checked reading with line numbers, full-precision writing.

What the reader accepts, beyond plain comma-separated UTF-8 with a header line: a
byte-order mark, Windows line endings, blank lines, quoted cells, spaces around cells,
and trailing commas that add only empty cells (a column with no name and no values).
Everything else that is odd is refused with the file, the line and what is wrong:
other separators, a missing or repeated header, a row of the wrong length, a number
written with a comma, an underscore, hexadecimal digits, NaN or infinity.
"""

from __future__ import annotations

import array
import csv
import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .fields import MAX_TABLE_BYTES, cut, open_checked

# A decimal number as people write it in a table; float() alone would also take
# "1_000", "infinity" or " nan ", which a table must not contain silently.
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_NON_FINITE = re.compile(r"[-+]?(nan|inf|infinity)", re.IGNORECASE)


@dataclass(frozen=True)
class Table:
    """A CSV table as read: header and cells, with the file for messages.

    Cells are held column by column as UTF-8 bytes (a numpy ``S`` array per column,
    about the size of the file) and turned into numbers or text only when asked, so a
    large table costs a small multiple of its file. ``lines`` holds the file line
    (1-based) of each data row; without it row ``i`` is taken to be on line ``i + 2``.
    """

    path: Path
    columns: tuple[str, ...]
    cells: tuple[np.ndarray, ...]  # per column, (rows,) bytes
    lines: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.cells[0]) if self.cells else 0

    @property
    def rows(self) -> tuple[tuple[str, ...], ...]:
        """Every row as text cells (for small tables: this builds one string per cell)."""
        texts = [self.text(c) for c in self.columns]
        return tuple(zip(*texts)) if texts else ()

    def has(self, name: str) -> bool:
        return name in self.columns

    def line(self, row: int) -> int:
        """File line number (1-based, header is line 1) of data row ``row`` (0-based)."""
        return int(self.lines[row]) if len(self.lines) else row + 2

    def missing(self, names: Sequence[str]) -> InputError | None:
        """An ``InputError`` for the ``names`` the table lacks (None when it has all),
        pointing at a column that differs only in case."""
        absent = [n for n in names if n not in self.columns]
        if not absent:
            return None
        lower = {c.lower(): c for c in self.columns}
        near = [f"{lower[n.lower()]!r} for {n!r}" for n in absent if n.lower() in lower]
        hint = f" (found {', '.join(near)}: column names are case-sensitive)" if near else ""
        label = "column" if len(absent) == 1 else "columns"
        shown = repr(absent[0]) if len(absent) == 1 else str(absent)
        return InputError(f"missing {label} {shown}; the table has {listed(self.columns)}{hint}",
                          file=self.path, where="line 1")

    def require(self, *names: str) -> None:
        """Raise the ``missing`` error when a column is absent."""
        error = self.missing(names)
        if error is not None:
            raise error

    def text(self, name: str) -> list[str]:
        """Column ``name`` as stripped strings."""
        self.require(name)
        return [c.decode("utf-8") for c in self.cells[self.columns.index(name)].tolist()]

    def numbers(self, name: str, *, allow_empty: bool = False) -> np.ndarray:
        """Column ``name`` as finite floats; a bad cell names its line and column.

        Cells made only of digits, signs, points and exponents are converted at once;
        any other column is read cell by cell for the message."""
        self.require(name)
        column = self.cells[self.columns.index(name)]
        empty = column == b""
        fast = _fast_numbers(column, empty if allow_empty else None)
        if fast is not None:
            return fast
        out = np.empty(len(column))
        for i, raw in enumerate(column.tolist()):
            cell = raw.decode("utf-8")
            if cell == "" and allow_empty:
                out[i] = np.nan
                continue
            out[i] = parse_number(cell, name, file=self.path, where=f"line {self.line(i)}")
        return out


# Bytes a plain decimal number may hold (and the padding of a numpy bytes array).
_NUMERIC_BYTES = np.zeros(256, dtype=bool)
_NUMERIC_BYTES[np.frombuffer(b"0123456789+-.eE\x00", dtype=np.uint8)] = True


def _fast_numbers(column: np.ndarray, empty: np.ndarray | None) -> np.ndarray | None:
    """``column`` (bytes) as finite floats when every cell is plainly a number (``empty``:
    cells to read as NaN); None when any cell needs a closer look."""
    if column.dtype.itemsize == 0 or not len(column):
        return None if len(column) else np.zeros(0)
    codes = column.view(np.uint8).reshape(len(column), column.dtype.itemsize)
    if not _NUMERIC_BYTES[codes].all():
        return None
    try:
        if empty is None or not empty.any():
            out = column.astype(np.float64)
        else:
            out = np.full(len(column), np.nan)
            out[~empty] = column[~empty].astype(np.float64)
    except ValueError:
        return None
    finite = np.isfinite(out)
    if not (finite.all() or (empty is not None and np.all(finite | empty))):
        return None
    return out


def listed(names: Sequence[str], limit: int = 200) -> str:
    """Column names for a message, cut to ``limit`` characters (a header may be anything)."""
    text = str(list(names))
    return text if len(text) <= limit else text[:limit - 3] + "..."


def parse_number(cell: str, column: str, *, file: Path | None, where: str) -> float:
    """A table cell as a finite float, or an ``InputError`` saying what is wrong with it."""
    if _NUMBER.fullmatch(cell):
        value = float(cell)
        if math.isfinite(value):
            return value
        raise InputError(f"column {column!r}: {cut(cell)} is too large for a number", file=file,
                         where=where)
    if _NON_FINITE.fullmatch(cell):
        raise InputError(f"column {column!r}: expected a finite number, got {cut(cell)}",
                         file=file, where=where)
    hint = ""
    if cell == "":
        hint = " (an empty cell)"
    elif re.fullmatch(r"[-+]?\d+,\d+", cell):
        hint = " (write the decimal separator as a point)"
    elif "\u2212" in cell:
        hint = " (a typographic minus sign; use '-')"
    raise InputError(f"column {column!r}: expected a number, got {cut(cell)}{hint}", file=file,
                     where=where)


CHUNK = 4096  # rows gathered as text before they are packed into byte arrays


def _records(path: Path) -> Iterator[tuple[int, list[str]]]:
    """The CSV records of ``path`` with the file line each starts on, read as a stream
    (UTF-8, a byte-order mark dropped); blank records are skipped."""
    handle = open_checked(path, what="data table", limit=MAX_TABLE_BYTES)
    with handle:
        reader = csv.reader(handle, skipinitialspace=True)
        line = 1
        try:
            for record in reader:
                if any("\x00" in c for c in record):
                    raise InputError("a NUL byte: this is not a text data table", file=path,
                                     where=f"line {line}")
                if record and any(c.strip() for c in record):
                    yield line, record
                line = reader.line_num + 1
        except csv.Error as error:
            raise InputError(f"not a readable CSV table ({error})", file=path,
                             where=f"line {reader.line_num}") from None
        except UnicodeDecodeError as error:
            raise InputError(f"not UTF-8 text (byte 0x{error.object[error.start]:02x}); save "
                             "the data table as UTF-8", file=path,
                             where=f"line {_first_bad_line(path)}") from None


def _first_bad_line(path: Path) -> int:
    """The line (1-based) holding the first bytes of ``path`` that are not UTF-8 (a
    character never spans a line break in UTF-8, so lines decode on their own)."""
    with path.open("rb") as handle:
        for number, raw in enumerate(handle, 1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError:
                return number
    return 1


def _header(path: Path, records: Iterator[tuple[int, list[str]]]) -> tuple[int, list[str]]:
    """The header line number and its column names, checked."""
    first = next(records, None)
    if first is None:
        raise InputError("empty table: no header row", file=path)
    header_line, header = first
    columns = [c.strip() for c in header]
    where = f"line {header_line}"
    if len(columns) == 1 and any(sep in columns[0] for sep in (";", "\t", "|")):
        sep = next(s for s in (";", "\t", "|") if s in columns[0])
        raise InputError(f"the header is one cell {cut(columns[0])} separated by {sep!r}; the "
                         "table must be comma-separated", file=path, where=where)
    if columns and all(_NUMBER.fullmatch(c) or _NON_FINITE.fullmatch(c) for c in columns if c):
        raise InputError("the first line holds numbers, not column names: the table needs a "
                         "header line", file=path, where=where)
    named = [c for c in columns if c]  # unnamed columns (trailing commas) are checked later
    if len(set(named)) != len(named):
        repeated = sorted({c for c in named if named.count(c) > 1})
        raise InputError(f"column(s) {repeated} appear more than once in the header "
                         f"{listed(columns)}", file=path, where=where)
    if not named:
        raise InputError("the header has no column names", file=path, where=where)
    return header_line, columns


def read_table(path: str | Path, *, required: Sequence[str] = ()) -> Table:
    """Read a CSV with a header row; ragged rows, missing columns and empty tables are errors.

    Streamed: rows are packed into one bytes array per column every ``CHUNK`` rows, so
    memory stays near the file's size."""
    path = Path(path)
    records = _records(path)
    header_line, columns = _header(path, records)
    width = len(columns)
    unnamed = [k for k, c in enumerate(columns) if c == ""]
    keep = [k for k in range(width) if k not in unnamed]
    chunks: list[list[np.ndarray]] = [[] for _ in keep]
    pending: list[list[bytes]] = [[] for _ in keep]
    lines = array.array("q")
    for number, record in records:
        cells = [c.strip() for c in record]
        if len(cells) > width and not any(cells[width:]):
            cells = cells[:width]  # trailing commas: empty cells only
        if len(cells) != width:
            raise InputError(f"expected {width} cells as in the header, got {len(cells)}",
                             file=path, where=f"line {number}")
        for k in unnamed:  # a column with no name must be empty throughout
            if cells[k]:
                raise InputError(f"column {k + 1} has no name in the header but holds "
                                 f"{cut(cells[k])}", file=path, where=f"line {number}")
        for slot, k in enumerate(keep):
            pending[slot].append(cells[k].encode("utf-8"))
        lines.append(number)
        if len(pending[0]) >= CHUNK:
            _pack(pending, chunks)
    _pack(pending, chunks)
    packed: list[np.ndarray] = []
    for slot in range(len(keep)):  # one column at a time: its chunks go as it is joined
        packed.append(np.concatenate(chunks[slot]) if chunks[slot] else np.zeros(0, "S1"))
        chunks[slot] = []
    table = Table(path, tuple(columns[k] for k in keep), tuple(packed),
                  np.frombuffer(lines, dtype=np.int64).copy())
    table.require(*required)
    if not lines:
        raise InputError("empty table: a header but no data rows", file=path)
    return table


def _pack(pending: list[list[bytes]], chunks: list[list[np.ndarray]]) -> None:
    """Move the gathered cells of each column into a bytes array (at least 1 byte wide)."""
    if not pending or not pending[0]:
        return
    for slot, cells in enumerate(pending):
        widest = max(1, max(len(c) for c in cells))
        chunks[slot].append(np.array(cells, dtype=f"S{widest}"))
        cells.clear()


def format_number(value) -> str:
    """Full precision text that reads back to the same float; NaN as an empty cell."""
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    value = float(value)
    if math.isnan(value):
        return ""
    return repr(value)


def write_table(path: str | Path, columns: Sequence[str], rows: Sequence[Sequence]) -> None:
    """Write a CSV with ``columns`` and full-precision numbers."""
    with Path(path).open("w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(columns)
        for row in rows:
            writer.writerow([format_number(v) for v in row])
