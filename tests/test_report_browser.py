"""The report in a real browser: headless Chromium loads it offline, every image decodes,
and a screenshot of the page is a valid, non-blank PNG.

Skipped when Chromium is not installed (``apt-get install chromium``; ``.ci/run`` does it).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from test_report import synthetic_result

from robocal_casadi.report import find_chromium, page_state, screenshot_report, write_report

needs_chromium = pytest.mark.skipif(find_chromium() is None,
                                    reason="Chromium not installed (apt-get install chromium)")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    path = tmp_path_factory.mktemp("browser") / "report.html"
    return write_report(synthetic_result(validation=False, effects=False), path)


@pytest.fixture(scope="module")
def state(report):
    return page_state(report)


@needs_chromium
def test_page_loads_with_every_image_decoded(report, state):
    images_in_file = len(re.findall(r"<img\b", report.read_text(encoding="utf-8")))
    assert images_in_file > 0
    assert state.get("report-ready") == "true", state
    assert int(state["images-total"]) == images_in_file
    assert int(state["images-loaded"]) == images_in_file
    assert int(state["page-height"]) > 2000  # many sections and figures, not an empty page


@needs_chromium
def test_screenshot_is_a_non_blank_png(report, tmp_path):
    png = screenshot_report(report, tmp_path / "shots" / "report.png", height=2000)
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pixels = matplotlib.image.imread(png)
    assert pixels.shape[:2] == (2000, 1280)
    grey = pixels[..., :3].mean(axis=2)
    assert (grey < 0.5).mean() > 0.002, "no dark ink: the page did not render"
    assert (grey > 0.9).mean() > 0.5, "no white page background"
    assert float(np.std(grey)) > 0.05
    # the report's accent colour (the header rule, #1f6fb2) is on screen
    accent = np.abs(pixels[..., :3] - np.array([0x1F, 0x6F, 0xB2]) / 255).max(axis=2) < 0.05
    assert accent.sum() > 500


@needs_chromium
def test_full_page_screenshot_is_as_tall_as_the_page(report, state, tmp_path):
    height = int(state["page-height"])
    png = screenshot_report(report, tmp_path / "full.png")
    assert matplotlib.image.imread(png).shape[:2] == (min(height, 30000), 1280)


def _pages(pdf: bytes) -> int:
    return len(re.findall(rb"/Type\s*/Page\b", pdf))


@needs_chromium
def test_printing_unfolds_the_full_diagnosis_table(tmp_path):
    """The full candidate table is folded on screen; printed, it is all there: the page
    prints to more pages than the same page with that block taken out, and as many as
    with the block opened by hand."""
    from dataclasses import replace

    from test_report import _diagnosis

    from robocal_casadi.report import print_pdf

    result = replace(synthetic_result(validation=False, effects=False), diagnosis=_diagnosis())
    page = write_report(result, tmp_path / "report.html").read_text(encoding="utf-8")
    start = page.index('<details id="diagnosis-all">')
    end = page.index("</details>", start) + len("</details>")
    variants = {"folded": page, "removed": page[:start] + page[end:],
                "opened": page.replace('<details id="diagnosis-all">',
                                       '<details id="diagnosis-all" open>')}
    pages = {}
    for name, text in variants.items():
        (tmp_path / f"{name}.html").write_text(text, encoding="utf-8")
        pdf = print_pdf(tmp_path / f"{name}.html", tmp_path / f"{name}.pdf").read_bytes()
        assert pdf.startswith(b"%PDF")
        pages[name] = _pages(pdf)
    assert pages["removed"] > 0
    assert pages["folded"] == pages["opened"] > pages["removed"], pages


def _page_texts(pdf: Path) -> list[str]:
    """Each page's text (pdftotext, poppler-utils), whitespace collapsed."""
    import subprocess

    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True,
                          text=True, check=True).stdout
    return [" ".join(page.split()) for page in text.split("\f")]


def _images_per_page(pdf: Path) -> dict[int, int]:
    import subprocess

    listing = subprocess.run(["pdfimages", "-list", str(pdf)], capture_output=True, text=True,
                             check=True).stdout.splitlines()[2:]
    counts: dict[int, int] = {}
    for line in listing:
        page = int(line.split()[0])
        counts[page] = counts.get(page, 0) + 1
    return counts


@pytest.mark.skipif(shutil.which("pdftotext") is None or shutil.which("pdfimages") is None,
                    reason="poppler-utils not installed (apt-get install poppler-utils)")
@pytest.mark.parametrize("printer", [pytest.param("chromium", marks=needs_chromium),
                                     "matplotlib"])
def test_printed_pages_keep_tables_whole_and_figures_with_captions(tmp_path, printer):
    """On the PDF's pages: a table's caption and its last row are on one page, and a
    figure's caption is on a page that holds an image."""
    from robocal_casadi.report import build_document

    result = synthetic_result(validation=False, effects=False)
    path = write_report(result, tmp_path / "report.html", pdf=True, printer=printer)
    pdf = path.with_suffix(".pdf")
    pages = _page_texts(pdf)
    images = _images_per_page(pdf)
    document = build_document(result)
    blocks = [b for s in document.sections for b in s.blocks]
    blocks += [inner for b in blocks if type(b).__name__ == "Details" for inner in b.blocks]
    tables = [b for b in blocks if type(b).__name__ == "Table" and 0 < len(b.rows) <= 25]
    plots = [b for b in blocks if type(b).__name__ == "Plot"]
    assert tables and plots
    for table in tables:
        caption = " ".join(table.caption.split())[:40]
        last = table.rows[-1][0]
        assert any(caption in page and last in page[page.index(caption):] for page in pages), \
            f"table {table.name!r} split over pages"
    for plot in plots:
        words = " ".join(plot.caption.split())[:50]
        holding = [k + 1 for k, page in enumerate(pages) if words in page]
        assert holding, f"caption of {plot.name!r} not found"
        assert all(images.get(k, 0) > 0 for k in holding), f"{plot.name!r} caption without image"


@needs_chromium
@pytest.mark.skipif(shutil.which("pdftotext") is None,
                    reason="poppler-utils not installed (apt-get install poppler-utils)")
def test_chromium_numbers_the_printed_pages_and_prints_the_sign_off(tmp_path):
    """Printed by Chromium, every page carries "page k of n" in its bottom margin, the
    last holds the sign-off, and every table's last column header is on the page (a
    table cut at the page edge loses its right-hand columns)."""
    from robocal_casadi.report import build_document
    from robocal_casadi.report.info import ReportInfo

    result = synthetic_result(validation=False, effects=False)
    info = ReportInfo(operator="J. Smith")
    path = write_report(result, tmp_path / "report.html", pdf=True, printer="chromium",
                        info=info)
    pages = _page_texts(path.with_suffix(".pdf"))
    pages = [page for page in pages if page]
    for k, page in enumerate(pages, start=1):
        assert f"page {k} of {len(pages)}" in page
    assert "Measured and calibrated by" in pages[-1] and "J. Smith" in pages[-1]
    document = build_document(result, info=info)
    tables = [b for s in document.sections for b in s.blocks
              if type(b).__name__ == "Table" and 0 < len(b.rows) <= 25 and b.numeric[-1]
              and b.rows[-1][-1] not in ("", "-")]
    assert tables
    for table in tables:  # numbers never wrap: the last row's last number is there whole
        caption = " ".join(table.caption.split())[:40]
        last = table.rows[-1][-1]
        assert any(caption in page and last in page[page.index(caption):] for page in pages), \
            f"table {table.name!r}: its last column is not on the page"
