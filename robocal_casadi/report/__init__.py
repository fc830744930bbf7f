"""The calibration report a customer reads: one self-contained HTML page (and a PDF).

``write_report(result, "report.html", pdf=True)`` writes the page, and ``report.pdf``
beside it; ``screenshot_report(html, png)`` takes a picture of it in headless Chromium.

Modules: ``content`` (the document model), ``numbers`` (statistics and formatting in
the robot file's units), ``figures`` (matplotlib plots), ``conclusion`` (the plain-
language summary), ``sections`` (what the report says), ``html`` and ``pdf`` (the two
renderers), ``browser`` (Chromium).
"""

from .browser import BrowserError, find_chromium, page_state, print_pdf, screenshot_report
from .html import render_html, write_report
from .sections import build_document

__all__ = ["BrowserError", "build_document", "find_chromium", "page_state", "print_pdf",
           "render_html", "screenshot_report", "write_report"]
