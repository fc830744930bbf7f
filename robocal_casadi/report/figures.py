"""The report's plots: matplotlib figures in one style, axes labelled with units.

Every function returns a fresh ``matplotlib.figure.Figure`` on an Agg canvas (no pyplot,
so the caller's matplotlib backend and state are left alone), with errors in the robot
file's length unit and joint readings in its angle unit (length unit for prismatic
joints). ``png_bytes`` renders one.
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING

import matplotlib
import matplotlib.image
import matplotlib.ticker as ticker
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..common.units import Units
from ..model.robot import Robot
from ..results import DatasetResiduals, Identifiability
from .numbers import MODEL_TITLES, errors_of, joint_reading_unit

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

    from .effect_views import EffectView

COLOURS = {"nominal": "#8c8c8c", "geometric": "#d9822b", "final": "#1f6fb2"}
ALPHA = {"nominal": 0.35, "geometric": 0.45, "final": 0.6}
STYLE: dict[RcKeyType, float | str | bool] = {
    "font.size": 9.0,
    "axes.titlesize": 10.0,
    "axes.labelsize": 9.0,
    "axes.grid": True,
    "grid.alpha": 0.35,
    "grid.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.fontsize": 8.0,
    "legend.frameon": False,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "figure.dpi": 110,
    "savefig.dpi": 110,
    "lines.linewidth": 1.4,
}
WIDTH = 8.0  # [in], one figure across the page
SCATTER_LIMIT = 20000  # points per series drawn; more are thinned evenly
BINS = 12


@contextmanager
def report_style() -> Iterator[None]:
    """The report's matplotlib settings, applied only inside the block."""
    with matplotlib.rc_context(STYLE):
        yield


def new_figure(height: float, width: float = WIDTH) -> Figure:
    """An Agg-backed figure of ``width`` x ``height`` inches with the report's layout."""
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


LOG_MINOR = (2.0, 5.0)  # minor ticks of a log axis, per decade


def log_scale(axes, which: str) -> None:
    """A log ``which`` axis ("x" or "y") with minor ticks at 2 and 5 of each decade only:
    enough to read values between the decades (and labelled where an axis spans less
    than one), at a quarter of the tick objects a full 2..9 set costs to lay out and draw."""
    if which == "x":
        axes.set_xscale("log")
        axes.xaxis.set_minor_locator(ticker.LogLocator(10.0, subs=LOG_MINOR))
    else:
        axes.set_yscale("log")
        axes.yaxis.set_minor_locator(ticker.LogLocator(10.0, subs=LOG_MINOR))


def png_bytes(figure: Figure) -> bytes:
    """The figure as PNG bytes, at the figure's own resolution.

    Drawn once on its Agg canvas and encoded from the canvas's pixels: ``savefig`` would
    draw a laid-out figure twice (once to lay it out, once to render), and the drawing is
    most of a report's plotting time; the pixels are the same."""
    canvas = figure.canvas
    if not isinstance(canvas, FigureCanvasAgg):
        canvas = FigureCanvasAgg(figure)
    canvas.draw()
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, np.asarray(canvas.buffer_rgba()), format="png",
                            dpi=figure.dpi)
    return buffer.getvalue()


# ----------------------------------------------------------------------------- helpers


def _thin(count: int) -> np.ndarray:
    """Indices of at most ``SCATTER_LIMIT`` evenly spread items out of ``count``."""
    if count <= SCATTER_LIMIT:
        return np.arange(count)
    return np.linspace(0, count - 1, SCATTER_LIMIT).astype(int)


def _mapped(residuals: DatasetResiduals) -> np.ndarray:
    """Positions of the errors that belong to one data row (``rows >= 0``)."""
    return np.flatnonzero(np.asarray(residuals.rows) >= 0)


def _binned_rms(x: np.ndarray, errors: np.ndarray,
                bins: int = BINS) -> tuple[np.ndarray, np.ndarray]:
    """Centres and RMS of ``errors`` in ``bins`` equal-width bins of ``x`` (empty bins dropped)."""
    if x.size == 0 or not np.isfinite(x).any():
        return np.zeros(0), np.zeros(0)
    lo, hi = float(np.nanmin(x)), float(np.nanmax(x))
    if hi <= lo:
        return np.array([lo]), np.array([math.sqrt(float(np.mean(errors**2)))])
    edges = np.linspace(lo, hi, bins + 1)
    which = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    centres, values = [], []
    for b in range(bins):
        inside = which == b
        if inside.any():
            centres.append(0.5 * (edges[b] + edges[b + 1]))
            values.append(math.sqrt(float(np.mean(errors[inside] ** 2))))
    return np.array(centres), np.array(values)


