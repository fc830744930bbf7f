"""Looking at a report in headless Chromium: the loaded page's state and a screenshot.

Chromium runs offline (no background networking, no component updates, a throw-away
profile). ``page_state`` reads the ``data-*`` marks the report's script puts on
``<body>`` once the page has loaded (see ``report.html``); ``screenshot_report`` takes a
PNG of the whole page, as tall as the page says it is; ``print_pdf`` prints it to PDF as
a reader's browser would (print style sheet, A4).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from ..common.output import atomic_file
from ..errors import RobocalError

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars", "--mute-audio")
VIRTUAL_TIME_BUDGET = 5000  # [ms] of page time before the DOM is read
TIMEOUT = 120.0  # [s] wall clock for one browser run
WIDTH = 1280  # [CSS px] window width of a screenshot and of a loaded page
WINDOW_HEIGHT = 900  # [CSS px] window height a page is loaded in
MAX_HEIGHT = 30000  # [CSS px] tallest screenshot taken


class BrowserError(RobocalError):
    """Chromium is missing, failed or produced nothing usable."""


def find_chromium() -> str | None:
    """Path of a Chromium executable: ``$CHROMIUM`` if set, ``/usr/bin/chromium``, then PATH."""
    preferred = os.environ.get("CHROMIUM")
    if preferred and shutil.which(preferred):
        return shutil.which(preferred)
    if os.access("/usr/bin/chromium", os.X_OK):
        return "/usr/bin/chromium"
    for name in CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


def _run(arguments: list[str], chromium: str | None) -> subprocess.CompletedProcess:
    executable = chromium or find_chromium()
    if executable is None:
        raise BrowserError("Chromium not found: install it (apt-get install chromium) or set "
                           "CHROMIUM to its path")
    with tempfile.TemporaryDirectory(prefix="robocal-chromium-") as profile:
        command = [executable, *FLAGS, f"--user-data-dir={profile}", *arguments]
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT,
                                  check=False, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired as error:
            raise BrowserError(f"Chromium took longer than {TIMEOUT:.0f} s: "
                               f"{' '.join(command)}") from error
    if done.returncode != 0:
        raise BrowserError(f"Chromium exited with status {done.returncode}: "
                           f"{done.stderr.strip()[-600:]}")
    return done


def dump_dom(html_path: str | Path, *, width: int = WIDTH, chromium: str | None = None) -> str:
    """The page's DOM after loading ``html_path`` in a window ``width`` CSS px wide and
    letting its scripts run."""
    url = Path(html_path).resolve().as_uri()
    done = _run([f"--window-size={int(width)},{WINDOW_HEIGHT}",
                 f"--virtual-time-budget={VIRTUAL_TIME_BUDGET}", "--dump-dom", url], chromium)
    if "<body" not in done.stdout:
        raise BrowserError(f"Chromium returned no page for {html_path}")
    return done.stdout


def page_state(html_path: str | Path, *, width: int = WIDTH,
               chromium: str | None = None) -> dict[str, str]:
    """The ``data-*`` attributes on ``<body>`` of the report loaded ``width`` CSS px wide
    (names without ``data-``)."""
    dom = dump_dom(html_path, width=width, chromium=chromium)
    body = re.search(r"<body([^>]*)>", dom)
    if body is None:
        raise BrowserError(f"no <body> in the page Chromium loaded from {html_path}")
    return dict(re.findall(r'data-([\w-]+)="([^"]*)"', body.group(1)))


def screenshot_report(html_path: str | Path, png_path: str | Path, *, width: int = WIDTH,
                      height: int | None = None, chromium: str | None = None) -> Path:
    """A PNG screenshot of the report at ``html_path``, ``width`` CSS px wide.

    ``height`` defaults to the page's full height as the loaded page reports it (capped
    at ``MAX_HEIGHT``). The PNG is written whole or not at all. Raises ``BrowserError``
    when Chromium is missing or fails.
    """
    html_path, png_path = Path(html_path), Path(png_path)
    if height is None:
        state = page_state(html_path, width=width, chromium=chromium)
        height = int(state.get("page-height", "2000") or 2000)
    height = max(200, min(int(height), MAX_HEIGHT))
    url = html_path.resolve().as_uri()
    with tempfile.TemporaryDirectory(prefix="robocal-screenshot-") as folder:
        shot = Path(folder) / "screenshot.png"  # Chromium picks the format from the suffix
        _run([f"--window-size={int(width)},{height}",
              f"--virtual-time-budget={VIRTUAL_TIME_BUDGET}", f"--screenshot={shot}", url],
             chromium)
        if not shot.is_file() or shot.stat().st_size == 0:
            raise BrowserError(f"Chromium wrote no screenshot of {html_path}")
        with atomic_file(png_path) as staging:
            shutil.copyfile(shot, staging)
            staging.chmod(0o644)
    return png_path


def print_pdf(html_path: str | Path, pdf_path: str | Path, *,
              chromium: str | None = None) -> Path:
    """The report at ``html_path`` printed by Chromium to ``pdf_path`` (print media, the
    page's ``@page`` size, no header or footer), written whole or not at all."""
    html_path, pdf_path = Path(html_path), Path(pdf_path)
    url = html_path.resolve().as_uri()
    with tempfile.TemporaryDirectory(prefix="robocal-print-") as folder:
        printed = Path(folder) / "printed.pdf"
        _run([f"--virtual-time-budget={VIRTUAL_TIME_BUDGET}", "--no-pdf-header-footer",
              f"--print-to-pdf={printed}", url], chromium)
        if not printed.is_file() or not printed.read_bytes().startswith(b"%PDF"):
            raise BrowserError(f"Chromium printed no PDF of {html_path}")
        with atomic_file(pdf_path) as staging:
            shutil.copyfile(printed, staging)
            staging.chmod(0o644)
    return pdf_path
