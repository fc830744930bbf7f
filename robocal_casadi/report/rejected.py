"""The report's account of the readings set aside as gross errors (``calibration.outliers``):
a table of every one, and where they lie in time (the order of the table) and in the
workspace (seen from above)."""

from __future__ import annotations

from functools import partial

import numpy as np
from matplotlib.figure import Figure

from ..common.units import Units
from ..model.kinematics import Kinematics
from ..results import CalibrationResult, RejectedReading
from .content import Paragraph, Plot, Section, Table
from .figures import log_scale, new_figure
from .numbers import display_units


def rejected_section(result: CalibrationResult) -> Section:
    """Every unit of data set aside, or a sentence saying none was."""
    units = display_units(result.units)
    s, unit = units.length_scale, units.length
    loss = result.solver.get("loss", "robust")
    if loss != "robust":
        return Section("rejected", "Gross errors", (Paragraph(
            f"The calibration kept every reading (loss {loss!r}): no search for gross "
            "errors was made."),))
    if not result.rejected:
        return Section("rejected", "Gross errors", (Paragraph(
            "No reading was set aside: every unit of data is consistent with the noise of "
            "the others."),))
    rows = tuple((e.table, str(e.line), e.role, e.reading, e.suspect or "",
                  f"{e.residual / s:.4g}", f"{e.threshold / s:.4g}") for e in result.rejected)
    text = (f"{len(result.rejected)} unit(s) of data were set aside as gross errors and "
            "everything else (identifiability, fits, diagnosis, noise level, validation "
            "statistics) was computed without them. A unit is set aside when its error, "
            "under the model fitted without it, exceeds what the noise of its kind reaches "
            "with a probability of 1 in 10,000. A placement is set aside whole; the touches "
            "named are those whose error alone explains what failed.")
    table = Table("rejected", f"Readings set aside [{unit}]",
                  ("table", "line", "role", "reading", "looks wrong", "error", "threshold"),
                  rows, numeric=(False, True, False, False, False, True, True))
    plot = Plot("rejected-where", "Readings set aside: their error against the threshold in "
                "the order they were taken (left), and where they lie, seen from above "
                "(right; grey: flange positions of the readings kept)",
                partial(rejected_figure, result, units))
    return Section("rejected", "Gross errors", (Paragraph(text), table, plot))


def rejected_figure(result: CalibrationResult, units: Units) -> Figure:
    """Error / threshold per set-aside unit against its row, and a top view."""
    figure = new_figure(3.2)
    time, space = figure.subplots(1, 2)
    entries: list[RejectedReading] = list(result.rejected)
    ratio = np.array([e.residual / e.threshold if e.threshold > 0 else np.nan for e in entries])
    rows = np.array([min(e.rows) if e.rows else -1 for e in entries])
    time.scatter(rows, ratio, marker="x", color="tab:red")
    time.axhline(1.0, color="grey", linestyle="--", linewidth=0.8)
    log_scale(time, "y")
    time.set_xlabel("row of the table (order taken)")
    time.set_ylabel("error / threshold")
    s = units.length_scale
    kinematics = Kinematics(result.robot_calibrated)
    for r in result.residuals:
        if r.joints is not None and len(r.joints):
            flange = kinematics.flange_poses(np.asarray(r.joints, float))[:, :3, 3]
            space.scatter(flange[:, 0] / s, flange[:, 1] / s, s=4, color="lightgrey")
    placed = np.array([e.position for e in entries if e.position is not None])
    if placed.size:
        space.scatter(placed[:, 0] / s, placed[:, 1] / s, marker="x", color="tab:red")
    space.set_xlabel(f"x [{units.length}]")
    space.set_ylabel(f"y [{units.length}]")
    space.set_aspect("equal", adjustable="datalim")
    return figure
