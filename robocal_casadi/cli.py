"""The ``robocal`` command line: one module per verb in ``robocal_casadi.commands``.

Each verb module exposes ``add_arguments(parser)`` and ``run(args) -> int`` and a
module docstring whose first line is the verb's help. Any ``InputError`` (or other
``RobocalError``), and any file that cannot be read or written (``OSError``), ends the
program with status 2 and one line on standard error.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .errors import RobocalError

VERBS = ("calibrate", "plan", "track", "fk", "simulate", "compensate", "export", "demo",
         "fleet")
MAX_MESSAGE = 1000  # characters of an error line


class _Parser(argparse.ArgumentParser):
    """An argument parser whose refusals are one line, like every other error."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} "
                     f"(see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="robocal",
        description="Calibrate, diagnose and track industrial robots (robocal_casadi).",
    )
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
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
        sub.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._module.run(args) or 0)
    except RobocalError as error:
        print(f"robocal {args.verb}: error: {one_line(str(error))}", file=sys.stderr)
        return 2
    except OSError as error:
        # A path that cannot be read or written (permissions, a full disk, a name that
        # is too long): the user's to fix, so one line, not a traceback.
        where = f"{one_line(str(error.filename), 300)}: " if error.filename else ""
        reason = error.strerror or str(error)
        print(f"robocal {args.verb}: error: {where}{one_line(reason)}", file=sys.stderr)
        return 2


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
