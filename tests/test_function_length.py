"""Functions stay short, or say why not.

Read from the source with ``ast``, without importing anything: a function (or method) of
``robocal_casadi/`` or ``planning/`` longer than ``LIMIT`` lines, counted from its first
decorator or ``def`` to its last line (docstring included), must carry a comment with
``long:`` (``# long: one numeric kernel ...``) in the ``ABOVE`` lines before it or
between its ``def`` and the first statement after its docstring.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("robocal_casadi", "planning")
LIMIT = 60  # [lines] a function longer than this says why
ABOVE = 3  # [lines] before the def (or first decorator) where the reason may stand
MARK = "long:"


def long_functions(source: str, limit: int = LIMIT) -> list[tuple[str, int, int]]:
    """``(name, first line, length)`` of every function in ``source`` over ``limit``
    lines without a ``long:`` comment where the module docstring says."""
    lines = source.splitlines()
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        first = min([node.lineno] + [d.lineno for d in node.decorator_list])
        assert node.end_lineno is not None
        length = node.end_lineno - first + 1
        if length <= limit:
            continue
        body = node.body
        has_docstring = (isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                         and isinstance(body[0].value.value, str))
        opening = body[1] if has_docstring and len(body) > 1 else body[0]
        window = lines[max(first - 1 - ABOVE, 0):opening.lineno - 1]
        if not any(MARK in line and "#" in line for line in window):
            found.append((node.name, first, length))
    return found


def project_files() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def _padded_function(reason: str = "", above: str = "") -> str:
    """A function over ``LIMIT`` lines, with ``reason`` as its first statement line and
    ``above`` on the line before its ``def``."""
    body = [f"    x{i} = {i}" for i in range(LIMIT + 1)]
    head = [above] if above else []
    opening = [f"    {reason}"] if reason else []
    return "\n".join(head + ["def padded():", '    """Many assignments."""', *opening, *body,
                             "    return x0", ""]) + "\n"


def test_the_checker_finds_a_long_function_and_accepts_a_reason():
    assert [name for name, _, _ in long_functions(_padded_function())] == ["padded"]
    assert long_functions(_padded_function(reason="# long: a table of constants")) == []
    assert long_functions(_padded_function(above="# long: a table of constants")) == []
    # a reason further down, or a plain comment, does not count
    late = _padded_function().replace("    x30 = 30", "    # long: too late\n    x30 = 30")
    assert [name for name, _, _ in long_functions(late)] == ["padded"]
    assert [name for name, _, _ in long_functions(_padded_function(reason="# a comment"))] \
        == ["padded"]
    short = "def short():\n    return 1\n"
    assert long_functions(short) == []


def test_every_long_function_says_why():
    offenders = [f"{path.relative_to(ROOT).as_posix()}:{line} {name} ({length} lines)"
                 for path in project_files()
                 for name, line, length in long_functions(path.read_text(encoding="utf-8"))]
    assert not offenders, (f"functions over {LIMIT} lines without a '# {MARK} why' comment:\n"
                           + "\n".join(offenders))