def _ecdf(axes, errors: np.ndarray, scale: float, model: str) -> None:
    magnitude = np.sort(np.abs(errors)) / scale
    if magnitude.size == 0:
        return
    fraction = np.arange(1, magnitude.size + 1) / magnitude.size
    axes.step(magnitude, fraction, where="post", color=COLOURS[model], label=MODEL_TITLES[model])


def _positive_floor(values: np.ndarray) -> float:
    positive = values[values > 0]
    return float(positive.min()) if positive.size else 1e-12


# ----------------------------------------------------------------------------- figures


def shown_ratio_title(values: np.ndarray) -> str:
    """The singular-value plot's title: the ratio of the largest to the smallest positive
    value the axis shows (zeros, drawn at the floor, are counted apart)."""
    positive = values[values > 0]
    zeros = int(values.size - positive.size)
    if positive.size == 0:
        return "Singular values: all zero"
    title = (f"Singular values: largest / smallest shown = "
             f"{positive.max() / positive.min():.4g}")
    return title + (f" ({zeros} exactly zero, drawn at the floor)" if zeros else "")


def singular_values(identifiability: Identifiability) -> Figure:
    """Singular values of the scaled identification Jacobian, log scale, largest first."""
    with report_style():
        figure = new_figure(3.0)
        axes = figure.add_subplot()
        values = np.asarray(identifiability.singular_values, dtype=float)
        index = np.arange(1, values.size + 1)
        floor = _positive_floor(values) * 1e-3
        shown = np.where(values > 0, values, floor)
        axes.plot(index, shown, color=COLOURS["final"], marker="o", markersize=4)
        log_scale(axes, "y")
        kept = len(identifiability.identifiable)
        if 0 < kept < values.size:
            axes.axvline(kept + 0.5, color=COLOURS["geometric"], linestyle="--", linewidth=1.0,
                         label=f"{kept} identifiable parameters")
            axes.legend(loc="lower left")
        axes.set_xlabel("singular value index (largest first)")
        axes.set_ylabel("singular value (scaled Jacobian) [-]")
        axes.set_title(shown_ratio_title(values))
        axes.xaxis.set_major_locator(ticker.MaxNLocator(integer=True))
    return figure


def error_distribution(groups: Sequence[tuple[str, tuple[DatasetResiduals, ...]]],
                       units: Units) -> Figure:
    """Empirical cumulative distribution of ``|error|`` per model, one panel per group.

    ``groups`` is e.g. ``[("fit data", residuals), ("validation data", residuals)]``.
    """
    scale = units.length_scale
    with report_style():
        figure = new_figure(3.2)
        panels = figure.subplots(1, len(groups), squeeze=False)[0]
        for axes, (title, residuals) in zip(panels, groups):
            everything = []
            for model in ("nominal", "geometric", "final"):
                errors = np.concatenate([errors_of(r, model) for r in residuals]) \
                    if residuals else np.zeros(0)
                everything.append(np.abs(errors))
                _ecdf(axes, errors, scale, model)
            pooled = np.concatenate(everything) / scale
            if (pooled > 0).any():
                log_scale(axes, "x")
                axes.set_xlim(left=max(_positive_floor(pooled), pooled.max() * 1e-5))
            axes.set_xlabel(f"|error| [{units.length}]")
            axes.set_ylabel("fraction of measurements [-]")
            axes.set_ylim(0, 1.02)
            axes.set_title(title)
            axes.legend(loc="lower right")
    return figure


def _models(residuals: tuple[DatasetResiduals, ...], wanted: Sequence[str]) -> list[str]:
    """``wanted`` models, without ``geometric`` when it equals ``final`` (no effect added)."""
    same = all(np.array_equal(errors_of(r, "geometric"), errors_of(r, "final")) for r in residuals)
    return [m for m in wanted if not (same and m == "geometric")]


