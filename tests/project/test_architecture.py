"""The layout's promises, checked: every module in a room, imports only downwards, no import cycles.

Rooms (docs/architecture.md), lowest first; a module may import its own room and the rooms
below it, never one above:

    errors, toolchain                          the base exceptions, the C-compiler rule
    fmus                                       physics, plant FMU glue, task metrics, the Python FMU
                                               build, the HIL's one room (card API, card clients, wire
                                               format, adapter glue; virtual rig, its server and service)
    controllers                                control-law design, discrete laws, the pure closed loop,
                                               controller FMU glue
    harness.support                            where things are found and built; the missing-extra check
    harness.native                             the C generator, over the plants and the laws
    harness.master                             the generic master (knows no plant, law or generator)
    harness.scenario                           SSP read, validate, bind, pack, flavours
    harness.analysis                           the loop's linear analysis, its figures, the residual cycle
                                               (a run's amplitude bound is predicted before it runs)
    harness.hil                                the card observer and the ``hil`` swap alias
    ipcosim, harness (the facade),             the lazy public names; the run API (options, grammar, engine,
    harness.api, harness.testing,              public, describe, plots, export); the test support (checks,
    harness.live                               baselines, pytest plugin); the live view
    harness.studies                            the generic study engine
    harness.cli                                the command line

An import is any ``import``/``from`` statement, at module level or inside a function (a lazy
import is still a dependency), and any string naming a project module the way
``importlib.import_module`` is given it (``"ipcosim.harness.cli.run"``, ``f"ipcosim.harness.cli.{name}"``,
``"module:Class"``); imports under ``if TYPE_CHECKING:`` only name types and do not count.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("fmus", "controllers", "harness")

#: The rooms, lowest first: each a tuple of module names or package prefixes (dotted, below ``ipcosim``;
#: ``""`` is the package itself). A module belongs to the room of its longest matching prefix.
ROOMS: tuple[tuple[str, ...], ...] = (
    ("errors", "toolchain"),
    ("fmus",),
    ("controllers",),
    ("harness.support",),
    ("harness.native",),
    ("harness.master",),
    ("harness.scenario",),
    ("harness.analysis",),
    ("harness.hil",),
    ("", "harness", "harness.api", "harness.testing", "harness.live"),
    ("harness.studies",),
    ("harness.cli",),
)
#: Prefixes that name one module only, not the package below them (the rest have rooms of their own).
EXACT = ("", "harness")
#: Rooms a room must not import although they lie below it: the master is generic.
FORBIDDEN_BELOW = {"harness.master": ("fmus", "controllers", "harness.native")}

_MODULE_STRING = re.compile(r"^ipcosim((?:\.\w+)+)(?::\w+)?$")


def _modules(root: Path = ROOT) -> dict[str, Path]:
    mods = {"": root / "__init__.py"}
    mods.update({f.stem: f for f in root.glob("*.py") if f.stem != "__init__"})
    for pkg in PACKAGES:
        for f in (root / pkg).rglob("*.py"):
            parts = f.relative_to(root).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return mods


def _targets(node: ast.AST, package: str) -> list[str]:
    """The dotted names (with ``ipcosim.``) an AST node imports or names as a module string."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level:
            parts = package.split(".")[: len(package.split(".")) - node.level + 1]
            base = ".".join(["ipcosim", *[p for p in parts if p], *([base] if base else [])])
        return [base] + [f"{base}.{a.name}" for a in node.names]
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        m = _MODULE_STRING.match(node.value)
        return [f"ipcosim{m.group(1)}"] if m else []
    if isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
        head = str(node.values[0].value)
        return [head.rstrip(".")] if head.startswith("ipcosim.") and head.endswith(".") else []
    return []


