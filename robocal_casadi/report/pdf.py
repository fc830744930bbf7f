"""The report as a PDF laid out with matplotlib, for machines without Chromium.

With Chromium installed the PDF is the page printed by the browser (``report.html``);
this is the fallback. The same document flows over A4 pages: paragraphs wrap, a table
is drawn whole on one page with its columns measured so no row wraps (only a table
taller than a page continues on the next, its header repeated), and every figure sits
with its caption directly under it on the same page; a sub-heading stays with what
follows it.
"""

from __future__ import annotations

import io
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import matplotlib.image
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from ..common.output import atomic_file
from .content import Details, Document, Paragraph, Plot, Table
from .figures import new_figure, png_bytes, report_style

PAGE = (8.27, 11.69)  # A4 [in]
MARGIN = 0.6  # [in]
WIDTH = PAGE[0] - 2 * MARGIN  # [in] of text
BOTTOM = PAGE[1] - MARGIN - 0.25  # [in] from the top: the footer sits below
INK, MUTED, ACCENT, BAND = "#1d2733", "#8a939c", "#1f6fb2", "#f4f6f8"
TEXT_SIZE = 9.0  # [pt]
CHAR_WIDTH = 0.6  # monospace glyph width / font size
SANS_WIDTH = 0.5  # average sans-serif glyph width / font size
GAP = 0.12  # [in] after a block


@dataclass
class _Flowable:
    """A piece of the page: ``height`` [in] and ``draw(figure, top)`` with ``top`` [in]
    from the page's top edge; ``keep_with_next`` for headings."""

    height: float
    draw: Callable[[Figure, float], None]
    keep_with_next: bool = False


def write_pdf(document: Document, path: str | Path) -> Path:
    """Write ``document`` to ``path`` as a PDF, whole or not at all."""
    path = Path(path)
    flowables = _title_block(document)
    for section in document.sections:
        flowables.append(_text(section.title, 13.0, weight="bold", colour=INK,
                               keep_with_next=True, rule=True,
                               page_break=section.appendix))
        for block in section.blocks:
            flowables += _block(block)
    flowables += _sign_off(document)
    with atomic_file(path) as staging, PdfPages(staging) as pages:
        _paginate(flowables, pages, document.title)
        info = pages.infodict()
        info["Title"] = document.title
        info["Subject"] = document.subtitle
    path.chmod(0o644)
    return path


# ----------------------------------------------------------------------------- blocks


def _block(block) -> list[_Flowable]:
    if isinstance(block, Details):  # folded blocks are printed in full
        out = [_text(block.summary, 10.0, weight="bold", keep_with_next=True)]
        for inner in block.blocks:
            out += _block(inner)
        return out
    if isinstance(block, Paragraph):
        if block.kind == "heading":
            return [_text(block.text, 10.5, weight="bold", keep_with_next=True)]
        if block.kind == "conclusion":
            return [_text(block.text, 10.0, weight="bold", band=True)]
        return [_text(block.text, 8.5 if block.kind == "note" else TEXT_SIZE,
                      colour="#5b6570" if block.kind == "note" else INK)]
    if isinstance(block, Table):
        return _table(block)
    if isinstance(block, Plot):
        return [_figure(block)]
    raise TypeError(f"unknown report block {block!r}")  # pragma: no cover


def _wrap(text: str, size: float, width: float = WIDTH, bold: bool = False) -> list[str]:
    glyph = SANS_WIDTH * (1.12 if bold else 1.0)
    columns = max(20, int(width * 72 / (size * glyph)))
    return textwrap.wrap(text, columns) or [""]


def _text(text: str, size: float, *, weight: str = "normal", colour: str = INK,
          keep_with_next: bool = False, band: bool = False, rule: bool = False,
          page_break: bool = False) -> _Flowable:
    indent = 0.12 if band else 0.0
    lines = _wrap(text, size, WIDTH - 2 * indent, bold=weight == "bold")
    line = size * 1.4 / 72
    pad = 0.08 if band else 0.0
    height = len(lines) * line + 2 * pad + GAP + (0.06 if rule else 0.0)

    def draw(figure: Figure, top: float) -> None:
        if band:
            figure.patches.append(_rectangle(figure, MARGIN, top, WIDTH,
                                             len(lines) * line + 2 * pad, "#eaf2fa"))
            figure.patches.append(_rectangle(figure, MARGIN, top, 0.04,
                                             len(lines) * line + 2 * pad, ACCENT))
        for i, content in enumerate(lines):
            y = top + pad + (i + 0.8) * line
            figure.text(_x(MARGIN + indent), _y(y), content, fontsize=size, weight=weight,
                        color=colour, va="baseline")
        if rule:
            y = top + len(lines) * line + 0.05
            figure.add_artist(_line(figure, MARGIN, y, MARGIN + WIDTH, y, "#d5dbe1"))

    flowable = _Flowable(height, draw, keep_with_next)
    flowable.page_break = page_break  # type: ignore[attr-defined]
    return flowable


