"""What a verb prints, under ``--quiet`` and ``--json`` (not a verb itself).

A verb prints its human summary with ``print`` and records the same facts as fields with
``summarise(args, ...)``. Normally the lines go to standard output. With ``--json`` the
lines are held back and standard output receives one JSON object at the end: ``verb``,
``exit_status``, the recorded fields, ``error`` (the one-line message, when the run was
refused) and ``printed`` (the human lines, for a reader who wants them). With ``--quiet``
nothing is printed but an error's one line on standard error (warnings and progress are
silenced too).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import warnings
from collections.abc import Iterator
from typing import Any, TextIO

from ..common.output import json_safe


class Console:
    """The terminal of one run of ``verb``."""

    def __init__(self, verb: str, *, quiet: bool = False, json: bool = False) -> None:
        self.verb = verb
        self.quiet = quiet
        self.json = json
        self.fields: dict[str, Any] = {}
        self._held = io.StringIO()
        self._stdout: TextIO = sys.stdout
        self._stderr: TextIO = sys.stderr

    @contextlib.contextmanager
    def capture(self) -> Iterator[None]:
        """Route what the verb prints for the chosen mode while the verb runs."""
        self._stdout, self._stderr = sys.stdout, sys.stderr
        with contextlib.ExitStack() as stack:
            if self.quiet or self.json:
                stack.enter_context(contextlib.redirect_stdout(self._held))
            if self.quiet:
                stack.enter_context(contextlib.redirect_stderr(io.StringIO()))
                stack.enter_context(warnings.catch_warnings())
                warnings.simplefilter("ignore")
            yield

    def record(self, **fields: Any) -> None:
        """Facts of the summary, for ``--json``."""
        self.fields.update(fields)

    def error(self, message: str) -> int:
        """Print the one-line error on standard error (in every mode); exit status 2."""
        self.fields["error"] = message
        print(f"robocal {self.verb}: error: {message}", file=self._stderr)
        return 2

    def finish(self, status: int) -> None:
        """Under ``--json``, write the summary object to standard output."""
        if not self.json:
            return
        summary = {"verb": self.verb, "exit_status": status, **self.fields,
                   "printed": self._held.getvalue().splitlines()}
        self._stdout.write(json.dumps(json_safe(summary), default=_plain) + "\n")
        self._stdout.flush()


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, paths and other objects as JSON can hold them."""
    if hasattr(value, "tolist"):
        return json_safe(value.tolist())
    return str(value)


def summarise(args: argparse.Namespace, **fields: Any) -> None:
    """Record summary fields for ``--json`` (nothing when the verb runs without ``main``)."""
    console = getattr(args, "console", None)
    if isinstance(console, Console):
        console.record(**fields)
