"""Numbers in the report as a reader sees them: one length unit throughout, means at the
resolution the figure's RMS is printed with, and plot titles the axes can confirm."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from test_report import read_page, synthetic_result

from robocal_casadi.common.units import Units
from robocal_casadi.report import write_report
from robocal_casadi.report.figures import singular_values
from robocal_casadi.report.kind_figures import position_axes
from robocal_casadi.results import DatasetResiduals, ErrorTerm, Identifiability


def _position_residuals(offset: np.ndarray, rows: int = 300) -> DatasetResiduals:
    """Position errors [m] whose per-axis mean is exactly ``offset`` up to rounding."""
    rng = np.random.default_rng(3)
    parts = rng.normal(0.0, 0.4e-3, size=(rows, 3))
    parts = parts - parts.mean(axis=0) + offset  # the mean left is floating-point noise
    norms = np.linalg.norm(parts, axis=1)
    components = {"nominal": parts * 20.0, "final": parts}
    return DatasetResiduals(label="a.yaml", kind="tracker_points", errors_nominal=norms * 20,
                            errors_geometric=norms, errors_final=norms, rows=np.arange(rows),
                            joints=None, components=components,
                            terms=tuple(ErrorTerm("position") for _ in range(rows)),
                            frame="instrument")


def _panel_means(figure) -> list[str]:
    texts = [t.get_text() for axes in figure.axes for t in axes.texts]
    return [re.match(r"mean (\S+)\nRMS (\S+)", t).groups() for t in texts]


def test_per_axis_means_below_the_resolution_print_as_zero():
    """A mean left by floating-point rounding (1e-17 m against an RMS of 0.4 mm) prints
    as 0; a real bias prints within half a unit of the RMS's last printed digit."""
    units = Units("mm", "deg")
    for mean, rms in _panel_means(position_axes([_position_residuals(np.zeros(3))], units)):
        assert mean == "0", (mean, rms)
    bias = np.array([0.0123e-3, -0.2e-3, 0.0])
    shown = _panel_means(position_axes([_position_residuals(bias)], units))
    for (mean, rms), true in zip(shown[3:], bias * 1e3):  # after-calibration panels
        resolution = 10.0 ** (np.floor(np.log10(float(rms))) - 2)  # RMS to 3 digits
        assert abs(float(mean) - true) <= resolution / 2 + 1e-15
        assert (mean == "0") == (abs(true) < resolution / 2)


def test_singular_value_title_is_the_ratio_the_axis_shows():
    """The title's number is the largest over the smallest value drawn, even when the
    calibration's condition number is that of a subset."""
    values = np.array([12.0, 4.0, 0.9, 0.05, 2e-4])
    ident = Identifiability(("a", "b", "c", "d", "e"), ("a", "b", "c"), {}, values,
                            condition_number=12.0 / 0.9)
    figure = singular_values(ident)
    axes = figure.axes[0]
    drawn = np.asarray(axes.get_lines()[0].get_ydata(), dtype=float)
    number = float(re.search(r"= ([0-9.eE+-]+)", axes.get_title()).group(1))
    assert number == pytest.approx(drawn.max() / drawn.min(), rel=5e-4)  # 4 digits printed


def test_relations_between_lengths_and_angles_are_in_the_report_units(tmp_path):
    """A relation found in SI (an angle acting like -0.08236 m of a length per rad) is
    shown per mm when the report shows lengths in mm, whatever the file's unit."""
    result = synthetic_result(Units("m", "rad"), validation=False, effects=False)
    relation = "-1*theta2 -0.08236*d3"
    held = dict(result.identifiability.unidentifiable)
    held["beta1"] = f"a combination of parameters already identified (beta1 acts like {relation})"
    ident = replace(result.identifiability, unidentifiable=held,
                    combinations=(f"beta1 ~ {relation}",))
    parameters = tuple(replace(p, reason=held[p.name]) if p.name == "beta1" else p
                       for p in result.parameters)
    result = replace(result, identifiability=ident, parameters=parameters)
    page = read_page(write_report(result, tmp_path / "r.html"))
    cells = [row[-1] for name in ("not-identifiable", "combinations", "parameters-held")
             for row in page.tables[name][1:] if "beta1" in row[0]]
    assert len(cells) == 3
    for cell in cells:
        assert "-82.36*d3" in cell and "-1*theta2" in cell, cell
