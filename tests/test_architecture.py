"""The layout's promises, checked: one-way imports between the rooms and no import cycles.

Rooms (docs/architecture.md), lowest first; a room may import only rooms to its left:

    errors, toolchain  <-  fmus (physics, plant FMU glue, HIL)  <-  controllers (laws, controller
            FMU glue)  <-  harness.native (the C generator: a build tool over both)
            <-  harness.master  <-  harness.scenario
            <-  harness.engine, harness.export  <-  harness.studies  <-  harness.evidence  <-  harness.cli

Every import counts, at module level or inside a function (a lazy import is still a
dependency), except those under ``if TYPE_CHECKING:``, which only name types for readers and
checkers and never run.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fmus", "controllers", "harness")

#: Modules of the package's top folder: below every room.
BOTTOM = ("errors", "toolchain")
#: room -> rooms it must not import (prefix match on the dotted name below ``ipcosim``).
FORBIDDEN = {
    **{base: PACKAGES for base in BOTTOM},
    "fmus": ("controllers", "harness"),
    "controllers": ("harness",),
    "harness.native": ("harness.master", "harness.scenario", "harness.engine", "harness.export",
                       "harness.studies", "harness.cli"),
    "harness.master": ("harness.scenario", "harness.studies", "harness.cli", "harness.engine",
                       "harness.plot", "harness.native", "controllers", "fmus"),
    "harness.scenario": ("harness.studies", "harness.cli", "harness.engine"),
    "harness.engine": ("harness.studies", "harness.cli"),
    "harness.export": ("harness.studies", "harness.cli"),
    "harness.studies": ("harness.evidence", "harness.cli"),
    "harness.evidence": ("harness.cli",),
}


def _modules() -> dict[str, Path]:
    mods = {base: ROOT / f"{base}.py" for base in BOTTOM if (ROOT / f"{base}.py").is_file()}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            parts = f.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = f
    return mods


def _imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    found: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    type_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If) and _is_type_checking(block.test)
                 for stmt in block.body for n in ast.walk(stmt)}
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(pkg + ([base] if base else []))
            else:
                base = base
            targets = [base] + [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        for target in targets:
            target = target.removeprefix("ipcosim.")
            while target and target not in mods:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    return {name: _imports(name, path, mods) for name, path in mods.items()}


def _room_of(module: str) -> str:
    return max((room for room in FORBIDDEN if module == room or module.startswith(room + ".")), key=len,
               default=module)


def test_imports_go_one_way() -> None:
    bad = []
    for module, targets in _graph().items():
        room = _room_of(module)
        for target in targets:
            if any(target == f or target.startswith(f + ".") for f in FORBIDDEN.get(room, ())):
                bad.append(f"{module} -> {target}")
    assert not bad, "imports against the layout's direction:\n" + "\n".join(sorted(bad))


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles of a module graph: its strongly connected components of more than one
    module (Tarjan's algorithm), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    for v in list(graph):
        if v not in index:
            visit(v)
    return cycles


def test_no_import_cycles() -> None:
    cycles = import_cycles(_graph())
    assert not cycles, f"import cycles: {cycles}"


def test_the_checks_see_a_forbidden_edge(tmp_path) -> None:
    """The direction check itself: a physics module importing the master is caught, lazily too,
    and a type-only import is not."""
    path = tmp_path / "physics.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                    "    from ipcosim.harness.engine import run_with\n"
                    "def f():\n    from ipcosim.harness.master.results import Result\n")
    mods = {"fmus.physics": path, "harness.master.results": path, "harness.engine": path}
    assert _imports("fmus.physics", path, mods) == {"harness.master.results"}


def test_the_cycle_check_sees_a_cycle() -> None:
    """The cycle finder itself: a two-module and a three-module cycle are found, a chain is not."""
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c", "f"}, "f": set()}
    assert sorted(import_cycles(graph)) == [["a", "b"], ["c", "d", "e"]]
