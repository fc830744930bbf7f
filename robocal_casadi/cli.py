"""The ``robocal`` command line: one module per verb in ``robocal_casadi.commands``.

Each verb module exposes ``add_arguments(parser)`` and ``run(args) -> int`` and a module
docstring whose first paragraph (one sentence) is the verb's help. Any ``InputError`` (or
other ``RobocalError``), and any file that cannot be read or written (``OSError``), ends
the program with status 2 and one line on standard error.

Every verb takes ``--quiet`` (nothing on standard output, and on standard error nothing
but an error) and ``--json`` (standard output is one JSON object and nothing else: the
verb's summary, see ``commands.console``).

Ctrl-C ends any verb with one line, ``robocal VERB: interrupted; ...``, and status 130,
however early it comes: this module and the package's ``__init__`` import nothing slow
(the verbs' modules, which do, are imported while the handler is in place), the verb is
read from the command line before anything else, and when this module is loaded as the
``robocal`` command an interruption that arrives before ``main`` runs is remembered and
answered by ``main`` first.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading

from . import __version__
from .commands.console import Console
from .common.output import clear_interrupt, interrupted, note_interrupt
from .common.workers import command_started, started_under_a_command
from .errors import RobocalError

VERBS = ("calibrate", "plan", "track", "fk", "simulate", "compensate", "export", "demo",
         "fleet", "prior")
MAX_MESSAGE = 1000  # characters of an error line
INTERRUPTED = 130  # exit status after Ctrl-C (128 + SIGINT, as shells report it)
_EARLY = {"interrupted": False}  # Ctrl-C before ``main`` ran (the command only)


def _remember_early_interrupt(signum, frame) -> None:
    _EARLY["interrupted"] = True


def _loaded_as_the_command() -> bool:
    """Whether this process is the ``robocal`` command (its script, or ``python -m``)."""
    script = sys.argv[0].rsplit("/", 1)[-1].removesuffix(".exe") if sys.argv else ""
    return (script == "robocal" or __name__ == "__main__") and not started_under_a_command() and (
        threading.current_thread() is threading.main_thread())


if _loaded_as_the_command():
    signal.signal(signal.SIGINT, _remember_early_interrupt)


class _Refused(Exception):
    """A command line the parser refuses: ``prog`` and the one-line ``message``."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog
        self.message = message


