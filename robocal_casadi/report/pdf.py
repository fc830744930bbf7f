"""The report as a PDF (matplotlib's PdfPages): the same content as the HTML page.

Text and tables flow over A4 text pages in a fixed-width font; each plot follows on its
own page, at its own size, after the text that names it.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

from matplotlib.backends.backend_pdf import PdfPages

from ..output import atomic_file
from .content import Details, Document, Paragraph, Plot, Table
from .figures import new_figure, report_style

PAGE = (8.27, 11.69)  # A4 [in]
MARGIN = 0.6  # [in]
LINE = 0.165  # [in] line height
COLUMNS = 96  # characters per line of fixed-width text


@dataclass(frozen=True)
class _Line:
    text: str
    weight: str = "normal"  # "normal" | "bold"
    size: float = 8.5
    colour: str = "#1d2733"


def write_pdf(document: Document, path: str | Path) -> Path:
    """Write ``document`` to ``path`` as a PDF, whole or not at all."""
    path = Path(path)
    with atomic_file(path) as staging, PdfPages(staging) as pages:
        lines: list[_Line] = [_Line(document.title, "bold", 14.0),
                              *(_Line(t, colour="#5b6570") for t in _wrap(document.subtitle)),
                              _Line("")]
        for section in document.sections:
            lines += [_Line(""), _Line(section.title, "bold", 11.0)]
            blocks = []
            for block in section.blocks:  # folded blocks are printed in full
                blocks += [block] if not isinstance(block, Details) else \
                    [Paragraph(block.summary, "heading"), *block.blocks]
            for block in blocks:
                if isinstance(block, Paragraph) and block.kind == "heading":
                    lines += [_Line(t, "bold", 9.5) for t in _wrap(block.text)]
                elif isinstance(block, Paragraph):
                    lines += [_Line(t, "bold" if block.kind == "conclusion" else "normal")
                              for t in _wrap(block.text)] + [_Line("")]
                elif isinstance(block, Table):
                    lines += _table_lines(block) + [_Line("")]
                elif isinstance(block, Plot):
                    lines += [_Line(t, colour="#5b6570") for t in _wrap(f"Figure: {block.caption}")]
                    _flush(pages, lines)
                    lines = []
                    figure = block.draw()
                    pages.savefig(figure)
            # a section's text stays together with its figures; the next section continues
        _flush(pages, lines)
        info = pages.infodict()
        info["Title"] = document.title
        info["Subject"] = document.subtitle
    path.chmod(0o644)
    return path


def _wrap(text: str, indent: str = "") -> list[str]:
    return textwrap.wrap(text, COLUMNS, subsequent_indent=indent) or [""]


def _table_lines(table: Table) -> list[_Line]:
    widths = [max([len(h)] + [len(r[j]) for r in table.rows]) for j, h in enumerate(table.header)]

    def row_text(cells: tuple[str, ...]) -> str:
        parts = [c.rjust(w) if numeric else c.ljust(w)
                 for c, w, numeric in zip(cells, widths, table.numeric)]
        return "  ".join(parts).rstrip()

    out = [_Line(table.caption, "bold")]
    out += [_Line(t, "bold") for t in _wrap(row_text(table.header), "    ")]
    out.append(_Line("-" * min(COLUMNS, sum(widths) + 2 * (len(widths) - 1))))
    for row, muted in zip(table.rows, table.muted):
        colour = "#8a939c" if muted else "#1d2733"
        out += [_Line(t, colour=colour) for t in _wrap(row_text(row), "    ")]
    return out


def _flush(pages: PdfPages, lines: list[_Line]) -> None:
    """Lay ``lines`` out on as many A4 pages as they need."""
    per_page = int((PAGE[1] - 2 * MARGIN) / LINE)
    while any(line.text for line in lines):
        chunk, lines = lines[:per_page], lines[per_page:]
        with report_style():
            figure = new_figure(PAGE[1], PAGE[0])
            figure.set_layout_engine(None)
            for i, line in enumerate(chunk):
                y = 1.0 - (MARGIN + (i + 1) * LINE) / PAGE[1]
                figure.text(MARGIN / PAGE[0], y, line.text, family="monospace",
                            fontsize=line.size, weight=line.weight, color=line.colour)
        pages.savefig(figure)
