"""The packages' import graph has no cycle.

The graph is read from the source with ``ast``, without importing anything: an edge runs
from a module to every module of the project it imports, at the top or inside a function
(an import deferred into a function is still a dependency), except under
``if TYPE_CHECKING:``. Importing ``a.b.c`` runs the ``__init__`` of ``a.b`` too, so the
edge also reaches those packages (not the importer's own enclosing packages, which are
already being initialised when it runs).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("robocal_casadi", "planning")


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules(root: Path, packages: tuple[str, ...]) -> dict[str, Path]:
    return {module_name(p, root): p for package in packages for p in (root / package).rglob("*.py")}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def imported_names(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement in ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _with_packages(target: str, importer: str, modules: dict[str, Path]) -> set[str]:
    """``target`` and the packages on its path that are not enclosing ``importer``."""
    parts = target.split(".")
    own = {".".join(importer.split(".")[:k]) for k in range(1, importer.count(".") + 1)}
    return {".".join(parts[:k]) for k in range(1, len(parts) + 1)} & modules.keys() - own


def import_graph(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    modules = project_modules(root, packages)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges: set[str] = set()
        for node in imported_names(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                # ``from a import b`` imports the module ``a.b`` when there is one.
                targets = [source] + [f"{source}.{alias.name}" for alias in node.names]
            for target in targets:
                edges |= _with_packages(target, name, modules)
        graph[name] = edges - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_a_planted_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"d"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_a_planted_cycle_through_a_function_level_import_is_found(tmp_path):
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("from .y import g\n")
    (package / "x.py").write_text("from .sub.y import g\n")
    (package / "sub" / "y.py").write_text("def g():\n    from ..x import f\n")
    (package / "z.py").write_text("from typing import TYPE_CHECKING\n"
                                  "if TYPE_CHECKING:\n    from .x import f\n")
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.x"] == {"pkg.sub", "pkg.sub.y"}  # the package on the way counts
    assert graph["pkg.sub.y"] == {"pkg.x"}  # not its own enclosing packages
    assert graph["pkg.z"] == set()  # names for type checking only
    assert cycles(graph) == [["pkg.sub", "pkg.sub.y", "pkg.x"]]


def test_the_project_graph_resolves_its_imports():
    graph = import_graph()
    assert "robocal_casadi.errors" in graph["robocal_casadi.model.robot"]
    assert "robocal_casadi.calibration.diagnosis" in graph[
        "robocal_casadi.calibration.identification"]  # ``from . import diagnosis``
    assert {"planning", "planning.designed"} <= graph["robocal_casadi.commands.plan"]
    assert "robocal_casadi.model.robot" not in graph["robocal_casadi.model.parameters"]


# The Python front door (``robocal_casadi.api``, re-exported by the package's
# ``__init__``) offers ``plan``, and the planner, a folder beside the package, builds on
# the package's engine. Python runs the package's ``__init__`` for any of its modules, so
# the front door's one edge into the planner closes a loop through ``__init__``. It is
# allowed only as an import deferred into ``api.plan`` (run when it is called, after every
# module is loaded), and ``test_the_front_door_reaches_the_planner_only_when_called``
# holds it there.
FRONT_DOOR = "robocal_casadi.api"


def test_no_import_cycle():
    graph = import_graph()
    graph[FRONT_DOOR] = {m for m in graph[FRONT_DOOR] if m.split(".")[0] != "planning"}
    found = cycles(graph)
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_the_front_door_reaches_the_planner_only_when_called():
    tree = ast.parse((ROOT / "robocal_casadi" / "api.py").read_text())
    at_top = [node for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))]
    assert at_top and not [n for n in at_top
                           if isinstance(n, ast.ImportFrom) and (n.module or "").startswith(
                               "planning")]
    deferred = [node for function in ast.walk(tree) if isinstance(function, ast.FunctionDef)
                for node in ast.walk(function) if isinstance(node, ast.ImportFrom)
                and (node.module or "").startswith("planning")]
    assert [function.name for function in ast.walk(tree)
            if isinstance(function, ast.FunctionDef)
            and any(n in deferred for n in ast.walk(function))] == ["plan"]


def test_the_result_records_know_nothing_of_the_calibration_engine():
    """``results`` holds the records a calibration fills in; it imports no module of the
    engine, not even for type checking (the engine builds the result from what it
    computed, nothing reads a ``Problem``'s inside from the outside)."""
    tree = ast.parse((ROOT / "robocal_casadi" / "results.py").read_text())
    modules = [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    modules += [alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                for alias in node.names]
    assert modules and not [m for m in modules if "calibration" in m.split(".")]


# The layers, bottom first: a package imports packages of its own layer or below, never
# one above. ``robocal_casadi`` itself (its ``__init__``, the public API) is the top; the
# graph's edge into it from every import of a submodule only says Python runs it first.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "common"),  # the root exception class; units, fields, tables, output
    ("model",),  # robot file, parameters, forward kinematics, inverse kinematics
    ("urdf",),  # URDF chains to and from the model
    ("formats",),  # what a calibration or a plan is written as for a controller
    ("results",),  # the typed records a calibration fills in, and result.json
    ("effects",),  # what the geometric model lacks
    ("instruments", "tracking"),  # each kind's reader, model and simulator; tracking
    ("calibration",),  # the engine: problem, solvers, identifiability, diagnosis
    ("report", "planning"),  # the customer report; experiment design
    ("job",),  # the whole job: calibrate, choose what is delivered, write; compensation
    ("fleet",),  # many jobs on a cluster
    ("commands",),  # one module per verb
    ("cli", "api", "robocal_casadi"),  # the command line; the Python front door; the package
)


def package_of(module: str) -> str:
    """The layer unit a module belongs to: ``planning``, or the package (or top-level
    module) right under ``robocal_casadi``, or ``robocal_casadi`` for its ``__init__``."""
    parts = module.split(".")
    if parts[0] == "planning":
        return "planning"
    return parts[1] if len(parts) > 1 else parts[0]


def package_graph(graph: dict[str, set[str]]) -> dict[str, dict[str, set[str]]]:
    """Package -> imported package -> the module edges that make it, the root's
    ``__init__`` left out as a target."""
    edges: dict[str, dict[str, set[str]]] = {}
    for module, targets in graph.items():
        for target in targets:
            a, b = package_of(module), package_of(target)
            if a != b and b != "robocal_casadi":
                edges.setdefault(a, {}).setdefault(b, set()).add(f"{module} -> {target}")
    return edges


def climbing_imports(graph: dict[str, set[str]],
                     layers: tuple[tuple[str, ...], ...] = LAYERS) -> list[str]:
    """Every module edge from a package to one of a higher layer."""
    level = {package: k for k, layer in enumerate(layers) for package in layer}
    return sorted(edge for a, targets in package_graph(graph).items()
                  for b, found in targets.items() if level[b] > level[a] for edge in found)


def test_every_package_has_a_layer():
    packages = {package_of(module) for module in import_graph()}
    listed = [package for layer in LAYERS for package in layer]
    assert len(listed) == len(set(listed))
    assert packages <= set(listed), f"unplaced: {sorted(packages - set(listed))}"


def test_no_import_climbs_a_layer():
    found = climbing_imports(import_graph())
    assert not found, "imports that climb the layers: " + "; ".join(found)


def test_no_package_level_cycle():
    packages = {a: set(targets) for a, targets in package_graph(import_graph()).items()}
    for targets in list(packages.values()):
        for b in targets:
            packages.setdefault(b, set())
    found = cycles(packages)
    assert not found, "package cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_a_planted_climbing_import_is_found():
    graph = {"robocal_casadi.results": {"robocal_casadi.calibration.problem",
                                        "robocal_casadi.model.robot"},
             "robocal_casadi.calibration.problem": {"robocal_casadi.results"},
             "robocal_casadi.model.robot": set(),
             "planning.design": {"robocal_casadi", "robocal_casadi.model.robot"}}
    assert climbing_imports(graph) == [
        "robocal_casadi.results -> robocal_casadi.calibration.problem"]
    assert package_graph(graph)["planning"] == {"model": {
        "planning.design -> robocal_casadi.model.robot"}}
