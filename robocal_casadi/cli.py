"""The ``robocal`` command line: one module per verb in ``robocal_casadi.commands``.

Each verb module exposes ``add_arguments(parser)`` and ``run(args) -> int`` and a
module docstring whose first line is the verb's help. Any ``InputError`` (or other
``RobocalError``), and any file that cannot be read or written (``OSError``), ends the
program with status 2 and one line on standard error.

Every verb takes ``--quiet`` (nothing on standard output, and on standard error nothing
but an error) and ``--json`` (standard output is one JSON object and nothing else: the
verb's summary, see ``commands.console``).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .commands.console import Console
from .errors import RobocalError

VERBS = ("calibrate", "plan", "track", "fk", "simulate", "compensate", "export", "demo",
         "fleet")


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
        sub = verbs.add_parser(verb, help=doc.splitlines()[0] if doc else None, description=doc,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(sub)
        add_output_options(sub)
        sub.set_defaults(_module=module, _parser=sub)
    return parser


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
        console.fields["error"] = refused.message
        print(f"{refused.prog}: error: {refused.message}", file=sys.stderr)
        console.finish(2)
        raise SystemExit(2) from None
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    console = Console(args.verb, quiet=args.quiet, json=args.json)
    args.console = console
    with console.capture():
        try:
            status = int(args._module.run(args) or 0)
        except RobocalError as error:
            status = console.error(" ".join(str(error).split()))
        except OSError as error:
            # A path that cannot be read or written (permissions, a full disk, a name that
            # is too long): the user's to fix, so one line, not a traceback.
            where = f"{error.filename}: " if error.filename else ""
            reason = error.strerror or str(error)
            status = console.error(f"{where}{' '.join(reason.split())}")
    console.finish(status)
    return status


if __name__ == "__main__":
    sys.exit(main())
