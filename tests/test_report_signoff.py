"""A report to sign: sign-off block, numbered pages, tables that fit the page, mm throughout."""

from __future__ import annotations

import re
import zlib
from dataclasses import replace

import numpy as np
import pytest
from test_report import _with_effect_models, read_page, synthetic_result

from robocal_casadi.common.units import Units
from robocal_casadi.report import write_report
from robocal_casadi.report.info import ReportInfo


def _signatures(page) -> list[list[list[str]]]:
    return [rows for name, rows in page.tables.items() if name == "signature"]


def test_sign_off_names_the_operator_and_the_customer(tmp_path):
    info = ReportInfo(customer="Acme Gearboxes Ltd", operator="J. Smith")
    path = write_report(synthetic_result(validation=False, effects=False),
                        tmp_path / "r.html", info=info)
    text = path.read_text(encoding="utf-8")
    block = text[text.index('<div class="sign-off"'):text.index("</footer>")]
    page = read_page(path)
    tables = re.findall(r'<table class="signature">.*?</table>', block, re.S)
    assert len(tables) == 2
    measured, accepted = tables
    assert "Measured and calibrated by" in measured and "J. Smith" in measured
    assert "Acme Gearboxes Ltd" in accepted
    for table in tables:  # role, date and signature are lines to fill in
        for label in ("name", "role", "date", "signature"):
            assert f"<th>{label}</th>" in table
        assert re.search(r"<th>signature</th><td></td>", table)
    assert page.tables  # the page still parses


def test_sign_off_leaves_names_blank_without_report_fields(tmp_path):
    path = write_report(synthetic_result(validation=False, effects=False),
                        tmp_path / "r.html")
    block = path.read_text(encoding="utf-8").split('<div class="sign-off"')[1]
    assert "<th>name</th><td></td>" in block and "<th>for</th>" not in block


def test_printed_pages_are_numbered_and_tables_fit_the_page():
    """The print style numbers pages n of m in the bottom margin, and lets wide tables
    take the page's width with wrapping cells instead of overflowing it."""
    from robocal_casadi.report.html import TEMPLATES

    css = (TEMPLATES / "report.css").read_text(encoding="utf-8")
    page_rule = css[css.index("@page"):]
    assert re.search(r'@bottom-center\s*{\s*content:\s*"page " counter\(page\) " of " '
                     r"counter\(pages\)", page_rule)
    printed = css[css.index("@media print"):css.index("@page")]
    assert "max-width: 100%" in printed and "overflow-wrap: anywhere" in printed
    assert "nowrap" not in printed.replace("td.number", "")


def _pdf_text(pdf: bytes) -> list[str]:
    """The text shown on each page of a matplotlib PDF, in drawing order."""
    pages = []
    for stream in re.findall(rb"stream\r?\n(.*?)\r?\nendstream", pdf, re.S):
        try:
            content = zlib.decompress(stream)
        except zlib.error:
            content = stream
        if b"BT" not in content:
            continue
        shown = re.findall(rb"\[(.*?)\]\s*TJ|\((.*?)\)\s*Tj", content, re.S)
        text = []
        for array, single in shown:
            parts = re.findall(rb"\(((?:\\.|[^\\)])*)\)", array) if array else [single]
            text.append(b"".join(parts).decode("latin-1"))
        pages.append(" ".join(text))
    return pages


def test_matplotlib_pdf_numbers_its_pages_and_ends_with_the_sign_off(tmp_path):
    info = ReportInfo(operator="J. Smith", customer="Acme Gearboxes Ltd")
    path = write_report(synthetic_result(validation=False, effects=False),
                        tmp_path / "r.html", pdf=True, printer="matplotlib", info=info)
    pdf = path.with_suffix(".pdf").read_bytes()
    count = len(re.findall(rb"/Type\s*/Page\b", pdf))
    texts = [t for t in _pdf_text(pdf) if "page " in t]
    footers = [re.search(r"page (\d+) of (\d+)", t) for t in texts]
    numbers = sorted(int(m.group(1)) for m in footers if m)
    assert numbers == list(range(1, count + 1))
    assert {int(m.group(2)) for m in footers if m} == {count}
    last = next(t for t in texts if f"page {count} of {count}" in t)
    assert "Measured and calibrated by" in last and "J. Smith" in last
    assert "Acme Gearboxes Ltd" in last
    for label in ("role:", "date:", "signature:"):
        assert last.count(label) == 2


def test_effect_plot_of_a_metre_file_is_in_millimetres():
    """The effect's plot is labelled in mm, and its errors are the result's [m] x 1000."""
    from robocal_casadi.effects.thermal import ThermalDrift
    from robocal_casadi.report import figures
    from robocal_casadi.report.effect_views import effect_view
    from robocal_casadi.report.numbers import display_units

    result = synthetic_result(Units("m", "rad"), validation=False, effects=False)
    result = _with_effect_models(result, (ThermalDrift(column="temperature",
                                                       reference_value=23.3),), [1.2e-5])
    view = effect_view(result, result.effects[0])
    r = result.residuals[0]
    np.testing.assert_allclose(view.panels[0].geometric, r.errors_geometric[r.rows] * 1e3,
                               rtol=1e-12)
    figure = figures.effect_evidence(view, display_units(result.units))
    labels = [axes.get_ylabel() for axes in figure.axes]
    assert "error [mm]" in labels


@pytest.mark.parametrize("length", ["m", "mm"])
def test_every_length_in_a_table_is_in_millimetres(length):
    """Whatever the file's unit, table headers and unit cells give lengths in mm, never m,
    and no unit cell is left empty."""
    from robocal_casadi.report.content import Details, Table
    from robocal_casadi.report.sections import build_document

    result = replace(synthetic_result(Units(length, "deg"), bar=True), notes=())
    blocks = [b for s in build_document(result).sections for b in s.blocks]
    blocks += [inner for b in blocks if isinstance(b, Details) for inner in b.blocks]
    tables = [b for b in blocks if isinstance(b, Table)]
    assert len(tables) > 5
    for table in tables:
        assert "[m]" not in " ".join(table.header) + table.caption, table.name
        if "unit" in table.header:
            k = table.header.index("unit")
            units = {row[k] for row in table.rows}
            assert "m" not in units and "" not in units, table.name


def test_matplotlib_pdf_table_wider_than_the_page_wraps_inside_it():
    """Eight columns of 60-character text (about 500 characters a row, more than a page
    holds at the smallest type): every cell is drawn, word for word, within the margins."""
    from robocal_casadi.report import pdf
    from robocal_casadi.report.content import Table
    from robocal_casadi.report.figures import new_figure, report_style

    words = "a long description of what this column holds for the reader"
    table = Table("wide", "A wide table", tuple(f"column {k}" for k in range(8)),
                  tuple(tuple(f"{words} {k}" for k in range(8)) for _ in range(3)))
    flowables = pdf._table(table)
    assert len(flowables) == 1
    with report_style():
        figure = new_figure(pdf.PAGE[1], pdf.PAGE[0])
    figure.set_layout_engine(None)
    flowables[0].draw(figure, pdf.MARGIN)
    renderer = figure.canvas.get_renderer()
    right = max(t.get_window_extent(renderer).x1 for t in figure.texts) / figure.dpi
    assert right <= pdf.PAGE[0] - pdf.MARGIN + 0.05  # [in], a glyph's side bearing
    drawn = " ".join(t.get_text() for t in figure.texts)
    assert drawn.count("reader") == 24 and drawn.count("description") == 24
