"""One root exception for everything the toolkit refuses.

``InputError`` carries where the problem is (file, row or key) and what is wrong, and
formats itself as the one line the command line prints before exiting with status 2.
"""

from __future__ import annotations

from pathlib import Path


class RobocalError(Exception):
    """Root of every error raised on purpose by robocal_casadi."""


class InputError(RobocalError):
    """A file or argument that cannot be used as given.

    The message reads ``<file>: <where>: <what>``, e.g.
    ``robot.yaml: joints[2].d: expected a number, got 'abc'``.
    """

    def __init__(self, what: str, *, file: str | Path | None = None, where: str | None = None):
        self.file = str(file) if file is not None else None
        self.where = where
        self.what = what
        parts = [p for p in (self.file, where, what) if p]
        super().__init__(": ".join(parts))


class SolverError(RobocalError):
    """A numerical solve that did not reach a usable answer (carries the solver's statistics)."""

    def __init__(self, message: str, *, stats: dict | None = None):
        self.stats = dict(stats or {})
        super().__init__(message)


class ArgumentError(InputError, ValueError):
    """A function argument that cannot be used as given (a ``ValueError`` as well, so
    callers used to scipy's front-door checks can catch it as one).

    The message names the argument, says what was expected and what was given, e.g.
    ``loss: unknown name 'hubr'; expected one of 'linear', 'huber' (did you mean 'huber'?)``.
    """

    def __init__(self, what: str, *, argument: str):
        self.argument = argument
        super().__init__(what, where=argument)
