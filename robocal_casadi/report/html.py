"""The report as one self-contained HTML page, and ``write_report``.

Plots are embedded as base64 PNG ``data:`` URIs, the style sheet and a small script are
inline: the page needs no network and no other file. The script marks ``<body>`` with
``data-images-total``, ``data-images-loaded`` (images with a decoded bitmap),
``data-page-height`` [CSS px] and ``data-report-ready="true"`` once every image has
loaded, so a headless browser can check the page (``report.browser``).
"""

from __future__ import annotations

import base64
import html
from datetime import datetime, timezone
from pathlib import Path

from ..errors import InputError
from ..output import atomic_file
from ..results import CalibrationResult
from .content import Details, Document, Paragraph, Plot, Section, Table
from .figures import png_bytes
from .sections import build_document

CSS = """
:root { --ink: #1d2733; --muted: #8a939c; --line: #d5dbe1; --accent: #1f6fb2;
        --band: #f4f6f8; }
* { box-sizing: border-box; }
body { margin: 0; color: var(--ink); background: #fff; line-height: 1.45;
       font: 15px/1.45 -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
main { max-width: 1100px; margin: 0 auto; padding: 24px 28px 48px; }
header { border-bottom: 3px solid var(--accent); margin-bottom: 12px; }
h1 { font-size: 1.7em; margin: 0 0 4px; }
.subtitle, .stamp { color: var(--muted); margin: 0 0 10px; }
nav { background: var(--band); padding: 8px 12px; border-radius: 4px; margin: 12px 0 8px; }
nav a { color: var(--accent); margin-right: 14px; text-decoration: none; white-space: nowrap; }
section { margin-top: 26px; }
h2 { font-size: 1.3em; border-bottom: 1px solid var(--line); padding-bottom: 4px; }
p.conclusion { font-size: 1.12em; background: #eaf2fa; border-left: 4px solid var(--accent);
               padding: 10px 14px; }
p.note { color: #5b6570; font-size: 0.92em; }
.table-wrap { overflow-x: auto; margin: 12px 0 18px; }
table { border-collapse: collapse; font-size: 0.9em; min-width: 40%; }
caption { text-align: left; font-weight: 600; padding: 4px 0; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 10px; vertical-align: top; }
th { background: var(--band); text-align: left; }
td.number, th.number { text-align: right; font-variant-numeric: tabular-nums; }
td.number { white-space: nowrap; }
table.diagnosis td, table.diagnosis-summary td { white-space: nowrap; }
table.diagnosis, table.diagnosis-summary { font-size: 0.82em; }
tr.muted td { color: var(--muted); font-style: italic; }
figure { margin: 14px 0 22px; }
figure img { display: block; max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { color: #5b6570; font-size: 0.9em; margin-top: 4px; max-width: 880px; }
h3 { font-size: 1.08em; margin: 22px 0 6px; }
details { margin: 8px 0 18px; }
details > summary { cursor: pointer; color: var(--accent); font-weight: 600; padding: 4px 0; }
@media print {
  body { font-size: 11pt; }
  main { max-width: none; padding: 0; }
  nav { display: none; }
  section { break-before: auto; }
  figure, table, p.conclusion { break-inside: avoid; page-break-inside: avoid; }
  table.diagnosis, table.parameters, table.not-identifiable { break-inside: auto;
                                                              page-break-inside: auto; }
  .table-wrap { overflow: visible; }
  table.diagnosis, table.diagnosis-summary { font-size: 7.5pt; }
  table.diagnosis td, table.diagnosis-summary td { white-space: normal; padding: 2px 5px; }
  table.diagnosis th, table.diagnosis-summary th { padding: 2px 5px; }
  h3 { break-after: avoid; page-break-after: avoid; }
  h2 { break-after: avoid; page-break-after: avoid; }
  a { color: inherit; }
  details > summary { color: inherit; }
  details::details-content { content-visibility: visible; display: block; }
  tr { break-inside: avoid; page-break-inside: avoid; }
  thead { display: table-header-group; }
}
@page { size: A4; margin: 16mm 14mm; }
"""

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
                 pdf: bool = False) -> Path:
    """Write the report of ``result`` to ``path`` (one self-contained HTML file).

    With ``pdf=True`` the same content goes to a PDF beside it (``path`` with suffix
    ``.pdf``). Files are written whole or not at all. Returns the HTML path.
    """
    if not isinstance(result, CalibrationResult):
        raise TypeError(f"result: expected a CalibrationResult, got {type(result).__name__}")
    path = Path(path)
    if path.is_dir():
        raise InputError("is a folder; give the report's file name, e.g. report.html",
                         file=path)
    document = build_document(result, title)
    page = render_html(document)
    pdf_path = path.with_suffix(".pdf")
    if pdf:
        from .pdf import write_pdf

        write_pdf(document, pdf_path)
    with atomic_file(path) as staging:
        staging.write_text(page, encoding="utf-8")
        staging.chmod(0o644)  # a report is for reading; the staging file starts private
    return path


