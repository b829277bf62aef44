"""The tree's architecture, kept: no import cycles between files, imports pointing one way
(operator -> runtime -> processes -> drivers / generator modules -> servo -> geometry -> base),
every package listed in pyproject.toml and opening with a docstring, files of a readable size."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ROOTS = ("controller", "drivers")
MAX_LINES = 420  # files under about 400 lines

# What each part of the tree may import besides itself (see controller/__init__.py).
GENERATOR_MODULES = {"corners", "ph", "feed", "dynamics"}
ALLOWED: dict[str, set[str]] = {
    "base": set(),
    "geometry": {"base"},
    "corners": {"base", "geometry"},
    "ph": {"base", "geometry", "corners"},
    "feed": {"base", "geometry"},
    "servo": {"base", "geometry"},  # path_distance evaluates NURBS blocks
    "dynamics": {"base", "geometry", "servo"},
    "drivers": {"base", "servo"},  # the sim card clocks its axes through the servo model
    "interpreter": {"base", "geometry"},
    "generator": {"base", "geometry", "servo"} | GENERATOR_MODULES,
    "motion": {"base", "drivers", "servo"},  # hold and override: the servo model's check
    "runtime": {"base", "geometry", "servo", "drivers", "interpreter", "generator", "motion"}
    | GENERATOR_MODULES,
    "operator": {"base", "geometry", "servo", "drivers", "interpreter", "generator", "motion",
                 "runtime"} | GENERATOR_MODULES,
}


def part_of(module: str) -> str:
    """The part of the tree a module belongs to (a key of ALLOWED)."""
    parts = module.split(".")
    if parts[0] == "drivers":
        return "drivers"
    if len(parts) >= 3 and parts[1] == "generator" and parts[2] in GENERATOR_MODULES:
        return parts[2]
    if len(parts) >= 3 or (len(parts) == 2 and (REPO / "controller" / parts[1]).is_dir()):
        return parts[1]
    return "base"


def source_files() -> dict[str, Path]:
    """Module name -> file, for every Python file of the installed packages."""
    files = {}
    for root in ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            rel = path.relative_to(REPO).with_suffix("")
            name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
            files[name] = path
    return files


def _resolve(name: str, modules: set[str]) -> str | None:
    """The project module an import names (the longest module prefix: `a.b.func` -> `a.b`)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def imports_of(path: Path, modules: set[str]) -> set[str]:
    """Every project module a file imports, at any depth: in functions and under TYPE_CHECKING
    too, since an import cycle is one whether or not it runs at import time."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        found |= {m for m in (_resolve(n, modules) for n in names) if m is not None}
    return found


def import_graph() -> dict[str, set[str]]:
    files = source_files()
    modules = set(files)
    graph = {}
    for name, path in files.items():
        # a package's own __init__ is imported on the way to any of its modules: not an edge
        graph[name] = {m for m in imports_of(path, modules) if m != name
                       and not (name.startswith(m + ".") and files[m].name == "__init__.py")}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph.get(v, ()):
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def wrong_way(graph: dict[str, set[str]]) -> list[str]:
    """Imports from a part of the tree that this part may not import."""
    bad = []
    for module, targets in sorted(graph.items()):
        here = part_of(module)
        for target in sorted(targets):
            there = part_of(target)
            if there != here and there not in ALLOWED[here]:
                bad.append(f"{module} ({here}) imports {target} ({there})")
    return bad


def test_no_import_cycles() -> None:
    assert cycles(import_graph()) == []


def test_imports_point_one_way() -> None:
    assert wrong_way(import_graph()) == []


def test_the_checks_find_a_cycle_and_a_wrong_way_import() -> None:
    graph = {"controller.geometry.nurbs": {"controller.generator.feed.planner"},
             "controller.generator.feed.planner": {"controller.geometry.nurbs"},
             "controller.config": set()}
    assert cycles(graph) == [["controller.generator.feed.planner", "controller.geometry.nurbs"]]
    assert wrong_way(graph) == ["controller.geometry.nurbs (geometry) imports "
                                "controller.generator.feed.planner (feed)"]


def test_parts_are_known() -> None:
    assert {part_of(m) for m in source_files()} == set(ALLOWED)
    assert part_of("controller.config") == "base"
    assert part_of("controller.generator.replan") == "generator"
    assert part_of("controller.generator.ph.fit") == "ph"
    assert part_of("controller.motion") == "motion"
    assert part_of("controller.servo.model") == "servo"


def test_every_package_is_installed() -> None:
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"][
        "packages"])
    packages = {name for name, path in source_files().items() if path.name == "__init__.py"}
    assert packages <= listed
    assert listed - packages == {"controller.machine_configs"}


# A file may be longer when it is one cohesive class that splitting would scatter (its state
# spread over mixins or helpers reaching into it): its docstring has a line "Kept whole:
# <Class> ..." naming a class the file defines and saying why.
MAX_LINES_KEPT_WHOLE = 700
KEPT_WHOLE = "Kept whole:"


def line_limit(source: str) -> int:
    """The most lines a file may have: MAX_LINES, or MAX_LINES_KEPT_WHOLE when its docstring
    has a "Kept whole:" line naming one of its classes and saying why."""
    tree = ast.parse(source)
    classes = {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
    for line in (ast.get_docstring(tree) or "").splitlines():
        if line.strip().startswith(KEPT_WHOLE):
            words = line.strip()[len(KEPT_WHOLE):].replace(",", " ").split()
            if len(words) >= 3 and words[0].strip("`") in classes:  # a class and why
                return MAX_LINES_KEPT_WHOLE
    return MAX_LINES


def test_only_a_class_kept_whole_may_be_longer() -> None:
    body = "class Loop:\n    pass\n"
    assert line_limit(f'"""A loop."""\n{body}') == MAX_LINES
    assert line_limit(f'"""A loop.\n\nKept whole: Loop owns the state of one run."""\n{body}'
                      ) == MAX_LINES_KEPT_WHOLE
    assert line_limit(f'"""A loop.\n\nKept whole: Other owns the state."""\n{body}'
                      ) == MAX_LINES  # not a class of this file
    assert line_limit(f'"""A loop.\n\nKept whole: Loop"""\n{body}') == MAX_LINES  # no why
    assert line_limit(f'"""A loop; Kept whole: Loop owns it."""\n{body}') == MAX_LINES


@pytest.mark.parametrize("name", sorted(source_files()))
def test_every_file_says_what_it_is(name: str) -> None:
    path = source_files()[name]
    source = path.read_text(encoding="utf-8")
    tree = ast.parse(source)
    doc = ast.get_docstring(tree)
    assert doc, f"{path} has no docstring"
    if path.name == "__init__.py" and not name.startswith("drivers."):  # drivers/ says it once
        assert "import" in doc.lower(), f"{path} does not say what its package may import"
    assert len(source.splitlines()) <= line_limit(source), \
        f"{path}: more than {MAX_LINES} lines, and not one class kept whole (see line_limit)"