def _imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    """The project modules that module ``name`` (file ``path``) imports, in ``mods``' names."""
    found: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    type_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If) and _is_type_checking(block.test)
                 for stmt in block.body for n in ast.walk(stmt)}
    in_fstring = {id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values}
    for node in ast.walk(tree):
        if id(node) in type_only or id(node) in in_fstring:
            continue
        for target in _targets(node, package):
            if target != "ipcosim" and not target.startswith("ipcosim."):
                continue
            target = target.removeprefix("ipcosim").removeprefix(".")
            if isinstance(node, ast.Constant) and target not in mods:
                continue  # a string that merely looks like a module path
            while target and target not in mods:
                target = target.rpartition(".")[0]
            if target != name and (target or isinstance(node, (ast.Import, ast.ImportFrom))):
                found.add(target)
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _graph(root: Path = ROOT) -> dict[str, set[str]]:
    mods = _modules(root)
    return {name: _imports(name, path, mods) for name, path in mods.items()}


def room_of(module: str, rooms: tuple[tuple[str, ...], ...] = ROOMS) -> tuple[int, str] | None:
    """(level, prefix) of the room a module belongs to (its longest matching prefix), or None."""
    best: tuple[int, str] | None = None
    for level, prefixes in enumerate(rooms):
        for p in prefixes:
            if module == p or (p not in EXACT and module.startswith(p + ".")):
                if best is None or len(p) > len(best[1]):
                    best = (level, p)
    return best


def against_the_layers(graph: dict[str, set[str]], rooms: tuple[tuple[str, ...], ...] = ROOMS,
                       forbidden_below: dict[str, tuple[str, ...]] = FORBIDDEN_BELOW) -> list[str]:
    """Every edge ``module -> target`` of ``graph`` that imports upwards (or into a room forbidden below)."""
    bad = []
    for module, targets in graph.items():
        here = room_of(module, rooms)
        for target in targets:
            there = room_of(target, rooms)
            if here is None or there is None:
                continue
            no = forbidden_below.get(here[1], ())
            if there[0] > here[0] or any(target == f or target.startswith(f + ".") for f in no):
                bad.append(f"{module} -> {target}")
    return sorted(bad)


def test_every_module_is_in_a_room() -> None:
    lost = sorted(m for m in _modules() if room_of(m) is None)
    assert not lost, f"modules in no room (add them to ROOMS): {lost}"


def test_imports_go_one_way() -> None:
    bad = against_the_layers(_graph())
    assert not bad, "imports against the layout's direction:\n" + "\n".join(bad)


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


#: Top-level folders of the clone that are not installed: the package never imports them.
OUTSIDE = ("evidence", "devtools", "benchmarks", "tests")


