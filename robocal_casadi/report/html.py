"""The report as one self-contained HTML page, and ``write_report``.

The page is built from Jinja2 templates (``templates/``), which an integrator may
replace one by one to brand the report. Plots are embedded as base64 PNG ``data:`` URIs,
the style sheet and a small script are inline: the page needs no network and no other
file. The script marks ``<body>`` with
``data-images-total``, ``data-images-loaded`` (images with a decoded bitmap),
``data-page-height`` [CSS px], ``data-tables-clipped`` (the tables wider than the space
they are given, which a reader would have to scroll sideways; empty when none),
``data-sign-off-bottom`` [CSS px] and ``data-report-ready="true"`` once every image has
loaded, so a headless browser can check the page (``report.browser``).
"""

from __future__ import annotations

import base64
from datetime import UTC, datetime
from pathlib import Path

import jinja2
from markupsafe import Markup

from ..common.output import atomic_file
from ..errors import ArgumentError, InputError
from ..results import CalibrationResult
from .content import Details, Document, Paragraph, Plot, Table
from .figures import png_bytes
from .info import ReportInfo
from .sections import build_document

READY_SCRIPT = """
(function () {
  function check() {
    var images = document.images, loaded = 0;
    for (var i = 0; i < images.length; i++) {
      if (images[i].complete && images[i].naturalWidth > 0) { loaded++; }
    }
    var body = document.body;
    body.setAttribute("data-images-total", String(images.length));
    body.setAttribute("data-images-loaded", String(loaded));
    body.setAttribute("data-page-height",
                      String(Math.ceil(document.documentElement.scrollHeight)));
    // tables wider than the space they are given (clipped on screen: scrolled sideways),
    // folded ones unfolded for the measurement and folded again
    var folded = document.querySelectorAll("details:not([open])");
    for (var f = 0; f < folded.length; f++) { folded[f].open = true; }
    var wraps = document.querySelectorAll(".table-wrap"), clipped = [];
    for (var k = 0; k < wraps.length; k++) {
      if (wraps[k].scrollWidth > wraps[k].clientWidth + 1) {
        var table = wraps[k].querySelector("table");
        clipped.push(table ? table.className || "table" : "table");
      }
    }
    for (f = 0; f < folded.length; f++) { folded[f].open = false; }
    body.setAttribute("data-tables-clipped", clipped.join(" "));
    var signOff = document.getElementById("sign-off");
    if (signOff) {
      body.setAttribute("data-sign-off-bottom", String(Math.ceil(
        signOff.getBoundingClientRect().bottom + window.scrollY)));
    }
    if (loaded === images.length) { body.setAttribute("data-report-ready", "true"); }
  }
  window.addEventListener("load", check);
  // folded blocks print in full: open them for printing, fold them again after
  var opened = [];
  window.addEventListener("beforeprint", function () {
    var folded = document.querySelectorAll("details:not([open])");
    for (var i = 0; i < folded.length; i++) { folded[i].open = true; opened.push(folded[i]); }
  });
  window.addEventListener("afterprint", function () {
    while (opened.length) { opened.pop().open = false; }
  });
})();
"""


def write_report(result: CalibrationResult, path: str | Path, *, title: str | None = None,
                 pdf: bool = False, info: ReportInfo | None = None,
                 templates: str | Path | None = None, printer: str = "auto") -> Path:
    """Write the report of ``result`` to ``path`` (one self-contained HTML file).

    ``info`` carries the customer's fields and logo; ``templates`` is a folder whose
    ``report.html.j2``, ``blocks.html.j2``, ``brand.html.j2`` or ``report.css`` replace
    the package's own (see ``templates/report.html.j2``). With ``pdf=True`` the page is
    also printed to a PDF beside it (``path`` with suffix ``.pdf``): by headless Chromium
    when it is installed (``printer="auto"`` or ``"chromium"``), else laid out with
    matplotlib (``printer="matplotlib"``). Files are written whole or not at all.
    Returns the HTML path.
    """
    if not isinstance(result, CalibrationResult):
        raise TypeError(f"result: expected a CalibrationResult, got {type(result).__name__}")
    if printer not in PRINTERS:
        raise ValueError(f"printer: expected one of {', '.join(PRINTERS)}, got {printer!r}")
    path = Path(path)
    if path.is_dir():
        raise InputError("is a folder; give the report's file name, e.g. report.html",
                         file=path)
    environment = template_environment(templates)
    document = build_document(result, title, info)
    page = render_html(document, environment)
    pdf_path = path.with_suffix(".pdf")
    with atomic_file(path) as staging:
        staging.write_text(page, encoding="utf-8")
        staging.chmod(0o644)  # a report is for reading; the staging file starts private
        if pdf:
            _print(document, staging, pdf_path, printer)
    return path


