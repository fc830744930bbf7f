"""``errors.csv``: every error of a calibration, one line each, before and after.

One row per error the calibration evaluates (docs/formats.md#error-table): the dataset
(labelled as in ``result.json``), whether it was fitted or held out, the line of the
dataset's CSV table the error belongs to, what the error is, and its size under the
nominal robot, the geometric calibration and the final model (with effects) in mm,
whatever the robot file's unit. Errors that belong to a whole placement rather than one
reading (a bar's length, a perpendicularity) have no line; their placement id says
where they come from.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..common.output import atomic_file
from ..common.table import format_number
from ..results import CalibrationResult, DatasetResiduals, ErrorTerm

FILE_NAME = "errors.csv"
MM = 1e-3  # [m] per mm
COLUMNS = ("dataset", "role", "line", "term", "placement", "points",
           "error_nominal_mm", "error_geometric_mm", "error_final_mm")


def write_errors_csv(result: CalibrationResult, folder: Path) -> Path:
    """Write ``errors.csv`` into ``folder`` (whole or not at all); returns its path.

    Errors are magnitudes [mm]: the length of a 3-D position error, the absolute
    distance from a surface, the absolute deviation of a known length.
    """
    if not isinstance(result, CalibrationResult):
        raise TypeError(f"result: expected a CalibrationResult, got {type(result).__name__}")
    path = Path(folder) / FILE_NAME
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for role, residuals in (("fit", result.residuals),
                            ("validation", result.validation_residuals)):
        for r in residuals:
            writer.writerows([_cell(v) for v in row] for row in error_rows(r, role))
    writer.writerows([_cell(v) for v in row] for row in set_aside_rows(result))
    with atomic_file(path) as staging:
        staging.write_text(text.getvalue(), encoding="utf-8")
        staging.chmod(0o644)
    return path


def error_rows(residuals: DatasetResiduals, role: str) -> Iterator[tuple]:
    """The table's rows for one dataset, in the order of its errors (see ``COLUMNS``)."""
    rows = np.asarray(residuals.rows, dtype=int)
    terms = residuals.terms or (ErrorTerm("error"),) * len(rows)
    if len(terms) != len(rows):
        raise ValueError(f"{residuals.label}: {len(terms)} error terms for {len(rows)} errors")
    stages = [np.abs(np.asarray(getattr(residuals, f"errors_{m}"), float)) / MM
              for m in ("nominal", "geometric", "final")]
    for i, (row, term) in enumerate(zip(rows, terms)):
        line = csv_line(residuals, int(row)) if row >= 0 else None
        yield (residuals.label, role, line, term.kind,
               term.pose if term.pose >= 0 else None, "-".join(term.points) or None,
               *(float(s[i]) for s in stages))


def set_aside_rows(result: CalibrationResult) -> Iterator[tuple]:
    """One row per table line of each reading the calibration set aside as a gross error
    (``result.rejected``): role ``fit, set aside`` or ``validation, set aside``, the error
    under the model fitted without it in ``error_final_mm`` (the other models' columns
    empty: it was never fitted), nothing dropped silently."""
    for reading in getattr(result, "rejected", ()) or ():
        for line in reading.lines or (reading.line,):
            yield (reading.dataset, f"{reading.role}, set aside", line, reading.reading,
                   None, reading.suspect or None, None, None, reading.residual / MM)


def csv_line(residuals: DatasetResiduals, row: int) -> int:
    """The line (1-based, the header on line 1) of data row ``row`` in the dataset's CSV
    table: as read when the result carries it for every row, else ``row + 2`` (a table
    without blank lines)."""
    lines = residuals.lines
    if lines is not None and row < len(lines) and \
            (residuals.joints is None or len(residuals.joints) == len(lines)):
        return int(np.asarray(lines)[row])
    return row + 2


def _cell(value) -> str:
    """A CSV cell: empty for None, numbers at full precision (they read back exactly)."""
    return "" if value is None else format_number(value)