def render_html(document: Document) -> str:
    """The page for ``document``: a complete HTML5 string with everything inline."""
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    nav = " ".join(f'<a href="#{_attr(s.anchor)}">{_text(s.title)}</a>' for s in document.sections)
    body = "\n".join(_section(s) for s in document.sections)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_text(document.title)}</title>
<style>{CSS}</style>
</head>
<body>
<main>
<header>
<h1>{_text(document.title)}</h1>
<p class="subtitle">{_text(document.subtitle)}</p>
<p class="stamp">Written {stamp} by robocal_casadi.</p>
</header>
<nav>{nav}</nav>
{body}
</main>
<script>{READY_SCRIPT}</script>
</body>
</html>
"""


# ----------------------------------------------------------------------------- blocks


def _section(section: Section) -> str:
    parts = [f'<section id="{_attr(section.anchor)}">', f"<h2>{_text(section.title)}</h2>"]
    parts += [_block(block) for block in section.blocks]
    parts.append("</section>")
    return "\n".join(parts)


def _block(block) -> str:
    if isinstance(block, Paragraph):
        if block.kind == "heading":
            return f"<h3>{_text(block.text)}</h3>"
        return f'<p class="{_attr(block.kind)}">{_text(block.text)}</p>'
    if isinstance(block, Table):
        return _table(block)
    if isinstance(block, Plot):
        return _figure(block)
    if isinstance(block, Details):
        inner = "\n".join(_block(b) for b in block.blocks)
        return (f'<details id="{_attr(block.name)}"><summary>{_text(block.summary)}</summary>'
                f"\n{inner}\n</details>")
    raise TypeError(f"unknown report block {block!r}")  # pragma: no cover


def _table(table: Table) -> str:
    head = "".join(f'<th{_number_class(n)}>{_text(h)}</th>'
                   for h, n in zip(table.header, table.numeric))
    rows = []
    for row, muted in zip(table.rows, table.muted):
        cells = "".join(f"<td{_number_class(n)}>{_text(c)}</td>"
                        for c, n in zip(row, table.numeric))
        opening = '<tr class="muted">' if muted else "<tr>"
        rows.append(f"{opening}{cells}</tr>")
    return (f'<div class="table-wrap"><table class="{_attr(table.name)}">'
            f"<caption>{_text(table.caption)}</caption><thead><tr>{head}</tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table></div>")


def _figure(plot: Plot) -> str:
    figure = plot.draw()
    width, height = (int(round(v)) for v in figure.get_size_inches() * figure.dpi)
    data = base64.b64encode(png_bytes(figure)).decode("ascii")
    return (f'<figure id="figure-{_attr(plot.name)}"><img src="data:image/png;base64,{data}" '
            f'width="{width}" height="{height}" alt="{_attr(plot.caption)}">'
            f"<figcaption>{_text(plot.caption)}</figcaption></figure>")


def _number_class(numeric: bool) -> str:
    return ' class="number"' if numeric else ""


def _text(value: str) -> str:
    return html.escape(str(value), quote=False)


def _attr(value: str) -> str:
    return html.escape(str(value), quote=True)
