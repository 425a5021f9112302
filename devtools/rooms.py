"""The rooms of the code base in figures: ``python -m devtools.rooms [--write]``.

For each room (docs/architecture.md) its modules (``.py`` files), the non-blank lines of those
files, its longest function (``def`` to last line, docstring included) and the import cycles its
modules take part in, and the number of import cycles between all the package's modules (the graph
of ``tests/project/test_architecture.py``). Prints a Markdown table; with ``--write`` it also replaces the
table in docs/architecture.md (its ``rooms:table`` block, ``devtools.docblocks``), which
``tests/project/test_docblocks.py`` compares with what this module computes from the tree. Not a benchmark
of speed: it reads source files only and runs nothing of them.
"""
from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: room -> (folder, whether its sub-folders belong to it); sub-folders listed as rooms of their own are left out.
ROOMS = {
    "ipcosim (top-level modules)": (".", False),
    "fmus": ("fmus", False),
    "fmus/kinds": ("fmus/kinds", True),
    "fmus/hil": ("fmus/hil", True),
    "harness/native": ("harness/native", True),
    "controllers": ("controllers", True),
    "harness/master": ("harness/master", True),
    "harness/scenario": ("harness/scenario", True),
    "harness/analysis": ("harness/analysis", True),
    "harness/hil": ("harness/hil", True),
    "harness/studies": ("harness/studies", True),
    "evidence": ("evidence", True),
    "harness/cli": ("harness/cli", True),
    "harness/live": ("harness/live", True),
    "harness/support": ("harness/support", True),
    "harness/api": ("harness/api", True),
    "harness/testing": ("harness/testing", True),
    "harness (the facade)": ("harness", False),
    "benchmarks": ("benchmarks", True),
    "devtools": ("devtools", True),
}
#: The block of docs/architecture.md that holds the table (``devtools.docblocks``).
BLOCK = "rooms:table"
DOC = ROOT / "docs" / "architecture.md"


def room_files(folder: str, deep: bool) -> list[Path]:
    """The ``.py`` files of a room."""
    base = ROOT / folder
    return sorted(base.rglob("*.py") if deep else base.glob("*.py"))


def nonblank_lines(files: list[Path]) -> int:
    return sum(1 for f in files for line in f.read_text().splitlines() if line.strip())


def longest_function(files: list[Path]) -> tuple[str, int, bool]:
    """(``file:name``, lines, whether its docstring says why it is long) of the longest function
    or method in ``files``."""
    best = ("-", 0, False)
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > best[1]:
                    why = "long on purpose" in (ast.get_docstring(node) or "").lower()
                    best = (f"{f.relative_to(ROOT)}:{node.name}", n, why)
    return best


def import_cycles() -> list[list[str]]:
    """The import cycles among the package's modules (dotted names below ``ipcosim``), by the machinery
    of tests/.../test_architecture.py."""
    path = next((ROOT / "tests").rglob("test_architecture.py"))  # wherever tests/ files it
    spec = importlib.util.spec_from_file_location("_architecture", path)
    assert spec is not None and spec.loader is not None
    arch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(arch)
    return arch.import_cycles(arch._graph())


def module_name(path: Path) -> str:
    """The dotted name below ``ipcosim`` of a file (``harness/master/slave.py``: ``harness.master.slave``)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def table() -> str:
    cycles = import_cycles()
    rows = ["| room | modules | lines (non-blank, .py) | longest function | its lines | import cycles |",
            "|---|---:|---:|---|---:|---:|"]
    for room, (folder, deep) in ROOMS.items():
        files = room_files(folder, deep)
        names = {module_name(f) for f in files}
        name, n, why = longest_function(files)
        note = " (its docstring says why)" if why else ""
        inside = sum(1 for cycle in cycles if names.intersection(cycle))
        rows.append(f"| {room} | {len(files)} | {nonblank_lines(files)} | `{name}`{note} | {n} | {inside} |")
    rows += ["", f"Import cycles between modules: {len(cycles)}."]
    return "\n".join(rows) + "\n"


def block(part: str) -> str:
    """The text of the block ``rooms:<part>`` (``devtools.docblocks``): ``table``, the rooms table."""
    if part != "table":
        raise KeyError(f"no rooms block {part!r} (the one block is rooms:table)")
    return table()


def main(argv: list[str]) -> int:
    from devtools.docblocks import write

    text = table()
    print(text, end="")
    if "--write" in argv:
        write(DOC, BLOCK, text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
