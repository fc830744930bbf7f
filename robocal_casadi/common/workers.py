"""Processes started under a command-line run leave Ctrl-C to the command.

The terminal sends Ctrl-C to every process of its group: the command and the worker
processes it started (a fleet's Dask workers). The command answers it (one line, exit
status 130) and closes its workers; a worker that answered too would print a traceback
of its own. ``command_started`` marks the environment with the command's process id;
any other process that imports the package with that mark (a descendant of the
command) ignores Ctrl-C from the start (``ignore_interrupts_in_workers``, run when this
module is imported, which the package does first).
"""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator

MARK = "ROBOCAL_COMMAND_PID"


@contextlib.contextmanager
def command_started() -> Iterator[None]:
    """Mark the environment for the processes this command starts; restore it after."""
    previous = os.environ.get(MARK)
    os.environ[MARK] = str(os.getpid())
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(MARK, None)
        else:
            os.environ[MARK] = previous


def started_under_a_command() -> bool:
    """Whether this process was started by a running command (a worker, not the command)."""
    mark = os.environ.get(MARK)
    return mark is not None and mark != str(os.getpid())


def ignore_interrupts_in_workers() -> None:
    """Ignore Ctrl-C in a process started under a command (not in the command itself)."""
    if started_under_a_command():
        with contextlib.suppress(ValueError):  # not the main thread: nothing to change
            signal.signal(signal.SIGINT, signal.SIG_IGN)


ignore_interrupts_in_workers()
