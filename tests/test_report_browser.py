"""The report in a real browser: headless Chromium loads it offline, every image decodes,
and a screenshot of the page is a valid, non-blank PNG. For a small simulated calibration
of every kind (slow): no table wider than a 1280 px screen or cut at the edge of an A4
page, and the sign-off whole on the screenshot and on one printed page.

Skipped when Chromium is not installed (``apt-get install chromium``; ``.ci/run`` does it).
"""

from __future__ import annotations

import re
import shutil
from html.parser import HTMLParser
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


# ----------------------------------------------------------------------------- every kind


A4 = (595.0, 842.0)  # [pt] portrait
MARGIN = 12 / 25.4 * 72  # [pt] the print style sheet's left and right page margins
TOLERANCE = 2.0  # [pt] a glyph's bounding box beyond its text box
LONGEST = 14  # [characters] longer words may be broken across lines, legitimately
KIND_RUNS = {  # kind: rows to fit, rows held out, extra simulate options
    "cross_bar": (14, 6, {"effects": {"joint_compliance": {2: 2e-6}}, "payload": (0.0, 20.0)}),
    "artifact_touches": (6, 3, {"sockets": 3, "touches": 3}),
    "tracker_points": (60, 30, {"effects": {"joint_compliance": {3: 2e-6}},
                                "payload": (0.0, 10.0)}),
    "sphere_laser": (150, 60, {}),
}
needs_poppler = pytest.mark.skipif(shutil.which("pdftotext") is None,
                                   reason="poppler-utils not installed (apt-get install "
                                          "poppler-utils)")


@pytest.fixture(scope="module", params=sorted(KIND_RUNS))
def kind_report(request, tmp_path_factory):
    """A small simulated calibration of one kind, its report and the report printed to
    PDF by Chromium."""
    from robocal_casadi.cli import main
    from robocal_casadi.instruments.simulate import simulate
    from robocal_casadi.model.examples import industrial_6r
    from robocal_casadi.model.robot import save_robot
    from robocal_casadi.report import print_pdf

    kind = request.param
    fit_rows, held_rows, options = KIND_RUNS[kind]
    folder = tmp_path_factory.mktemp(kind)
    save_robot(industrial_6r(), folder / "robot.yaml")
    sims = [simulate(folder / "robot.yaml", kind, out_dir=folder / role, rows=rows,
                     noise=2e-5, geometric_errors={"a2": 4e-4, "d4": -3e-4, "theta3": 7e-4},
                     mounted_error=0.0, seed=seed, progress=False, **options)
            for role, rows, seed in (("fit", fit_rows, 1), ("held", held_rows, 2))]
    out = folder / "out"
    status = main(["calibrate", str(sims[0].dataset_path), "--validate",
                   str(sims[1].dataset_path), "--out", str(out), "--quiet",
                   "--operator", "J. Smith", "--customer", "Example customer"])
    assert status in (0, 3)  # 3: not better than doing nothing, a report all the same
    html = out / "report.html"
    return kind, html, print_pdf(html, out / "report.pdf")


class _Cells(HTMLParser):
    """The text of every table's caption, header and cells in a report (a column set under
    its row gives its title and its text as cells of their own)."""

    def __init__(self):
        super().__init__()
        self.cells: list[tuple[str, str]] = []  # (table class, text)
        self._table = ""
        self._open: list[list[str]] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "table":
            self._table = attrs.get("class") or ""
        elif tag in ("caption", "th", "td") or (
                tag == "span" and attrs.get("class") in ("below-header", "below-value")):
            self._open.append([])

    def handle_endtag(self, tag):
        if tag in ("caption", "th", "td", "span") and self._open:
            if tag == "span" and not self._open:
                return
            text = " ".join("".join(self._open.pop()).split())
            if text:
                self.cells.append((self._table, text))

    def handle_data(self, data):
        if self._open:
            self._open[-1].append(data)


