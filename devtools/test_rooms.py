"""Where a test file belongs: ``python -m devtools.test_rooms [--move] [FILE ...]``.

``tests/`` holds one folder per room of docs/architecture.md, beside ``conformance/`` (the
standards' conformance suite) and the helpers every test imports (at ``tests/`` itself). A test
file's folder is found, in this order:

1. ``PLACED``: the few files the next two rules would put elsewhere, each with its reason;
2. its name: ``test_<words>.py`` goes to the folder whose room has a module (or subpackage) named
   by the longest leading run of ``<words>`` (``test_plant_fmu_x`` -> ``fmus/plant_fmu.py``:
   ``fmus``), or to the folder named so (``test_hil_x`` -> ``hil``). The command modules of
   ``harness/cli/`` and the FMU scripts (``fmu_*.py``) name no room: a command is thin over the
   room that does the work;
3. the modules it imports: every ``import``/``from`` statement of the file (at module level or in
   a function) and every string naming a project module counts once for the folder of that
   module's room; the command line and the public API count only when no other room is imported
   (many tests drive a room through them); ``errors`` and ``toolchain`` count for none. The most
   counted folder wins (a tie: the one listed first in ``FOLDERS``); no project import: ``project``.

Prints ``FILE -> tests/<folder>/`` for each file given (default: every test file outside
``conformance/``), marking a file that is not there; ``--move`` moves such files there with
``git mv``. Exit status 1 if a file is not in its folder (and was not moved).
``tests/project/test_test_layout.py`` checks that every test file is where this puts it.
"""
from __future__ import annotations

import argparse
import ast
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
#: Folder of tests/ -> the source folders of the rooms it tests, the most specific first for the module
#: prefixes (``fmus/hil`` before ``fmus``). A tie of imports goes to the folder listed first.
FOLDERS: dict[str, tuple[str, ...]] = {
    "hil": ("fmus/hil", "harness/hil"),
    "fmus": ("fmus",),
    "controllers": ("controllers",),
    "master": ("harness/master",),
    "scenario": ("harness/scenario",),
    "native": ("harness/native",),
    "studies": ("harness/studies", "harness/analysis"),
    "live": ("harness/live",),
    "evidence": ("evidence",),
    "project": ("devtools", "benchmarks"),
    "api": (".", "harness", "harness/api", "harness/testing", "harness/support"),
    "cli": ("harness/cli",),
}
#: Folders whose imports count only when a file imports no other room: the ways in.
ENTRY = ("api", "cli")
#: Modules of every room (they count for none).
COMMON = ("errors", "toolchain")
#: Folders of tests/ that are not rooms.
OTHER = ("conformance", "data", "c", "hosts")
#: Files the name and import rules would put elsewhere: file name -> folder.
PLACED: dict[str, str] = {
    "test_architecture.py": "project",        # the import rules of every room
    "test_error_tree.py": "project",          # the exception classes of every room
    "test_default_experiment.py": "fmus",     # every FMU's model description (it exports one loop too)
    "test_fmi3_integers.py": "master",        # the master's integer channels (on a small C FMU)
    "test_win64.py": "native",                # the native FMUs' binaries on another platform
    "test_aarch64.py": "native",              # likewise
    "test_from_sources.py": "native",         # the native FMUs compiled from their sources/
    "test_rebuild_hint.py": "scenario",       # harness/scenario/binding.py's hint
    "test_margins.py": "studies",             # the margins of `ipcosim analyze`
    "test_plant_model_exchange.py": "native",  # the native plants' model exchange (over fmus/hybrid.py)
    "test_exit_crash.py": "fmus",             # the FMUs' wrapper at a host's exit (FMUs from tests/conftest.py)
    "test_fmu_runtime.py": "fmus",            # the FMU runtime's imports (FMUs from tests/conftest.py)
}


def folder_of_module(name: str) -> str | None:
    """The folder of tests/ for project module ``name`` (dotted, ``ipcosim.`` removed; None: every room's)."""
    if name.split(".")[0] in COMMON:
        return None
    best, length = "api", 0
    for folder, sources in FOLDERS.items():
        for source in sources:
            prefix = source.replace("/", ".").strip(".")
            if prefix and (name == prefix or name.startswith(prefix + ".")) and len(prefix) > length:
                best, length = folder, len(prefix)
    return best


def _names() -> dict[str, str]:
    """Module and subpackage name -> folder, then each source folder's and each tests/ folder's own
    name (so they win). A room's sub-folders count with it (``controllers/laws/lqg.py``), the
    harness's top-level modules without its sub-folders (rooms of their own)."""
    sources = [(folder, ROOT / source) for folder, paths in FOLDERS.items() for source in paths if source != "."]
    names: dict[str, str] = {}
    for folder, base in sources:
        glob = base.glob if base == ROOT / "harness" else base.rglob
        for path in [*glob("*.py"), *(p.parent for p in glob("*/__init__.py"))]:
            thin = path.parent == ROOT / "harness" / "cli" or path.stem.startswith(("_", "fmu_"))
            if not thin and path.stem not in COMMON:
                names.setdefault(path.stem, folder)
    names.update({base.name: folder for folder, base in sources})
    names.update({folder: folder for folder in FOLDERS})
    return names


def _imported(path: Path) -> list[str]:
    """Each project module ``path`` imports or names in a string, once per statement or string."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
            if node.module in ("ipcosim", "ipcosim.harness"):   # from ipcosim.harness import cli
                names = [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("ipcosim."):
            names = [node.value.split(":")[0]]
        else:
            continue
        for name in names:
            if name == "ipcosim" or name.startswith("ipcosim."):
                found.append(name.removeprefix("ipcosim").removeprefix("."))
            elif name.split(".")[0] in ("evidence", "devtools", "benchmarks"):
                found.append(name)
    return found


def folder_of(path: Path, names: dict[str, str] | None = None) -> str:
    """The folder of tests/ where the test file ``path`` belongs."""
    if path.name in PLACED:
        return PLACED[path.name]
    names = _names() if names is None else names
    words = path.stem.removeprefix("test_").split("_")
    for n in range(len(words), 0, -1):
        if "_".join(words[:n]) in names:
            return names["_".join(words[:n])]
    votes = Counter(f for f in map(folder_of_module, _imported(path)) if f)
    rooms = Counter({f: n for f, n in votes.items() if f not in ENTRY}) or votes
    order = list(FOLDERS)
    return max(rooms, key=lambda f: (rooms[f], -order.index(f))) if rooms else "project"


def room_test_files() -> list[Path]:
    """Every test file of tests/ outside the folders that are not rooms."""
    return sorted(p for p in TESTS.rglob("test_*.py") if p.relative_to(TESTS).parts[0] not in OTHER)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m devtools.test_rooms", description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path, help="test files (default: every one under tests/)")
    parser.add_argument("--move", action="store_true", help="git mv each file that is not in its folder there")
    args = parser.parse_args(argv)
    names, status = _names(), 0
    for path in [p.resolve() for p in args.files] or room_test_files():
        folder = TESTS / folder_of(path, names)
        shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        line = f"{shown} -> {folder.relative_to(ROOT)}/"
        if path.parent == folder:
            print(line)
        elif args.move:
            folder.mkdir(exist_ok=True)
            subprocess.run(["git", "mv", str(path), str(folder / path.name)], cwd=ROOT, check=True)
            print(f"{line} (moved)")
        else:
            print(f"{line} (not there)")
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
