"""CSV tables: checked reading with line numbers, full-precision writing.

What the reader accepts, beyond plain comma-separated UTF-8 with a header line: a
byte-order mark, Windows line endings, blank lines, quoted cells, spaces around cells,
and trailing commas that add only empty cells (a column with no name and no values).
Everything else that is odd is refused with the file, the line and what is wrong:
other separators, a missing or repeated header, a row of the wrong length, a number
written with a comma, an underscore, hexadecimal digits, NaN or infinity.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .fields import MAX_TABLE_BYTES, cut, read_text

# A decimal number as people write it in a table; float() alone would also take
# "1_000", "infinity" or " nan ", which a table must not contain silently.
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_NON_FINITE = re.compile(r"[-+]?(nan|inf|infinity)", re.IGNORECASE)


@dataclass(frozen=True)
class Table:
    """A CSV table as read: header and string cells, with the file for messages.

    ``lines`` holds the file line (1-based) of each data row; without it row ``i`` is
    taken to be on line ``i + 2``.
    """

    path: Path
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...] = ()

    def __len__(self) -> int:
        return len(self.rows)

    def has(self, name: str) -> bool:
        return name in self.columns

    def line(self, row: int) -> int:
        """File line number (1-based, header is line 1) of data row ``row`` (0-based)."""
        return self.lines[row] if self.lines else row + 2

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
        k = self.columns.index(name)
        return [r[k] for r in self.rows]

    def numbers(self, name: str, *, allow_empty: bool = False) -> np.ndarray:
        """Column ``name`` as finite floats; a bad cell names its line and column."""
        self.require(name)
        k = self.columns.index(name)
        out = np.empty(len(self.rows))
        for i, row in enumerate(self.rows):
            cell = row[k]
            if cell == "" and allow_empty:
                out[i] = np.nan
                continue
            out[i] = parse_number(cell, name, file=self.path, where=f"line {self.line(i)}")
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


def read_table(path: str | Path, *, required: Sequence[str] = ()) -> Table:
    """Read a CSV with a header row; ragged rows, missing columns and empty tables are errors."""
    path = Path(path)
    text = read_text(path, what="data table", limit=MAX_TABLE_BYTES)
    reader = csv.reader(io.StringIO(text, newline=""), skipinitialspace=True)
    records: list[tuple[int, list[str]]] = []
    try:
        line = reader.line_num + 1
        for record in reader:
            records.append((line, record))
            line = reader.line_num + 1
    except csv.Error as error:
        raise InputError(f"not a readable CSV table ({error})", file=path,
                         where=f"line {reader.line_num}") from None
    records = [(n, r) for n, r in records if r and any(c.strip() for c in r)]
    if not records:
        raise InputError("empty table: no header row", file=path)
    header_line, header = records[0]
    columns = [c.strip() for c in header]
    if len(columns) == 1 and any(sep in columns[0] for sep in (";", "\t", "|")):
        sep = next(s for s in (";", "\t", "|") if s in columns[0])
        raise InputError(f"the header is one cell {cut(columns[0])} separated by {sep!r}; the "
                         "table must be comma-separated", file=path, where=f"line {header_line}")
    if columns and all(_NUMBER.fullmatch(c) or _NON_FINITE.fullmatch(c) for c in columns if c):
        raise InputError("the first line holds numbers, not column names: the table needs a "
                         "header line", file=path, where=f"line {header_line}")
    named = [c for c in columns if c]  # unnamed columns (trailing commas) are checked below
    if len(set(named)) != len(named):
        repeated = sorted({c for c in named if named.count(c) > 1})
        raise InputError(f"column(s) {repeated} appear more than once in the header "
                         f"{listed(columns)}", file=path, where=f"line {header_line}")
    rows, lines = [], []
    for number, record in records[1:]:
        cells = [c.strip() for c in record]
        if len(cells) > len(columns) and not any(cells[len(columns):]):
            cells = cells[:len(columns)]  # trailing commas: empty cells only
        if len(cells) != len(columns):
            raise InputError(f"expected {len(columns)} cells as in the header, got {len(cells)}",
                             file=path, where=f"line {number}")
        rows.append(cells)
        lines.append(number)
    # A column with no name (a trailing comma on the header) must be empty throughout.
    unnamed = [k for k, c in enumerate(columns) if c == ""]
    for k in unnamed:
        filled = [i for i, r in enumerate(rows) if r[k]]
        if filled:
            raise InputError(f"column {k + 1} has no name in the header but holds "
                             f"{cut(rows[filled[0]][k])}", file=path,
                             where=f"line {lines[filled[0]]}")
    keep = [k for k in range(len(columns)) if k not in unnamed]
    table = Table(path, tuple(columns[k] for k in keep),
                  tuple(tuple(r[k] for k in keep) for r in rows), tuple(lines))
    if not table.columns:
        raise InputError("the header has no column names", file=path,
                         where=f"line {header_line}")
    table.require(*required)
    if not rows:
        raise InputError("empty table: a header but no data rows", file=path)
    return table


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