def _table_words(html: Path) -> set[tuple[str, str]]:
    parser = _Cells()
    parser.feed(html.read_text(encoding="utf-8"))
    return {(table, word) for table, text in parser.cells for word in text.split()}


def _pdf_words(pdf: Path) -> list[tuple[int, float, float, float, float, str]]:
    """Every word Chromium printed: page (1-based), its page's width and height, the
    word's left and right edges [pt] and its text (pdftotext -bbox)."""
    import html as entities
    import subprocess

    xml = subprocess.run(["pdftotext", "-bbox", str(pdf), "-"], capture_output=True,
                         text=True, check=True).stdout
    out = []
    pages = re.findall(r'<page width="([\d.]+)" height="([\d.]+)">(.*?)</page>', xml, re.S)
    for k, (width, height, body) in enumerate(pages, start=1):
        for left, right, word in re.findall(
                r'<word xMin="([\d.]+)" yMin="[\d.]+" xMax="([\d.]+)" yMax="[\d.]+">(.*?)</word>',
                body):
            out.append((k, float(width), float(height), float(left), float(right),
                        entities.unescape(word)))
    return out


@pytest.mark.slow  # a calibration per kind, then Chromium three times
@needs_chromium
def test_no_table_is_wider_than_the_screen_and_the_sign_off_is_whole(kind_report, tmp_path):
    """At 1280 px no table needs scrolling sideways (the page measures every table, folded
    ones unfolded), and the full-page screenshot reaches below the sign-off."""
    kind, html, _ = kind_report
    state = page_state(html, width=1280)
    assert state.get("report-ready") == "true", state
    assert state.get("tables-clipped") == "", f"{kind}: tables wider than the screen: {state}"
    png = screenshot_report(html, tmp_path / f"{kind}.png")
    pixels = matplotlib.image.imread(png)
    assert pixels.shape[1] == 1280
    assert pixels.shape[0] >= int(state["sign-off-bottom"]) > 0
    # the sign-off's last line (the signature rule, dark ink) is in the picture
    bottom = int(state["sign-off-bottom"])
    assert (pixels[bottom - 80:bottom, :, :3].mean(axis=2) < 0.3).any()


@pytest.mark.slow
@needs_chromium
@needs_poppler
def test_printed_a4_pages_hold_every_table_whole_and_the_sign_off_on_one_page(kind_report):
    """Printed to A4 portrait: every word lies within the page's margins, every word of
    every table (caption, header, cells) is printed, so no column is cut at the page
    edge, and one page holds the whole sign-off block."""
    kind, html, pdf = kind_report
    words = _pdf_words(pdf)
    assert words
    sizes = {(w, h) for _, w, h, *_ in words}
    assert all(abs(w - A4[0]) < 1 and abs(h - A4[1]) < 1 for w, h in sizes), \
        f"{kind}: pages not A4 portrait: {sizes}"
    outside = [(page, word) for page, width, _, left, right, word in words
               if left < MARGIN - TOLERANCE or right > width - MARGIN + TOLERANCE]
    assert not outside, f"{kind}: printed beyond the margins: {outside[:5]}"
    printed = {word.rstrip(":") for *_, word in words}  # a set-under title gains a colon
    missing = sorted({(table, word) for table, word in _table_words(html)
                      if len(word) <= LONGEST and word.rstrip(":") not in printed})
    assert not missing, f"{kind}: table words not printed: {missing[:10]}"
    signers = ("Measured and calibrated by", "Checked and accepted for the customer")
    pages = _page_texts(pdf)
    holding = [k for k, page in enumerate(pages) if "Sign-off" in page]
    assert len(holding) == 1, f"{kind}: the sign-off heading on pages {holding}"
    page = pages[holding[0]]
    assert all(signer in page for signer in signers)
    assert page.count("signature") >= len(signers) and page.count("date") >= len(signers)
    assert "J. Smith" in page
