"""CSV tables: checked reading with line numbers, full-precision writing."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class Table:
    """A CSV table as read: header and string cells, with the file for messages."""

    path: Path
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def __len__(self) -> int:
        return len(self.rows)

    def has(self, name: str) -> bool:
        return name in self.columns

    def line(self, row: int) -> int:
        """File line number (1-based, header is line 1) of data row ``row`` (0-based)."""
        return row + 2

    def text(self, name: str) -> list[str]:
        """Column ``name`` as stripped strings."""
        k = self.columns.index(name)
        return [r[k] for r in self.rows]

    def numbers(self, name: str, *, allow_empty: bool = False) -> np.ndarray:
        """Column ``name`` as finite floats; a bad cell names its line and column."""
        if name not in self.columns:
            raise InputError(f"missing column {name!r}; the table has {list(self.columns)}",
                             file=self.path)
        k = self.columns.index(name)
        out = np.empty(len(self.rows))
        for i, row in enumerate(self.rows):
            cell = row[k]
            if cell == "" and allow_empty:
                out[i] = np.nan
                continue
            try:
                value = float(cell)
            except ValueError:
                raise InputError(f"column {name!r}: expected a number, got {cell!r}",
                                 file=self.path, where=f"line {self.line(i)}") from None
            if not math.isfinite(value):
                raise InputError(f"column {name!r}: expected a finite number, got {cell!r}",
                                 file=self.path, where=f"line {self.line(i)}")
            out[i] = value
        return out


def read_table(path: str | Path, *, required: Sequence[str] = ()) -> Table:
    """Read a CSV with a header row; ragged rows, missing columns and empty tables are errors."""
    path = Path(path)
    if not path.is_file():
        raise InputError("data table not found", file=path)
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = next(reader)
        except StopIteration:
            raise InputError("empty table: no header row", file=path) from None
        columns = tuple(c.strip() for c in header)
        if len(set(columns)) != len(columns):
            raise InputError(f"duplicate column names in header {list(columns)}", file=path,
                             where="line 1")
        rows = []
        for number, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(columns):
                raise InputError(f"expected {len(columns)} cells, got {len(row)}", file=path,
                                 where=f"line {number}")
            rows.append(tuple(c.strip() for c in row))
    missing = [c for c in required if c not in columns]
    if missing:
        raise InputError(f"missing column(s) {missing}; the table has {list(columns)}", file=path)
    if not rows:
        raise InputError("empty table: a header but no data rows", file=path)
    return Table(path, columns, tuple(rows))


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
