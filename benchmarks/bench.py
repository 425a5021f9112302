"""``make bench`` (``python -m benchmarks.bench [NAME ...]``): run every ``benchmarks/bench_*.py``.

Each bench module exposes ``run() -> list[str]``, the lines to print; its module docstring
says what it measures. A module whose figures miss a target raises :class:`TargetMissed` with
its lines and the targets missed (``benchmarks.targets``): they are printed and the run exits
non-zero. Modules run one after the other, in name order, each in a fresh
interpreter: FMUs loaded in-process put their resources on ``sys.path`` (pythonfmu's wrapper
does), which would change what a later module imports. A module that fails prints one error
line and the others still run (exit status 1).
"""
from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Sequence

from benchmarks.targets import TargetMissed

HERE = Path(__file__).resolve().parent


def bench_modules() -> list[str]:
    """Names of the bench modules (``benchmarks.bench_*``), sorted."""
    return sorted(f"benchmarks.{m.name}" for m in pkgutil.iter_modules([str(HERE)])
                  if m.name.startswith("bench_"))


def run_one(name: str) -> int:
    """Run one bench module in this process and print its lines (or one error line)."""
    start = time.perf_counter()
    try:
        lines = importlib.import_module(name).run()
    except TargetMissed as exc:
        for line in exc.lines:
            print(f"   {line}", flush=True)
        for line in exc.missed:
            print(f"   TARGET MISSED: {line}", flush=True)
        return 1
    except Exception as exc:  # noqa: BLE001 -- one line, the other benches still run
        text = str(exc).strip()
        print(f"   error: {type(exc).__name__}: {text.splitlines()[0] if text else ''}", flush=True)
        return 1
    for line in lines:
        print(f"   {line}", flush=True)
    print(f"   ({time.perf_counter() - start:.1f} s)", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bench modules (all, or those whose name contains one of ``argv``), each in its own process."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["--one"] and len(args) == 2:
        return run_one(args[1])
    status = 0
    for name in bench_modules():
        if args and not any(w in name for w in args):
            continue
        print(f"== {name}", flush=True)
        rc = subprocess.run([sys.executable, "-m", "benchmarks.bench", "--one", name]).returncode
        if rc != 0:
            if rc < 0:
                print(f"   error: the bench process ended by signal {-rc}", flush=True)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
