"""The path of one run through the package's modules: ``python -m devtools.run_path [RUN ARGS...]``.

Runs ``ipcosim run`` in this process (default ``single-mass-lqr --stop-time 1``, into a temporary
folder) under a profile hook (:func:`sys.setprofile`) and lists the package's modules whose
functions are called, in the order of their first call, from the command line's entry to the end
of the command (results.csv and metrics.json written, summary printed). How it counts:

- a module is on the *path* when a function of it is called outside any import; a module whose
  code runs only while modules are imported (its body, decorators, dataclass creation) is only
  *loaded*, and listed apart; so are the modules called only while the command line's parser
  is built (every sub-command's ``register``);
- the FMUs' own Python code (a Python FMU carries a private copy of the modules it needs, under
  ``_ipcosim_<model>_<digest>``) is the FMU's, not the master's: listed as one line per FMU, not
  counted;
- a call *goes back* when a module calls (directly, or through library code such as a callback
  from a C loop) a function of a module in a higher room of the layout
  (``tests/project/test_architecture.py``'s ROOMS): listed with the first function called.

Not a benchmark: the hook slows the run down many times.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
from contextlib import redirect_stdout
from pathlib import Path
from types import FrameType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ARGS = ("single-mass-lqr", "--stop-time", "1")


def _architecture() -> Any:
    """tests/project/test_architecture.py as a module (its ROOMS and ``room_of``)."""
    spec = importlib.util.spec_from_file_location("_architecture", ROOT / "tests" / "project" / "test_architecture.py")
    assert spec is not None and spec.loader is not None
    arch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(arch)
    return arch


def _project(name: str) -> bool:
    return name == "ipcosim" or name.startswith("ipcosim.")


def _fmu(name: str) -> bool:
    return name.startswith("_ipcosim_")


class PathRecorder:
    """The profile hook: first calls per module, in and out of imports, and upward calls."""

    def __init__(self) -> None:
        self.importing = 0  # module bodies executing now (nested imports)
        self.path: dict[str, str] = {}  # module -> first function called outside imports (in order)
        self.outside_parser: set[str] = set()  # modules called outside the building of the command's parser
        self.parsing = 0  # inside ``build_parser``
        self.loaded: dict[str, str] = {}  # module -> first code run while importing
        self.fmus: dict[str, int] = {}  # FMU private package -> calls
        self.edges: dict[tuple[str, str], str] = {}  # (caller module, callee module) -> first function

    def __call__(self, frame: FrameType, event: str, arg: Any) -> None:
        if event == "call":
            code = frame.f_code
            if code.co_name == "<module>":
                self.importing += 1
            name = frame.f_globals.get("__name__", "")
            if _project(name):
                if self.importing:
                    self.loaded.setdefault(name, code.co_name)
                else:
                    self.path.setdefault(name, code.co_name)
                    if code.co_name == "build_parser":
                        self.parsing += 1
                    if not self.parsing:
                        self.outside_parser.add(name)
                    self._edge(frame, name, code.co_name)
            elif _fmu(name):
                package = name.split(".", 1)[0]
                self.fmus[package] = self.fmus.get(package, 0) + 1
        elif event == "return" and frame.f_code.co_name == "<module>":
            self.importing -= 1
        elif event == "return" and frame.f_code.co_name == "build_parser" and self.parsing:
            self.parsing -= 1

    def _edge(self, frame: FrameType, callee: str, function: str) -> None:
        caller = frame.f_back
        while caller is not None:
            name = caller.f_globals.get("__name__", "")
            if _project(name) or _fmu(name):
                if name != callee:
                    self.edges.setdefault((name, callee), function)
                return
            caller = caller.f_back


def record(run_args: list[str]) -> tuple[PathRecorder, int]:
    """Run ``ipcosim run RUN_ARGS`` under the hook (``--out`` a temporary folder unless given)."""
    recorder = PathRecorder()
    with tempfile.TemporaryDirectory(prefix="run-path-") as tmp:
        args = list(run_args) + ([] if "--out" in run_args else ["--out", os.path.join(tmp, "out")])
        sys.setprofile(recorder)
        try:
            from ipcosim.harness.cli import main

            with open(os.devnull, "w") as null, redirect_stdout(null):
                status = main(["run", *args])
        finally:
            sys.setprofile(None)
    return recorder, status


def report(recorder: PathRecorder, status: int) -> str:
    arch = _architecture()

    def room(module: str) -> tuple[int, str]:
        found = arch.room_of(module.removeprefix("ipcosim").removeprefix("."))
        return found if found is not None else (-1, "?")

    parsers = [m for m in recorder.path if m not in recorder.outside_parser]
    path = [(m, f) for m, f in recorder.path.items() if m not in parsers]
    lines = [f"exit status {status}", "",
             f"The path of the run: {len(path)} modules, in order of first call (room, first function):"]
    for k, (module, function) in enumerate(path, 1):
        lines.append(f"  {k:2d}. {module:45s} [{room(module)[1] or 'ipcosim'}] {function}")
    lines += ["", f"Other sub-commands, only their parser registered: {len(parsers)} modules",
              "  " + ", ".join(parsers)]
    only_loaded = [m for m in recorder.loaded if m not in recorder.path]
    lines += ["", f"Loaded only (code run while importing, no call on the path): {len(only_loaded)} modules",
              "  " + ", ".join(only_loaded)]
    lines += ["", "FMU code (the FMUs' private copies; not counted): "
              + (", ".join(f"{p} ({n} calls)" for p, n in recorder.fmus.items()) or "none")]
    back = [(a, b, f) for (a, b), f in recorder.edges.items()
            if _project(a) and room(b)[0] > room(a)[0]]
    lines += ["", f"Calls back up (a module calling into a higher room): {len(back)}"]
    lines += [f"  {a} -> {b}.{f}" for a, b, f in back]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    recorder, status = record(argv or list(DEFAULT_ARGS))
    print(report(recorder, status), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