class _Parser(argparse.ArgumentParser):
    """An argument parser whose refusals are one line, like every other error."""

    def error(self, message: str):
        raise _Refused(self.prog, f"{' '.join(message.split())} (see {self.prog} --help)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="robocal",
        description="Calibrate, diagnose and track industrial robots (robocal_casadi).",
    )
    parser.add_argument("--version", action="version", version=f"robocal {__version__}")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True,
                                  parser_class=_Parser)
    for verb in VERBS:
        try:
            module = importlib.import_module(f"robocal_casadi.commands.{verb}")
        except ModuleNotFoundError as error:
            if error.name != f"robocal_casadi.commands.{verb}":
                raise
            continue  # a verb whose module is not installed is not offered
        doc = (module.__doc__ or "").strip()
        sub = verbs.add_parser(verb, help=summary(doc) or None, description=doc,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(sub)
        add_output_options(sub)
        sub.set_defaults(_module=module, _parser=sub)
    return parser


def summary(doc: str) -> str:
    """A verb's one-sentence help: its docstring's first paragraph on one line (a first
    line alone may stop mid-sentence)."""
    return " ".join(doc.split("\n\n", 1)[0].split())


def add_output_options(parser: argparse.ArgumentParser) -> None:
    """``--quiet`` and ``--json``, the same on every verb."""
    group = parser.add_argument_group("terminal output")
    choice = group.add_mutually_exclusive_group()
    choice.add_argument("--quiet", action="store_true",
                        help="print nothing but an error (on standard error)")
    choice.add_argument("--json", action="store_true",
                        help="print the summary as one JSON object on standard output, and "
                        "nothing else there")


def parse(argv: list[str] | None) -> argparse.Namespace:
    """The arguments; an option the verb does not know is refused in the verb's name
    (``robocal calibrate: error: unrecognized arguments: ...``). A refusal exits with
    status 2 after its one line (and, when ``--json`` was asked for, the JSON object)."""
    words = sys.argv[1:] if argv is None else list(argv)
    try:
        args, unknown = build_parser().parse_known_args(words)
        if unknown:
            args._parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    except _Refused as refused:
        verb = refused.prog.removeprefix("robocal").strip() or None
        console = Console(verb or "robocal", json="--json" in words)
        console.fields["error"] = one_line(refused.message)
        print(f"{refused.prog}: error: {one_line(refused.message)}", file=sys.stderr)
        console.finish(2)
        raise SystemExit(2) from None
    return args


def _on_interrupt(signum, frame) -> None:
    """Ctrl-C: remember it (a library may swallow the exception) and stop."""
    note_interrupt()
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Run one verb; the exit status is 0, 1 (a robot of a fleet failed), 2 (bad input),
    3 (a calibration no better than doing nothing) or 130 (interrupted)."""
    words = sys.argv[1:] if argv is None else list(argv)
    verb = verb_named(words)
    clear_interrupt()
    handler = None
    if threading.current_thread() is threading.main_thread():
        handler = signal.signal(signal.SIGINT, _on_interrupt)
    try:
        if _EARLY["interrupted"]:  # Ctrl-C while the program was still loading
            _EARLY["interrupted"] = False
            raise KeyboardInterrupt
        args = parse(words)
        verb = f"robocal {args.verb}"
        console = Console(args.verb, quiet=args.quiet, json=args.json)
        args.console = console
        with command_started(), console.capture():
            status = _run(args, console)
        if interrupted():  # swallowed by a library, yet the user asked to stop
            raise KeyboardInterrupt
        console.finish(status)
        return status
    except KeyboardInterrupt:
        return _interrupted(verb)
    except BaseException:
        if interrupted():  # e.g. a solver turning the interruption into its own error
            return _interrupted(verb)
        raise
    finally:
        if handler is not None:
            signal.signal(signal.SIGINT, handler)


def verb_named(words: list[str]) -> str:
    """``robocal VERB`` for the verb the command line names (its first word that is not an
    option), else ``robocal``: known before any verb's module is imported."""
    first = next((w for w in words if not w.startswith("-")), None)
    return f"robocal {first}" if first in VERBS else "robocal"


def _interrupted(verb: str) -> int:
    print(f"{verb}: interrupted; no output was left half-written", file=sys.stderr)
    return INTERRUPTED


def _run(args: argparse.Namespace, console: Console) -> int:
    try:
        return int(args._module.run(args) or 0)
    except (RobocalError, OSError) as error:
        if interrupted():  # a failure the interruption caused: say it was interrupted
            raise KeyboardInterrupt from None
        return console.error(_error_line(error))


def _error_line(error: RobocalError | OSError) -> str:
    """What went wrong, on one line. An ``OSError`` is a path that cannot be read or
    written (permissions, a full disk, a name that is too long): the user's to fix."""
    if isinstance(error, RobocalError):
        return one_line(str(error))
    where = f"{one_line(str(error.filename), 300)}: " if error.filename else ""
    return f"{where}{one_line(error.strerror or str(error))}"


def one_line(message: str, limit: int = MAX_MESSAGE) -> str:
    """``message`` on one line, cut in the middle to ``limit`` characters (a value
    quoted from a file may be of any size; the start names the file and key, the end
    says what is wrong)."""
    text = " ".join(message.split())
    if len(text) <= limit:
        return text
    head = (limit * 2) // 3
    return f"{text[:head]} [...] {text[-(limit - head - 7):]}"


if __name__ == "__main__":
    sys.exit(main())
