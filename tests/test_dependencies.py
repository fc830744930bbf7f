"""Every package the code imports is one the installation brings.

The imports are read from the source with ``ast`` (nothing is imported), and compared with
``pyproject.toml``: a module of the core must only import the standard library, the
project itself and the core dependencies; the optional fleet engine (Dask, psutil) may only
be imported inside a function that turns its absence into a one-line message.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

from test_import_graph import PACKAGES, ROOT, imported_names

# The name a distribution is imported by, where the two differ.
IMPORT_NAMES = {"pin": "pinocchio", "pyyaml": "yaml", "jinja2": "jinja2",
                "dask[distributed]": "dask"}
# Imported through a declared distribution that requires it.
BROUGHT_BY = {"markupsafe": "jinja2", "distributed": "dask"}


def _distribution(requirement: str) -> str:
    name = re.split(r"[<>=!~; ]", requirement, maxsplit=1)[0].strip().lower()
    return IMPORT_NAMES.get(name, name)


def _declared() -> tuple[set[str], set[str]]:
    """The core dependencies, and those of the optional run-time extras (the ``test``
    extra's tools are not for running the program)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = {_distribution(r) for r in project["dependencies"]}
    optional = {_distribution(r) for k, v in project.get("optional-dependencies", {}).items()
                if k != "test" for r in v}
    return core, optional - core


def _third_party_imports() -> dict[str, list[tuple[Path, ast.AST]]]:
    """Top-level name of every import outside the standard library and the project."""
    found: dict[str, list[tuple[Path, ast.AST]]] = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in imported_names(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom):
                    if node.level:
                        continue
                    names = [node.module or ""]
                else:
                    names = [alias.name for alias in node.names]
                for name in names:
                    top = name.split(".")[0]
                    if top in sys.stdlib_module_names or top in PACKAGES:
                        continue
                    found.setdefault(top, []).append((path, node))
    return found


def test_imports_are_declared_dependencies():
    core, optional = _declared()
    missing = {}
    for name, places in _third_party_imports().items():
        provider = BROUGHT_BY.get(name, name)
        if provider in core or provider in optional:
            continue
        missing[name] = sorted({str(p.relative_to(ROOT)) for p, _ in places})
    assert not missing, f"imported, but neither a core dependency nor a run-time extra's: " \
                        f"{missing}"


def _guards(path: Path, package: str) -> bool:
    """``path`` imports ``package`` inside a function, in a ``try`` whose handler catches
    ImportError (or ModuleNotFoundError): its absence is told where it is first needed."""
    tree = ast.parse(path.read_text())
    for function in ast.walk(tree):
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for block in ast.walk(function):
            if not isinstance(block, ast.Try):
                continue
            caught = {ast.unparse(h.type) for h in block.handlers if h.type is not None}
            if not caught & {"ImportError", "ModuleNotFoundError"}:
                continue
            for node in (n for s in block.body for n in ast.walk(s)):
                if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] \
                        in (package, *[k for k, v in BROUGHT_BY.items() if v == package]):
                    return True
                if isinstance(node, ast.Import) and any(
                        a.name.split(".")[0] == package for a in node.names):
                    return True
    return False


def test_optional_packages_are_imported_behind_a_message():
    """A module importing an optional package also catches its absence (once, in a
    function); no such import sits at module level, where a core verb would load it."""
    core, optional = _declared()
    unguarded = []
    for name, places in _third_party_imports().items():
        provider = BROUGHT_BY.get(name, name)
        if provider in core:
            continue
        assert provider in optional, name
        unguarded += [f"{p.relative_to(ROOT)}:{n.lineno} ({name})" for p, n in places
                      if n.col_offset == 0 or not _guards(p, provider)]
    assert not unguarded, f"optional packages imported without a message when missing: " \
                          f"{unguarded}"