def _table(table: Table) -> list[_Flowable]:
    """The table, whole; split by rows (header repeated) only when taller than a page.

    A text cell longer than ``CELL`` characters wraps inside its row (the row grows), and
    narrower still when the table would not otherwise fit the page's width at the
    smallest type; numbers never wrap."""
    table, widths = _fitted(table)
    characters = sum(widths) + 2 * (len(widths) - 1)
    size = max(SMALLEST, min(8.0, WIDTH * 72 / (characters * CHAR_WIDTH)))
    row = size * 1.55 / 72
    caption = _wrap(table.caption, 8.5, bold=True)
    caption_height = len(caption) * 8.5 * 1.4 / 72
    room = BOTTOM - MARGIN - caption_height - 2 * row - GAP
    heights = [_lines(r) * row for r in table.rows]
    chunks: list[list[int]] = [[]]
    used = 0.0
    for i, height in enumerate(heights):
        if chunks[-1] and used + height > room:
            chunks.append([])
            used = 0.0
        chunks[-1].append(i)
        used += height
    out = []
    for k, chunk in enumerate(chunks):
        title = caption if k == 0 else _wrap(f"{table.caption} (continued)", 8.5, bold=True)
        out.append(_Flowable(caption_height + row + sum(heights[i] for i in chunk) + 0.08 + GAP,
                             _table_drawer(table, chunk, widths, size, row, title)))
    return out


CELL = 56  # characters of a text cell before it wraps
NARROWEST = 8  # characters a text cell is narrowed to, at most, to fit the page
SMALLEST = 4.5  # [pt] smallest type of a table
MOST_CHARACTERS = int(WIDTH * 72 / (SMALLEST * CHAR_WIDTH))  # a row's width at that size


def _fitted(table: Table) -> tuple[Table, list[int]]:
    """The table with its text cells wrapped, and each column's width [characters]: at
    ``CELL`` characters, then narrower until the row fits ``MOST_CHARACTERS`` (headers,
    which do not wrap, and numbers set the least)."""
    cell = CELL
    while True:
        wrapped = _wrapped_cells(table, cell)
        widths = [max([len(h)] + [len(line) for r in wrapped.rows for line in r[j].split("\n")])
                  for j, h in enumerate(wrapped.header)]
        if sum(widths) + 2 * (len(widths) - 1) <= MOST_CHARACTERS or cell <= NARROWEST:
            return wrapped, widths
        cell = max(NARROWEST, min(cell, max(widths)) - 4)


def _wrapped_cells(table: Table, cell: int = CELL) -> Table:
    from dataclasses import replace

    rows = tuple(tuple(c if numeric or len(c) <= cell else
                       "\n".join(textwrap.wrap(c, cell, break_long_words=True))
                       for c, numeric in zip(r, table.numeric)) for r in table.rows)
    return replace(table, rows=rows)


def _lines(row: tuple[str, ...]) -> int:
    return max(cell.count("\n") + 1 for cell in row) if row else 1


def _table_drawer(table: Table, chunk: list[int], widths: list[int], size: float, row: float,
                  caption: list[str]):
    char = size * CHAR_WIDTH / 72  # [in]
    total = (sum(widths) + 2 * (len(widths) - 1)) * char

    def cells(figure: Figure, y: float, values, colour: str, weight: str) -> None:
        x = MARGIN
        for value, width, numeric in zip(values, widths, table.numeric):
            if numeric:
                figure.text(_x(x + width * char), _y(y), value, fontsize=size,
                            family="monospace", ha="right", color=colour, weight=weight)
            else:
                figure.text(_x(x), _y(y), value, fontsize=size, family="monospace",
                            color=colour, weight=weight)
            x += (width + 2) * char

    def draw(figure: Figure, top: float) -> None:
        line = 8.5 * 1.4 / 72
        for i, text in enumerate(caption):
            figure.text(_x(MARGIN), _y(top + (i + 0.8) * line), text, fontsize=8.5,
                        weight="bold", color=INK)
        y = top + len(caption) * line
        figure.patches.append(_rectangle(figure, MARGIN - 0.04, y, total + 0.08, row, BAND))
        cells(figure, y + 0.72 * row, table.header, INK, "bold")
        y += row
        for i in chunk:
            height = _lines(table.rows[i]) * row
            for k in range(_lines(table.rows[i])):
                parts = [(c.split("\n") + [""] * 99)[k] for c in table.rows[i]]
                cells(figure, y + (k + 0.72) * row, parts, MUTED if table.muted[i] else INK,
                      "normal")
            figure.add_artist(_line(figure, MARGIN - 0.04, y + height, MARGIN + total + 0.04,
                                    y + height, "#d5dbe1"))
            y += height

    return draw