def _label(model: str, models: list[str]) -> str:
    if model == "final" and "geometric" not in models:
        return "calibrated (no effect added)"
    return MODEL_TITLES[model]


def _with_rows(residuals: tuple[DatasetResiduals, ...]) -> list[DatasetResiduals]:
    return [r for r in residuals if _mapped(r).size]


def error_against_joints(residuals: tuple[DatasetResiduals, ...], robot: Robot, units: Units,
                         title: str) -> Figure:
    """Calibrated errors against each joint reading, one panel per joint, datasets pooled.

    Errors that belong to no single row (e.g. a bar length) are left out.
    """
    residuals = tuple(r for r in _with_rows(residuals) if r.joints is not None)
    models = _models(residuals, ("geometric", "final"))
    x = np.concatenate([np.asarray(r.joints)[np.asarray(r.rows)[_mapped(r)]] for r in residuals])
    errors = {m: np.concatenate([errors_of(r, m)[_mapped(r)] for r in residuals])
              / units.length_scale for m in models}
    columns = 3 if robot.dof > 4 else robot.dof
    lines = math.ceil(robot.dof / columns)
    keep = _thin(len(x))
    with report_style():
        figure = new_figure(2.1 * lines + 0.4)
        panels = figure.subplots(lines, columns, squeeze=False, sharey=True).ravel()
        for j, axes in enumerate(panels):
            if j >= robot.dof:
                axes.set_visible(False)
                continue
            reading_scale, reading_unit = joint_reading_unit(robot, j, units)
            for model in models:
                axes.scatter(x[keep, j] / reading_scale, errors[model][keep], s=5,
                             alpha=ALPHA[model], color=COLOURS[model], linewidths=0,
                             rasterized=True, label=_label(model, models))
            axes.set_xlabel(f"q{j + 1} [{reading_unit}]")
            if j % columns == 0:
                axes.set_ylabel(f"error [{units.length}]")
        panels[0].legend(loc="best", markerscale=3)
        figure.suptitle(f"{title}: error against each joint reading")
    return figure


def error_over_rows(residuals: tuple[DatasetResiduals, ...], units: Units, title: str) -> Figure:
    """``|error|`` of every model against measurement order (datasets one after another,
    boundaries marked) and, where the data has a ``temperature`` column, against it."""
    residuals = tuple(_with_rows(residuals))
    models = _models(residuals, ("nominal", "geometric", "final"))
    starts = np.cumsum([0] + [int(np.asarray(r.rows).max()) + 1 for r in residuals])
    order = np.concatenate([start + np.asarray(r.rows)[_mapped(r)]
                            for start, r in zip(starts, residuals)]).astype(float)
    magnitude = {m: np.abs(np.concatenate([errors_of(r, m)[_mapped(r)] for r in residuals]))
                 / units.length_scale for m in models}
    with_temperature = [r for r in residuals if "temperature" in r.extras]
    keep = _thin(order.size)
    floor = min(_positive_floor(v) for v in magnitude.values()) * 0.5
    with report_style():
        figure = new_figure(3.0)
        panels = figure.subplots(1, 2 if with_temperature else 1, squeeze=False, sharey=True)[0]
        for model in models:
            panels[0].scatter(order[keep], np.maximum(magnitude[model][keep], floor), s=5,
                              alpha=ALPHA[model], linewidths=0, color=COLOURS[model],
                              rasterized=True, label=_label(model, models))
        if len(residuals) > 1:
            for start in starts[1:-1]:
                panels[0].axvline(start - 0.5, color="#555555", linewidth=0.6, alpha=0.6)
        panels[0].set_xlabel("data row, datasets in turn (measurement order)")
        panels[0].set_ylabel(f"|error| [{units.length}]")
        log_scale(panels[0], "y")
        panels[0].set_ylim(bottom=floor)
        panels[0].legend(loc="best", markerscale=3)
        if with_temperature:
            temperature = np.concatenate([np.asarray(r.extras["temperature"], dtype=float)
                                          [np.asarray(r.rows)[_mapped(r)]]
                                          for r in with_temperature])
            keep_t = _thin(temperature.size)
            for model in models:
                values = np.concatenate([np.abs(errors_of(r, model)[_mapped(r)])
                                         for r in with_temperature]) / units.length_scale
                panels[1].scatter(temperature[keep_t], np.maximum(values[keep_t], floor), s=5,
                                  alpha=ALPHA[model], linewidths=0, color=COLOURS[model],
                                  rasterized=True)
            panels[1].set_xlabel("temperature [C]")
        figure.suptitle(f"{title}: error magnitude over the measurements")
    return figure


