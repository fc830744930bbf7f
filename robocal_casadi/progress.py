"""Progress for long jobs: a single updating line on a terminal, silence when piped."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``with Progress("design", total=200) as bar: bar.update(k)``.

    Writes to standard error only when it is a terminal (or ``force=True``), at most
    ten times a second, and clears its line at the end.
    """

    def __init__(self, label: str, total: int | None = None, *, stream: TextIO | None = None,
                 force: bool = False):
        self.label = label
        self.total = total
        self.stream = stream or sys.stderr
        self.enabled = force or (hasattr(self.stream, "isatty") and self.stream.isatty())
        self._last = 0.0
        self._start = time.perf_counter()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()

    def update(self, done: int, note: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and (self.total is None or done < self.total):
            return
        self._last = now
        count = f"{done}/{self.total}" if self.total else str(done)
        self.stream.write(f"\r\033[K{self.label}: {count} {note} ({now - self._start:.1f} s)")
        self.stream.flush()