PRINTERS = ("auto", "chromium", "matplotlib")


def _print(document: Document, page: Path, pdf_path: Path, printer: str) -> None:
    """The PDF of the page: Chromium prints the HTML as a browser would; without it, the
    matplotlib layout of the same document."""
    from .browser import find_chromium, print_pdf

    if printer == "chromium" or (printer == "auto" and find_chromium() is not None):
        staged = page.with_name(f".{pdf_path.stem}-print.html")  # Chromium wants .html
        try:
            staged.write_bytes(page.read_bytes())
            print_pdf(staged, pdf_path)
        finally:
            staged.unlink(missing_ok=True)
        return
    from .pdf import write_pdf

    write_pdf(document, pdf_path)


def template_environment(templates: str | Path | None = None) -> jinja2.Environment:
    """Jinja2 environment over the package's templates, ``templates`` searched first."""
    loaders: list[jinja2.BaseLoader] = []
    if templates is not None:
        folder = Path(templates)
        if not folder.is_dir():
            raise InputError("is not a folder of report templates", file=folder)
        loaders.append(jinja2.FileSystemLoader(str(folder)))
    loaders.append(jinja2.FileSystemLoader(str(TEMPLATES)))
    return jinja2.Environment(loader=jinja2.ChoiceLoader(loaders), autoescape=True,
                              undefined=jinja2.StrictUndefined, keep_trailing_newline=True)


def render_html(document: Document, environment: jinja2.Environment | None = None) -> str:
    """The page for ``document``: a complete HTML5 string with everything inline."""
    environment = environment or template_environment()
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    if environment.loader is None:
        raise ArgumentError("the template environment has no loader to read report.css from",
                            argument="environment")
    css = environment.loader.get_source(environment, "report.css")[0]
    sections = [{"anchor": s.anchor, "title": s.title, "appendix": s.appendix,
                 "blocks": [_view(b) for b in s.blocks]} for s in document.sections]
    return environment.get_template("report.html.j2").render(
        document=document, sections=sections, css=Markup(css),
        script=Markup(READY_SCRIPT), stamp=stamp)


TEMPLATES = Path(__file__).with_name("templates")


# ----------------------------------------------------------------------------- blocks


def _view(block) -> dict:
    """What the templates need of one block: its fields, and a figure drawn to a PNG."""
    if isinstance(block, Paragraph):
        return {"type": "paragraph", "kind": block.kind, "text": block.text}
    if isinstance(block, Table):
        return {"type": "table", "name": block.name, "caption": block.caption,
                "header": block.header, "rows": block.rows, "muted": block.muted,
                "numeric": block.numeric, "columns": block.columns,
                "under": [block.under(i) for i in range(len(block.rows))]}
    if isinstance(block, Plot):
        figure = block.draw()
        width, height = (int(round(v)) for v in figure.get_size_inches() * figure.dpi)
        data = base64.b64encode(png_bytes(figure)).decode("ascii")
        return {"type": "figure", "name": block.name, "caption": block.caption,
                "uri": f"data:image/png;base64,{data}", "width": width, "height": height}
    if isinstance(block, Details):
        return {"type": "details", "name": block.name, "summary": block.summary,
                "blocks": [_view(b) for b in block.blocks]}
    raise TypeError(f"unknown report block {block!r}")  # pragma: no cover
