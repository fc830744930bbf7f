"""The report as a document: sections of paragraphs, tables and figures.

The content is built once from a ``CalibrationResult`` (``report.sections``) and drawn
by two renderers: ``report.html`` (one self-contained page) and ``report.pdf``
(matplotlib's PdfPages). Text is plain; the renderers escape it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from matplotlib.figure import Figure


@dataclass(frozen=True)
class Paragraph:
    """Plain text; ``kind`` is ``"text"``, ``"note"`` (muted), ``"conclusion"`` (stands out)
    or ``"heading"`` (a sub-heading within a section)."""

    text: str
    kind: str = "text"


@dataclass(frozen=True)
class Table:
    """A table of display strings. ``muted[i]`` greys row i (e.g. a parameter held at nominal).

    ``name`` becomes the HTML class, so tests and styles can find the table.
    ``numeric[j]`` right-aligns column j. ``below[j]`` sets column j's text under its row,
    across the table's width, headed by its title: a long text (a decision, an estimate)
    reads as a sentence there, and the table keeps to the width of a page.
    """

    name: str
    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    muted: tuple[bool, ...] = ()
    numeric: tuple[bool, ...] = ()
    below: tuple[bool, ...] = ()

    def __post_init__(self):
        for i, row in enumerate(self.rows):
            if len(row) != len(self.header):
                raise ValueError(f"table {self.name!r} row {i} has {len(row)} cells, "
                                 f"header has {len(self.header)}")
        if not self.muted:
            object.__setattr__(self, "muted", (False,) * len(self.rows))
        if not self.numeric:
            object.__setattr__(self, "numeric", (False,) * len(self.header))
        if not self.below:
            object.__setattr__(self, "below", (False,) * len(self.header))

    @property
    def columns(self) -> tuple[int, ...]:
        """The columns set side by side (those not set under their row)."""
        return tuple(j for j, under in enumerate(self.below) if not under)

    def under(self, row: int) -> tuple[tuple[str, str], ...]:
        """``(title, text)`` of row ``row``'s columns set under it, empty texts left out."""
        return tuple((self.header[j], self.rows[row][j]) for j, under in enumerate(self.below)
                     if under and self.rows[row][j] not in ("", "-"))

    def __repr__(self) -> str:
        return f"Table({self.name!r}, {len(self.rows)} rows x {len(self.header)} columns)"


@dataclass(frozen=True)
class Plot:
    """A figure with its caption; ``draw`` builds a fresh matplotlib ``Figure`` each call."""

    name: str
    caption: str
    draw: Callable[[], Figure]

    def __repr__(self) -> str:
        return f"Plot({self.name!r})"


@dataclass(frozen=True)
class Details:
    """Blocks folded away on screen behind a ``summary`` line (HTML ``<details>``), and
    always shown in print and in the PDF: e.g. a long table of secondary rows."""

    name: str
    summary: str
    blocks: tuple[Paragraph | Table | Plot, ...]

    def __repr__(self) -> str:
        return f"Details({self.name!r}, {len(self.blocks)} blocks)"


Block = Paragraph | Table | Plot | Details


@dataclass(frozen=True)
class Section:
    """One titled part of the report; ``anchor`` is its HTML id."""

    anchor: str
    title: str
    blocks: tuple[Block, ...]
    appendix: bool = False  # reference material after the main text (solver details)

    def __repr__(self) -> str:
        return f"Section({self.anchor!r}, {len(self.blocks)} blocks)"


@dataclass(frozen=True)
class SignOff:
    """One signature on the report: what the signer attests (``title``), and the name and
    organisation when known (empty: a line to fill in by hand); role, date and signature
    are always left to the signer."""

    title: str
    name: str = ""
    organisation: str = ""


@dataclass(frozen=True)
class Document:
    """The whole report: a title, a one-line subtitle and its sections in order."""

    title: str
    subtitle: str
    sections: tuple[Section, ...]
    facts: tuple[tuple[str, str], ...] = ()  # the customer's fields: (title, value)
    logo: str | None = None  # a data: URI
    units_note: str = ""  # the report's units and the file's, in words
    sign_off: tuple[SignOff, ...] = ()  # signature blocks at the end

    def __repr__(self) -> str:
        return f"Document({self.title!r}, sections={[s.anchor for s in self.sections]})"
