"""Who the report is for: customer, robot serial, instrument, operator, date and a logo.

The fields come from a ``report:`` block in a dataset file, and command-line options
override them field by field::

    report:
      customer: Acme Gearboxes Ltd
      robot_serial: KR-120-4711
      instrument: Leica AT960 tracker
      operator: J. Smith
      date: 2024-05-14
      logo: acme.png            # PNG, JPEG or SVG, relative to the dataset file

The logo is embedded into the page (a ``data:`` URI), so the report stays one file.
Every field is optional; a field given nowhere is left out of the page.
"""

from __future__ import annotations

import base64
import datetime as _dt
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from ..errors import InputError

FIELDS = ("customer", "robot_serial", "instrument", "operator", "date", "logo")
FIELD_TITLES = {"customer": "customer", "robot_serial": "robot serial number",
                "instrument": "instrument", "operator": "operator", "date": "date of measurement"}
LOGO_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg",
              ".svg": "image/svg+xml"}
LOGO_LIMIT = 2_000_000  # [bytes] largest logo embedded


@dataclass(frozen=True)
class ReportInfo:
    """Fields a customer signs off against; ``logo`` is a file path (None: no logo)."""

    customer: str | None = None
    robot_serial: str | None = None
    instrument: str | None = None
    operator: str | None = None
    date: str | None = None
    logo: Path | None = None

    def facts(self) -> tuple[tuple[str, str], ...]:
        """``(title, value)`` of every text field that is set, in reading order."""
        return tuple((FIELD_TITLES[name], getattr(self, name)) for name in FIELD_TITLES
                     if getattr(self, name))

    def merged(self, other: ReportInfo) -> ReportInfo:
        """This info with every field ``other`` sets taking its place."""
        given = {f.name: getattr(other, f.name) for f in fields(other)
                 if getattr(other, f.name) is not None}
        return replace(self, **given)

    def logo_uri(self) -> str | None:
        """The logo as a ``data:`` URI, or None without a logo."""
        if self.logo is None:
            return None
        kind = LOGO_TYPES[self.logo.suffix.lower()]
        return f"data:{kind};base64," + base64.b64encode(self.logo.read_bytes()).decode("ascii")


def info_from_mapping(content: Any, *, file: str | Path | None = None,
                      where: str = "report", base: Path | None = None) -> ReportInfo:
    """Read a ``report:`` block (``base`` resolves a relative logo path)."""
    if content is None:
        return ReportInfo()
    if not isinstance(content, Mapping):
        raise InputError(f"expected a mapping of {', '.join(FIELDS)}", file=file, where=where)
    unknown = sorted(set(content) - set(FIELDS))
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r}; allowed: {', '.join(FIELDS)}", file=file,
                         where=f"{where}.{unknown[0]}")
    values: dict[str, Any] = {}
    for name in FIELDS[:-1]:
        value = content.get(name)
        if value is None:
            continue
        if isinstance(value, (_dt.date, _dt.datetime)):  # YAML reads 2024-05-14 as a date
            value = value.isoformat()
        if isinstance(value, bool) or not isinstance(value, (str, int, float)) or \
                not str(value).strip():
            raise InputError(f"expected a line of text, got {value!r}", file=file,
                             where=f"{where}.{name}")
        values[name] = str(value).strip()
    if content.get("logo") is not None:
        values["logo"] = check_logo(content["logo"], file=file, where=f"{where}.logo", base=base)
    return ReportInfo(**values)


def check_logo(value: Any, *, file: str | Path | None = None, where: str = "--logo",
               base: Path | None = None) -> Path:
    """The logo's path, checked: an existing PNG, JPEG or SVG file of sensible size."""
    if not isinstance(value, (str, Path)) or not str(value).strip():
        raise InputError(f"expected the path of a PNG, JPEG or SVG file, got {value!r}",
                         file=file, where=where)
    path = Path(value)
    if base is not None and not path.is_absolute():
        path = base / path
    if path.suffix.lower() not in LOGO_TYPES:
        raise InputError(f"{path.name}: expected a .png, .jpg or .svg file", file=file,
                         where=where)
    if not path.is_file():
        raise InputError(f"no such file {path}", file=file, where=where)
    if path.stat().st_size > LOGO_LIMIT:
        raise InputError(f"{path.name} is {path.stat().st_size} bytes; a logo of at most "
                         f"{LOGO_LIMIT} bytes is embedded", file=file, where=where)
    return path


def info_from_dataset_file(path: str | Path) -> ReportInfo:
    """The ``report:`` block of a dataset file (empty info when it has none)."""
    import yaml

    path = Path(path)
    content = yaml.safe_load(path.read_text(encoding="utf-8"))
    block = content.get("report") if isinstance(content, Mapping) else None
    return info_from_mapping(block, file=path, base=path.parent)
