"""Plots of the error before and after, as each kind of data shows it best.

- position errors (tracker points, artifact touches): the x, y, z parts, a histogram of
  the magnitude, the magnitude against each joint and across the workspace;
- bar and artifact lengths: ``|AC| - L``, ``|BD| - L`` and the perpendicularity
  ``AC.BD / L`` of every placement;
- sphere and laser: the signed distance from the sphere surface over the scan.

"Before" is the nominal robot (only the instrument placement fitted), "after" the final
model (the geometric calibration with the effects added). Inputs are SI [m]; plots are
in ``units`` (the report's display units). Every function returns a fresh figure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..common.units import Units
from ..model.robot import Robot
from ..results import DatasetResiduals
from .figures import COLOURS, WIDTH, _binned_rms, _thin, log_scale, new_figure, report_style
from .numbers import (
    dataset_name,
    errors_of,
    format_at_resolution,
    joint_reading_unit,
    resolution_of,
)

BEFORE, AFTER = "nominal", "final"
TITLES = {BEFORE: "before: nominal robot", AFTER: "after: calibrated"}
AXES = ("x", "y", "z")
FRAME_WORDS = {"instrument": "instrument frame", "base": "robot base frame"}
TERM_TITLES = {"distance": "length error", "perpendicular": "perpendicularity error"}


def _of_kind(residuals: Sequence[DatasetResiduals], kind: str) -> list[tuple[DatasetResiduals,
                                                                           np.ndarray]]:
    """``(residuals, positions of the errors of that kind)`` for datasets that have them."""
    out = []
    for r in residuals:
        if r.terms and r.components:
            which = np.flatnonzero([t.kind == kind for t in r.terms])
            if which.size:
                out.append((r, which))
    return out


def has_kind(residuals: Sequence[DatasetResiduals], kind: str) -> bool:
    """True when some dataset records errors of ``kind`` (see ``results.ErrorTerm``)."""
    return bool(_of_kind(residuals, kind))


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values.size else float("nan")


def mean_and_rms(values: np.ndarray) -> str:
    """``mean ...\nRMS ...``: the RMS to 3 significant digits and the mean to the same
    decimal place, so a mean below what the RMS resolves prints as 0."""
    spread = _rms(values)
    mean = float(np.mean(values)) if values.size else float("nan")
    return (f"mean {format_at_resolution(mean, resolution_of(spread), sign=True)}\n"
            f"RMS {spread:.3g}")


# ----------------------------------------------------------------------------- positions


def position_axes(residuals: Sequence[DatasetResiduals], units: Units) -> Figure:
    """Histograms of the x, y and z parts of the position error, before (top) and after
    (bottom), each with its mean and RMS."""
    chosen = _of_kind(residuals, "position")
    frame = FRAME_WORDS.get(chosen[0][0].frame, "measurement frame")
    parts = {m: np.vstack([r.components[m][w] for r, w in chosen]) / units.length_scale
             for m in (BEFORE, AFTER)}
    with report_style():
        figure = new_figure(4.6)
        panels = figure.subplots(2, 3)
        for row, model in enumerate((BEFORE, AFTER)):
            for a, axes in enumerate(panels[row]):
                values = parts[model][:, a]
                axes.hist(values, bins=40, color=COLOURS[model], alpha=0.85)
                axes.axvline(0.0, color="#222222", linewidth=0.6)
                axes.set_title(f"{AXES[a]}, {TITLES[model]}", fontsize=9)
                axes.text(0.02, 0.95, mean_and_rms(values), transform=axes.transAxes,
                          va="top", fontsize=7.5)
                axes.set_xlabel(f"{AXES[a]} error [{units.length}]")
                if a == 0:
                    axes.set_ylabel("count")
        figure.suptitle(f"Position error per axis ({frame}): before and after")
    return figure


def magnitude_histogram(groups: Sequence[tuple[str, Sequence[DatasetResiduals]]],
                        units: Units) -> Figure:
    """Histogram of ``|error|`` before and after on logarithmic bins, one panel per group."""
    with report_style():
        figure = new_figure(3.0)
        panels = figure.subplots(1, len(groups), squeeze=False)[0]
        for axes, (title, residuals) in zip(panels, groups):
            values = {m: np.abs(np.concatenate([errors_of(r, m) for r in residuals]))
                      / units.length_scale for m in (BEFORE, AFTER)}
            everything = np.concatenate(list(values.values()))
            positive = everything[everything > 0]
            if positive.size == 0:
                continue
            edges = np.logspace(math.log10(positive.min()), math.log10(positive.max()), 41)
            for model in (BEFORE, AFTER):
                axes.hist(np.maximum(values[model], edges[0]), bins=edges, color=COLOURS[model],
                          alpha=0.7, label=f"{TITLES[model]} (RMS {_rms(values[model]):.3g})")
            log_scale(axes, "x")
            axes.set_xlabel(f"|error| [{units.length}]")
            axes.set_ylabel("count")
            axes.set_title(title)
            axes.legend(loc="upper left")
    return figure


def magnitude_against_joints(residuals: Sequence[DatasetResiduals], robot: Robot, units: Units,
                             title: str) -> Figure:
    """``|error|`` of every row against each joint reading, before and after, with the RMS
    in bins of the reading as lines (log scale, so both show)."""
    chosen = [r for r in residuals if r.joints is not None and (np.asarray(r.rows) >= 0).any()]
    mapped = [np.flatnonzero(np.asarray(r.rows) >= 0) for r in chosen]
    x = np.concatenate([np.asarray(r.joints)[np.asarray(r.rows)[m]] for r, m in zip(chosen,
                                                                                     mapped)])
    errors = {model: np.abs(np.concatenate([errors_of(r, model)[m] for r, m in zip(chosen,
                                                                                  mapped)]))
              / units.length_scale for model in (BEFORE, AFTER)}
    floor = max(min(float(v[v > 0].min()) if (v > 0).any() else 1e-9
                    for v in errors.values()) * 0.5, 1e-9)
    columns = 3 if robot.dof > 4 else robot.dof
    lines = math.ceil(robot.dof / columns)
    keep = _thin(len(x))
    with report_style():
        figure = new_figure(2.2 * lines + 0.5)
        panels = figure.subplots(lines, columns, squeeze=False, sharey=True).ravel()
        for j, axes in enumerate(panels):
            if j >= robot.dof:
                axes.set_visible(False)
                continue
            scale, unit = joint_reading_unit(robot, j, units)
            reading = x[:, j] / scale
            for model in (BEFORE, AFTER):
                axes.scatter(reading[keep], np.maximum(errors[model][keep], floor), s=4,
                             alpha=0.3, color=COLOURS[model], linewidths=0, rasterized=True)
                centres, values = _binned_rms(reading, errors[model])
                axes.plot(centres, values, color=COLOURS[model], marker="o", markersize=3,
                          label=f"{TITLES[model]}, RMS per bin")
            log_scale(axes, "y")
            axes.set_xlabel(f"q{j + 1} [{unit}]")
            if j % columns == 0:
                axes.set_ylabel(f"|error| [{units.length}]")
        handles, labels = panels[0].get_legend_handles_labels()
        figure.legend(handles, labels, loc="outside lower center", ncols=2)
        figure.suptitle(f"{title}: error against each joint reading")
    return figure


def workspace(residuals: Sequence[DatasetResiduals], positions: Sequence[np.ndarray],
              units: Units, title: str) -> Figure:
    """``|error|`` over the workspace: flange positions seen from above (x, y) and from the
    side (x, z), coloured by the error before (top) and after (bottom), on one colour
    scale (zero to the 99th percentile of both), so that a colour means one error.

    ``positions[k]`` are the flange positions [m] (rows x 3, robot base frame) of dataset
    ``k``'s data rows.
    """
    points: list[np.ndarray] = []
    errors: dict[str, list[np.ndarray]] = {BEFORE: [], AFTER: []}
    for r, p in zip(residuals, positions):
        mapped = np.flatnonzero(np.asarray(r.rows) >= 0)
        points.append(np.asarray(p)[np.asarray(r.rows)[mapped]])
        for model in (BEFORE, AFTER):
            errors[model].append(np.abs(errors_of(r, model)[mapped]))
    xyz = np.vstack(points) / units.length_scale
    keep = _thin(len(xyz))
    magnitudes = {model: np.concatenate(errors[model]) / units.length_scale
                  for model in (BEFORE, AFTER)}
    top = float(np.percentile(np.concatenate(list(magnitudes.values())), 99)) or None
    with report_style():
        figure = new_figure(6.0)
        panels = figure.subplots(2, 2)
        for row, model in enumerate((BEFORE, AFTER)):
            magnitude = magnitudes[model]
            for column, (a, b) in enumerate(((0, 1), (0, 2))):
                axes = panels[row, column]
                order = keep[np.argsort(magnitude[keep])]  # largest errors drawn on top
                dots = axes.scatter(xyz[order, a], xyz[order, b], c=magnitude[order], s=9,
                                    cmap="viridis", linewidths=0, rasterized=True,
                                    vmin=0.0, vmax=top)
                axes.set_aspect("equal", adjustable="datalim")
                axes.set_xlabel(f"{AXES[a]} [{units.length}]")
                axes.set_ylabel(f"{AXES[b]} [{units.length}]")
                axes.set_title(f"{'top' if column == 0 else 'side'} view, {TITLES[model]}",
                               fontsize=9)
        bar = figure.colorbar(dots, ax=panels, shrink=0.9)  # one scale for both rows
        bar.set_label(f"|error| [{units.length}], before and after")
        figure.suptitle(f"{title}: error across the workspace (flange positions, base frame)")
    return figure


# ----------------------------------------------------------------------------- lengths


def placement_lengths(residuals: Sequence[DatasetResiduals], units: Units) -> Figure:
    """Per placement of the bar or artifact: each known length's error and the
    perpendicularity error, before and after (signed)."""
    series: dict[str, list[tuple[str, float, float]]] = {}
    for r in residuals:
        if not (r.terms and r.components):
            continue
        for i, term in enumerate(r.terms):
            if term.kind not in ("distance", "perpendicular"):
                continue
            if term.kind == "distance":
                name = f"|{term.points[0]}{term.points[1]}| - L" if \
                    all(len(p) == 1 for p in term.points) else \
                    f"|{term.points[0]} - {term.points[1]}| - L"
            else:
                a, c, b, d = term.points
                name = f"perpendicularity {a}{c}.{b}{d} / L"
            prefix = f"{dataset_name(r)} " if len(residuals) > 1 else ""
            series.setdefault(name, []).append(
                (f"{prefix}{term.pose}", r.components[BEFORE][i, 0] / units.length_scale,
                 r.components[AFTER][i, 0] / units.length_scale))
    names = sorted(series, key=lambda n: (n.startswith("perpendicularity"), n))[:6]
    with report_style():
        figure = new_figure(1.9 * len(names) + 0.7)
        panels = figure.subplots(len(names), 1, squeeze=False, sharex=False).ravel()
        for axes, name in zip(panels, names):
            entries = series[name]
            index = np.arange(len(entries))
            before = np.array([e[1] for e in entries])
            after = np.array([e[2] for e in entries])
            axes.bar(index - 0.2, before, width=0.4, color=COLOURS[BEFORE],
                     label=f"{TITLES[BEFORE]} (RMS {_rms(before):.3g})")
            axes.bar(index + 0.2, after, width=0.4, color=COLOURS[AFTER],
                     label=f"{TITLES[AFTER]} (RMS {_rms(after):.3g})")
            axes.axhline(0.0, color="#222222", linewidth=0.6)
            axes.set_ylabel(f"[{units.length}]")
            axes.set_title(name, fontsize=9, loc="left")
            step = max(1, len(entries) // 30)
            axes.set_xticks(index[::step], [e[0] for e in entries][::step], fontsize=7)
            axes.legend(loc="upper right", ncols=2)
        panels[-1].set_xlabel("placement")
        figure.suptitle("Known lengths and perpendicularity per placement: before and after")
    return figure


# ----------------------------------------------------------------------------- sphere


def sphere_scan(residuals: Sequence[DatasetResiduals], units: Units) -> Figure:
    """Signed distance of each laser point from the sphere surface over the scan, before
    (top) and after (bottom); scans one after another."""
    chosen = _of_kind(residuals, "surface")
    with report_style():
        figure = new_figure(4.4)
        panels = figure.subplots(2, 1, sharex=True)
        start = 0
        for r, which in chosen:
            index = start + np.arange(which.size)
            for axes, model in zip(panels, (BEFORE, AFTER)):
                values = r.components[model][which, 0] / units.length_scale
                axes.plot(index, values, color=COLOURS[model], linewidth=0.8)
            if start:
                for axes in panels:
                    axes.axvline(start - 0.5, color="#555555", linewidth=0.6)
            start += which.size
        for axes, model in zip(panels, (BEFORE, AFTER)):
            values = np.concatenate([r.components[model][w, 0] for r, w in chosen]) \
                / units.length_scale
            axes.axhline(0.0, color="#222222", linewidth=0.6)
            axes.set_ylabel(f"distance [{units.length}]")
            axes.set_title(f"{TITLES[model]}: RMS {_rms(values):.3g} {units.length}, "
                           f"max {np.max(np.abs(values)):.3g} {units.length}", fontsize=9,
                           loc="left")
        panels[-1].set_xlabel("reading, in scan order")
        figure.suptitle("Distance of the laser point from the sphere surface over the scan "
                        "(outside positive)")
    return figure


# ----------------------------------------------------------------------------- unexplained


def residual_against(values: np.ndarray, errors: np.ndarray, label: str, units: Units) -> Figure:
    """The calibrated error magnitude against ``values`` (one per error), with its RMS per
    bin: the structure the model does not explain."""
    errors = np.abs(np.asarray(errors, dtype=float)) / units.length_scale
    values = np.asarray(values, dtype=float)
    keep = _thin(values.size)
    with report_style():
        figure = new_figure(3.0, WIDTH * 0.85)
        axes = figure.add_subplot()
        axes.scatter(values[keep], errors[keep], s=5, alpha=0.35, color=COLOURS[AFTER],
                     linewidths=0, rasterized=True)
        centres, rms = _binned_rms(values, errors)
        axes.plot(centres, rms, color="#222222", marker="o", markersize=3, label="RMS per bin")
        axes.set_ylim(bottom=0)
        axes.set_xlabel(label)
        axes.set_ylabel(f"|error| after calibration [{units.length}]")
        axes.legend(loc="upper right")
        figure.suptitle(f"What the model leaves: error against {label}")
    return figure