def _figure(plot: Plot) -> _Flowable:
    """The figure at its own proportions, as wide as it was drawn (at most the text
    width), its caption right under it; both on one page."""
    figure = plot.draw()
    width, height = figure.get_size_inches()
    image = matplotlib.image.imread(io.BytesIO(png_bytes(figure)), format="png")
    caption = _wrap(plot.caption, 8.0)
    caption_height = len(caption) * 8.0 * 1.4 / 72
    scale = min(1.0, WIDTH / width, (BOTTOM - MARGIN - caption_height - 0.3) / height)
    width, height = width * scale, height * scale

    def draw(page: Figure, top: float) -> None:
        left = MARGIN + (WIDTH - width) / 2
        axes = page.add_axes((_x(left), _y(top + height), width / PAGE[0], height / PAGE[1]))
        axes.imshow(image, interpolation="antialiased")
        axes.set_axis_off()
        for i, text in enumerate(caption):
            page.text(_x(MARGIN), _y(top + height + 0.05 + (i + 0.8) * 8.0 * 1.4 / 72), text,
                      fontsize=8.0, color="#5b6570", style="italic")

    return _Flowable(height + 0.05 + caption_height + GAP, draw)


def _title_block(document: Document) -> list[_Flowable]:
    out = [_text(document.title, 16.0, weight="bold"),
           _text(document.subtitle, 9.0, colour="#5b6570")]
    if document.facts:
        out += _table(Table("facts", "Report", ("item", "value"), document.facts))
    if document.units_note:
        out.append(_text(document.units_note, 8.5, colour="#5b6570"))
    return out


# ----------------------------------------------------------------------------- pages


def _paginate(flowables: list[_Flowable], pages: PdfPages, title: str) -> None:
    """Lay the flowables out over pages, each with ``title``, page k of n at its foot."""
    layout = _pages(flowables)
    for number, placed in enumerate(layout, start=1):
        with report_style():
            figure = new_figure(PAGE[1], PAGE[0])
        figure.set_layout_engine(None)
        for i, top in placed:
            flowables[i].draw(figure, top)
        figure.text(0.5, _y(PAGE[1] - MARGIN / 2), f"{title}   page {number} of {len(layout)}",
                    ha="center", fontsize=7.5, color=MUTED)
        pages.savefig(figure)


def _pages(flowables: list[_Flowable]) -> list[list[tuple[int, float]]]:
    """Per page, ``(flowable index, top [in])`` of what it holds: a flowable goes on the
    next page when it does not fit (a heading with the start of what follows) or asks
    for a page of its own."""
    out: list[list[tuple[int, float]]] = []
    top = BOTTOM
    for i, item in enumerate(flowables):
        needed = item.height
        if item.keep_with_next and i + 1 < len(flowables):
            needed += min(flowables[i + 1].height, BOTTOM - MARGIN - item.height)
        if not out or top + needed > BOTTOM or getattr(item, "page_break", False):
            out.append([])
            top = MARGIN
        out[-1].append((i, top))
        top += item.height
    return out


def _sign_off(document: Document) -> list[_Flowable]:
    """The signature blocks, each kept whole: what is attested, then name (and
    organisation) when known and lines for role, date and signature."""
    if not document.sign_off:
        return []
    out = [_text("Sign-off", 13.0, weight="bold", keep_with_next=True, rule=True)]
    blank = "_" * 44
    for signer in document.sign_off:
        fields = [("name", signer.name or blank)]
        if signer.organisation:
            fields.append(("for", signer.organisation))
        fields += [("role", blank), ("date", blank), ("signature", blank)]
        lines = [_text(signer.title, 10.0, weight="bold")]
        lines += [_text(f"{label}:  {value}", TEXT_SIZE) for label, value in fields]
        out.append(_together(lines))
    return out


def _together(parts: list[_Flowable]) -> _Flowable:
    """One flowable of ``parts`` one under the other: never split over two pages."""
    def draw(figure: Figure, top: float) -> None:
        for part in parts:
            part.draw(figure, top)
            top += part.height

    return _Flowable(sum(part.height for part in parts), draw)


def _x(inches: float) -> float:
    return inches / PAGE[0]


def _y(inches_from_top: float) -> float:
    return 1.0 - inches_from_top / PAGE[1]


def _rectangle(figure: Figure, left: float, top: float, width: float, height: float,
               colour: str):
    from matplotlib.patches import Rectangle

    return Rectangle((_x(left), _y(top + height)), width / PAGE[0], height / PAGE[1],
                     transform=figure.transFigure, facecolor=colour, edgecolor="none",
                     zorder=-1)


def _line(figure: Figure, x0: float, y0: float, x1: float, y1: float, colour: str):
    from matplotlib.lines import Line2D

    return Line2D([_x(x0), _x(x1)], [_y(y0), _y(y1)], transform=figure.transFigure,
                  color=colour, linewidth=0.5)