def outside_imports(path: Path) -> list[str]:
    """The imports of a module (file ``path``) of a folder the package does not install (``OUTSIDE``):
    ``import``/``from`` statements anywhere in the module and strings naming one of their modules."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and \
                re.fullmatch(r"(\w+)(\.\w+)+(:\w+)?", node.value):
            module = node.value.partition(":")[0]
            if (ROOT / module.replace(".", "/")).with_suffix(".py").is_file():
                names = [module]
        found += [n for n in names if n.split(".")[0] in OUTSIDE]
    return found


def test_the_package_never_imports_the_evidence_or_the_tooling() -> None:
    bad = {name: found for name, path in _modules().items() if (found := outside_imports(path))}
    assert not bad, f"installed modules importing folders that are not installed: {bad}"


def test_the_outside_check_sees_an_import(tmp_path) -> None:
    mod = tmp_path / "m.py"
    mod.write_text("def f():\n    from evidence.claims import judge\n    import devtools.apidoc\n"
                   "    return 'evidence.results_page:main', 'evidence and more'\n")
    assert outside_imports(mod) == ["evidence.claims", "devtools.apidoc", "evidence.results_page"]


def test_no_import_cycles() -> None:
    cycles = import_cycles(_graph())
    assert not cycles, f"import cycles: {cycles}"


def test_the_checks_see_a_forbidden_edge(tmp_path) -> None:
    """The direction check itself: a physics module importing the master is caught, lazily too and by
    a module string, and a type-only import and a string that is no module are not."""
    path = tmp_path / "physics.py"
    path.write_text("from typing import TYPE_CHECKING\nimport importlib\nif TYPE_CHECKING:\n"
                    "    from ipcosim.harness.api.engine import run_with\n"
                    "TOOL = 'ipcosim.fmus.gone'\n"
                    "def f():\n    from ipcosim.harness.master.results import Result\n"
                    "def g(name):\n    return importlib.import_module(f'ipcosim.harness.cli.{name}')\n"
                    "PLUGIN = 'ipcosim.harness.studies.sweep:run_sweep'\n")
    mods = {"fmus.physics": path, "fmus": path, "harness.master.results": path, "harness.api.engine": path,
            "harness.cli": path, "harness.studies.sweep": path}
    found = _imports("fmus.physics", path, mods)
    assert found == {"harness.master.results", "harness.cli", "harness.studies.sweep"}
    assert against_the_layers({"fmus.physics": found}) == [
        "fmus.physics -> harness.cli", "fmus.physics -> harness.master.results",
        "fmus.physics -> harness.studies.sweep"]
    assert against_the_layers({"harness.master.slave": {"fmus.params", "errors"}}) == [
        "harness.master.slave -> fmus.params"]


def test_the_cycle_check_sees_a_cycle() -> None:
    """The cycle finder itself: a two-module and a three-module cycle are found, a chain is not."""
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c", "f"}, "f": set()}
    assert sorted(import_cycles(graph)) == [["a", "b"], ["c", "d", "e"]]


#: What a plain simulation (no swap, no real time, no live view) must not load: the master stays
#: generic, and the rooms above it are loaded only by the commands that use them; the code of FMI 3.0
#: clocks only for FMI 3.0 FMUs (the scenarios' are FMI 2.0).
NOT_FOR_A_PLAIN_RUN = ("ipcosim.harness.hil", "ipcosim.fmus.hil", "ipcosim.harness.studies", "ipcosim.harness.live",
                       "ipcosim.harness.native", "ipcosim.harness.master.clocked", "ipcosim.harness.master.clocks",
                       "ipcosim.harness.master.clockstep")

_LOADED = """
import os, sys, tempfile
from ipcosim.harness.cli import main
with tempfile.TemporaryDirectory() as tmp:
    status = main(["run", "single-mass-lqr", "--stop-time", "0.05", "--quiet", "--out", os.path.join(tmp, "out"),
                   *sys.argv[1:]])
print(status, *sorted(m for m in sys.modules if m.startswith("ipcosim")))
"""


def _loaded_by_run(*args: str, env: dict[str, str] | None = None) -> tuple[int, set[str]]:
    import os
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _LOADED, *args], capture_output=True, text=True, timeout=300,
                          cwd=ROOT, env={**os.environ, **(env or {})})
    status, *modules = done.stdout.split()
    return int(status), set(modules)


def _within(modules: set[str], packages: tuple[str, ...]) -> list[str]:
    return sorted(m for m in modules if any(m == p or m.startswith(p + ".") for p in packages))


def test_a_plain_run_loads_no_hil_study_or_live_code() -> None:
    status, modules = _loaded_by_run()
    assert status == 0
    assert "ipcosim.harness.master.execution" in modules  # the probe did run the master
    assert _within(modules, NOT_FOR_A_PLAIN_RUN) == []


def test_a_native_run_loads_the_native_flavour_alone(native_fmus) -> None:
    """The native flavour's run loads its redesign of the bindings (``harness.native``), and nothing else
    a plain run does not."""
    status, modules = _loaded_by_run("--fmus", "native", "--fmu-dir", str(native_fmus[1]))
    assert status == 0
    assert "ipcosim.harness.native.redesign" in modules  # the probe did run the native flavour
    assert _within(modules, tuple(p for p in NOT_FOR_A_PLAIN_RUN if p != "ipcosim.harness.native")) == []


def test_a_hil_swap_still_finds_its_alias() -> None:
    """The ``hil`` alias is registered when a swap asks for it (the run itself fails: no rig serves
    the port given, which this test holds bound without listening, so that nothing else can)."""
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        uri = f"q4:0@tcpip://127.0.0.1:{held.getsockname()[1]}"
        status, modules = _loaded_by_run("--swap", "plant=hil", env={"IPCOSIM_HIL_URI": uri})
    assert status == 1  # bound and run, stopped by the missing rig: not a usage error (2)
    assert "ipcosim.harness.hil.swap" in modules
