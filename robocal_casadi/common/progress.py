"""Progress for long jobs: a single updating line on a terminal, silence when piped.

``Progress`` counts done items of a known total; ``Stages`` names the stage a job is in
and how long it has been running.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TextIO, TypeVar


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


TICK = 0.5  # [s] how often a running stage's elapsed time is refreshed
KEEP_AFTER = 2.0  # [s] a top-level stage that took longer leaves a line with its time


class Stages:
    """The stages of a long job on one terminal line: ``with stages.stage("diagnosis"):``.

    While a stage runs, standard error shows the open stages' names (outermost first)
    and the innermost one's elapsed time, refreshed every ``TICK`` seconds by a
    background thread, so a stage spent inside one long computation still shows it is
    alive. A top-level stage that took longer than ``KEEP_AFTER`` seconds leaves a line
    with its name and time. Silent unless ``enabled`` and the stream is a terminal
    (``force=True`` skips the terminal check).
    """

    def __init__(self, enabled: bool = True, *, stream: TextIO | None = None,
                 force: bool = False):
        self.stream = stream or sys.stderr
        terminal = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.enabled = bool(enabled) and (force or terminal)
        self._open: list[tuple[str, float]] = []
        self._note = ""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Show ``name`` with its elapsed time while the block runs."""
        if not self.enabled:
            yield
            return
        with self._lock:
            self._open.append((name, time.perf_counter()))
            self._note = ""
            self._draw()
        if self._ticker is None:
            self._stop.clear()
            self._ticker = threading.Thread(target=self._tick, name="robocal-progress",
                                            daemon=True)
            self._ticker.start()
        try:
            yield
        finally:
            self._close()

    def note(self, text: str) -> None:
        """A short note after the innermost stage (e.g. ``3/40``), shown until it ends."""
        if self.enabled and self._open:
            with self._lock:
                self._note = text
                self._draw()

    def _close(self) -> None:
        with self._lock:
            name, start = self._open.pop()
            self._note = ""
            elapsed = time.perf_counter() - start
            if not self._open and elapsed > KEEP_AFTER:
                self.stream.write(f"\r\033[K{name}: {elapsed:.1f} s\n")
            self._draw()
            last = not self._open
        if last and self._ticker is not None:
            self._stop.set()
            self._ticker.join()
            self._ticker = None

    def _draw(self) -> None:
        """Rewrite the line (the caller holds the lock)."""
        if not self._open:
            self.stream.write("\r\033[K")
        else:
            names = " > ".join(name for name, _ in self._open)
            elapsed = time.perf_counter() - self._open[-1][1]
            note = f" {self._note}" if self._note else ""
            self.stream.write(f"\r\033[K{names}{note} ({elapsed:.1f} s)")
        self.stream.flush()

    def _tick(self) -> None:
        while not self._stop.wait(TICK):
            with self._lock:
                if self._open:
                    self._draw()


_active: contextvars.ContextVar[Stages | None] = contextvars.ContextVar("robocal_stages",
                                                                        default=None)


def stage(name: str) -> contextlib.AbstractContextManager:
    """The named stage of the job in progress (see ``reports_stages``); a no-op outside one."""
    stages = _active.get()
    return contextlib.nullcontext() if stages is None else stages.stage(name)


def note(text: str) -> None:
    """A short note after the innermost stage of the job in progress (e.g. ``3/40``)."""
    stages = _active.get()
    if stages is not None:
        stages.note(text)


F = TypeVar("F", bound=Callable[..., Any])


def reports_stages(default: bool) -> Callable[[F], F]:
    """Decorate a job whose keyword ``progress`` (default ``default``) switches the
    terminal progress of the stages it runs (``stage``). Called inside another such job,
    it reports on that job's line (silenced altogether by ``progress=False``)."""
    def decorate(function: F) -> F:
        @functools.wraps(function)
        def job(*args, progress: bool = default, **kwargs):
            outer = _active.get()
            stages = outer if outer is not None and progress else Stages(progress)
            token = _active.set(stages)
            try:
                return function(*args, progress=progress, **kwargs)
            finally:
                _active.reset(token)
        return job  # type: ignore[return-value]
    return decorate
