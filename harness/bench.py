"""``make bench`` (``python -m harness.bench [NAME ...]``): run every ``harness/bench_*.py``.

Each bench module exposes ``run() -> list[str]``, the lines to print; its module docstring
says what it measures. Modules run one after the other in this process, in name order; a
module that fails prints one error line and the others still run (exit status 1).
"""
from __future__ import annotations

import importlib
import pkgutil
import sys
import time
from typing import Sequence

import harness


def bench_modules() -> list[str]:
    """Names of the bench modules (``harness.bench_*``), sorted."""
    return sorted(f"harness.{m.name}" for m in pkgutil.iter_modules(harness.__path__)
                  if m.name.startswith("bench_"))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bench modules (all, or those whose name contains one of ``argv``)."""
    wanted = list(sys.argv[1:] if argv is None else argv)
    status = 0
    for name in bench_modules():
        if wanted and not any(w in name for w in wanted):
            continue
        print(f"== {name}", flush=True)
        start = time.perf_counter()
        try:
            lines = importlib.import_module(name).run()
        except Exception as exc:  # noqa: BLE001 -- one line, the other benches still run
            print(f"   error: {type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}",
                  flush=True)
            status = 1
            continue
        for line in lines:
            print(f"   {line}", flush=True)
        print(f"   ({time.perf_counter() - start:.1f} s)", flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
