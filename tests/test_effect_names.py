"""Only the effects package names an effect.

Everything else asks the registry (``robocal_casadi.effects``) and the effect's own
declarations, so adding an effect touches its module and one registry line. The check
reads every string literal of the code in ``robocal_casadi/`` and ``planning/`` outside
``robocal_casadi/effects/`` (docstrings excepted: prose may give an example) and looks
for a registered effect's name as a whole word.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from robocal_casadi.effects import EFFECTS, LEARNED

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("robocal_casadi", "planning")
OWNER = ROOT / "robocal_casadi" / "effects"


def _docstrings(tree: ast.AST) -> set[int]:
    """``id`` of every docstring node of ``tree`` (module, class, function)."""
    found: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                found.add(id(first.value))
    return found


def named_effects(source: str, names: list[str]) -> list[tuple[int, str]]:
    """``(line, name)`` of each string literal in ``source`` (f-string parts included,
    docstrings not) holding one of ``names`` as a whole word."""
    pattern = re.compile(r"(?<!\w)(" + "|".join(map(re.escape, names)) + r")(?!\w)")
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in docstrings:
            hits += [(node.lineno, m.group(1)) for m in pattern.finditer(node.value)]
    return sorted(hits)


def test_the_finder_finds_a_planted_name_and_spares_prose_and_longer_words():
    source = ('"""A module about gravity."""\n'
              'def f(x):\n'
              '    """Uses gravity."""\n'
              '    return {"gravity": x, "note": f"with gravity_extra {x}"}\n'
              'MESSAGE = f"too much {1} gravity"\n')
    assert named_effects(source, ["gravity"]) == [(4, "gravity"), (5, "gravity")]
    assert named_effects("X = 'antigravity'\n", ["gravity"]) == []


def test_no_effect_is_named_outside_the_effects_package():
    names = sorted(set(EFFECTS) | set(LEARNED))
    assert names  # the registry is populated on import
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if OWNER in path.parents:
                continue
            found += [f"{path.relative_to(ROOT)}:{line} {name}"
                      for line, name in named_effects(path.read_text(encoding="utf-8"), names)]
    assert not found, "effect names outside robocal_casadi/effects/: " + "; ".join(found)