def effect_evidence(view: EffectView, units: Units) -> Figure:
    """Errors before (geometric) and after (final) an effect against its own variable.

    One panel per joint (``view.panels``): scatter of both error sets with their RMS in
    bins of the variable as lines, so what the effect took out shows as the gap between
    the lines; the fitted effect on a right-hand axis (dashed line, or points when it is
    not a function of the variable alone).
    """
    count = max(1, len(view.panels))
    columns = min(2, count)
    lines = math.ceil(count / columns)
    width = WIDTH if columns > 1 else WIDTH * 0.85
    with report_style():
        figure = new_figure(2.9 * lines + 0.4, width)
        panels = figure.subplots(lines, columns, squeeze=False).ravel()
        for p, axes in enumerate(panels):
            if p >= len(view.panels):
                axes.set_visible(False)
                continue
            panel = view.panels[p]
            keep = _thin(panel.x.size)
            handles = []
            for model, errors in (("geometric", panel.geometric), ("final", panel.final)):
                axes.scatter(panel.x[keep], errors[keep], s=4, alpha=0.3, linewidths=0,
                             color=COLOURS[model], rasterized=True)
                centres, values = _binned_rms(panel.x, errors)
                title = "before: geometric only" if model == "geometric" else \
                    "after: with the effects"
                handles += axes.plot(centres, values, color=COLOURS[model], marker="o",
                                     markersize=3, label=f"{title}, RMS per bin")
            if (panel.geometric >= 0).all() and (panel.final >= 0).all():
                axes.set_ylim(bottom=0)
            axes.set_xlabel(panel.x_label)
            axes.set_ylabel(f"error [{units.length}]")
            if panel.fitted is not None and panel.fitted.size == panel.x.size:
                right = axes.twinx()
                right.grid(False)
                right.spines["right"].set_visible(True)
                if panel.fitted_is_curve:
                    order = np.argsort(panel.x)
                    handles += right.plot(panel.x[order], panel.fitted[order], color="#222222",
                                          linestyle="--", linewidth=1.3,
                                          label="fitted effect (right axis)")
                else:
                    handles.append(right.scatter(panel.x[keep], panel.fitted[keep], s=3,
                                                 color="#222222", alpha=0.5, linewidths=0,
                                                 rasterized=True,
                                                 label="fitted effect (right axis)"))
                right.axhline(0.0, color="#222222", linewidth=0.5, alpha=0.4)
                right.set_ylabel(panel.fitted_label)
                right.yaxis.set_major_formatter(ticker.ScalarFormatter(useMathText=True))
                right.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4))
            if p == 0:
                figure.legend(handles=handles, loc="outside lower center", ncols=len(handles))
        figure.suptitle(f"{view.title}: error before and after")
    return figure


def predicted_errors(errors: np.ndarray, scale: float, unit: str,
                     region: str = "the joint ranges the data cover") -> Figure:
    """Histogram of the predicted tool-position error [``unit``] over the sampled poses of
    the work cell (``job.accuracy``)."""
    with report_style():
        figure = new_figure(2.8)
        axes = figure.add_subplot()
        values = np.asarray(errors, dtype=float) / scale
        axes.hist(values, bins=30, color=COLOURS["final"], alpha=0.8)
        axes.axvline(float(np.sqrt(np.mean(values**2))), color=COLOURS["geometric"],
                     linestyle="--", linewidth=1.0, label="RMS")
        axes.axvline(float(np.percentile(values, 95)), color=COLOURS["nominal"],
                     linestyle=":", linewidth=1.0, label="95th percentile")
        axes.set_xlabel(f"predicted tool-position error [{unit}]")
        axes.set_ylabel("poses")
        axes.set_title(f"Predicted error over {region}")
        axes.legend(loc="upper right")
    return figure
