"""``make bench`` (``python -m benchmarks.bench [NAME ...]``): run every ``benchmarks/bench_*.py``.

Each bench module exposes ``run() -> list[str]``, the lines to print; its module docstring says
what it measures. It records its figures through ``benchmarks.targets`` (:func:`~benchmarks.targets.target`
for the checked ones, :func:`~benchmarks.targets.figure` for the rest). Modules run one after
the other, in name order, each in a fresh interpreter: FMUs loaded in-process put their resources
on ``sys.path`` (pythonfmu's wrapper does), which would change what a later module imports.

After its lines, a module prints one ``TARGET MISSED`` line per missed target; a module that
cannot run its subject prints one error line. Every module runs; the exit status is 1 when a
target was missed or a module failed, else 0.

The figures of the modules that ran replace theirs in ``benchmarks/last.json`` (with the date,
the machine and its load average at the start and the end of each module), from which
``python -m benchmarks.docs --update`` writes the figures of the docs.
"""
from __future__ import annotations

import datetime
import importlib
import json
import os
import pkgutil
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence

HERE = Path(__file__).resolve().parent
#: Where the figures of the last run go (one entry per module).
LAST_JSON = HERE / "last.json"
#: Exit status of a bench module that ran but missed a target.
MISSED_STATUS = 3


def bench_modules() -> list[str]:
    """Names of the bench modules (``benchmarks.bench_*``), sorted."""
    return sorted(f"benchmarks.{m.name}" for m in pkgutil.iter_modules([str(HERE)])
                  if m.name.startswith("bench_"))


def machine() -> str:
    """The machine in one line: CPU model, cores, OS, Python."""
    model = platform.processor() or platform.machine()
    try:
        model = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    system = f"{platform.system()} {platform.release()}"
    return f"{model}, {os.cpu_count()} cores, {system}, Python {platform.python_version()}"


def _load() -> float:
    return round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else float("nan")


def run_one(name: str, out: Path | None = None) -> int:
    """Run one bench module in this process, print its lines, its misses or its one error line,
    and write its entry for last.json to ``out``."""
    from benchmarks import targets

    entry: dict[str, Any] = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                             "machine": machine(), "load": [_load()]}
    start = time.perf_counter()
    try:
        speed = targets.SPEED_MS = targets.machine_speed()
        targets.RESAMPLE = True
        lines = importlib.import_module(name).run()
        short = name.split(".")[-1].removeprefix("bench_")
        lines.append("the machine's speed: a fixed pure-Python workload took "
                     + targets.figure(f"{short}.machine_reference_ms", min(speed, targets.machine_speed()), "ms",
                                      anchor="the sum of 2.5 million integers; the other CPU figures move with it",
                                      what="machine speed: fixed pure-Python workload, CPU"))
        status = "ok"
    except Exception as exc:  # noqa: BLE001 -- one line, the other benches still run
        text = str(exc).strip()
        lines, status = [f"error: {type(exc).__name__}: {text.splitlines()[0] if text else ''}"], "failed"
    for line in lines:
        print(f"   {line}", flush=True)
    entry["seconds"] = round(time.perf_counter() - start, 1)
    print(f"   ({entry['seconds']:.1f} s)", flush=True)
    missed = targets.missed()
    for miss in missed:
        print(f"   TARGET MISSED: {miss}", flush=True)
    if status == "ok" and missed:
        status = "missed"
    entry.update(status=status, figures=targets.FIGURES)
    entry["load"].append(_load())
    if out is not None:
        out.write_text(json.dumps(entry))
    return {"ok": 0, "missed": MISSED_STATUS}.get(status, 1)


def write_last(entries: dict[str, dict[str, Any]], path: Path = LAST_JSON) -> None:
    """Replace the entries of the modules that ran in ``path`` (others are kept)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        data = {}
    modules = data.setdefault("modules", {})
    modules.update(entries)
    data["modules"] = dict(sorted(modules.items()))
    path.write_text(json.dumps(data, indent=1, sort_keys=False) + "\n")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bench modules (all, those named exactly in ``argv``, or else those whose name contains one of
    ``argv``), each in its own process."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["--one"] and len(args) in (2, 3):
        return run_one(args[1], Path(args[2]) if len(args) == 3 else None)
    names = [n for n in bench_modules() if not args or any(w in n for w in args)]
    exact = [n for n in names if n.split(".")[-1] in args]
    names = exact or names     # a module's own name selects it alone (bench_hil, not bench_hil_floor)
    if not names:
        print(f"bench: no bench module matches {' '.join(args)} (known: "
              f"{', '.join(n.split('.')[-1] for n in bench_modules())})", file=sys.stderr)
        return 1
    failed, missed, entries = [], [], {}
    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-") as tmp:
        for name in names:
            print(f"== {name}", flush=True)
            out = Path(tmp) / f"{name}.json"
            rc = subprocess.run([sys.executable, "-m", "benchmarks.bench", "--one", name, str(out)]).returncode
            if out.exists():
                entries[name.split(".")[-1]] = json.loads(out.read_text())
            if rc == MISSED_STATUS:
                missed.append(name)
            elif rc != 0:
                if rc < 0:
                    print(f"   error: the bench process ended by signal {-rc}", flush=True)
                failed.append(name)
    write_last(entries)
    if missed:
        print(f"bench: targets missed in {', '.join(missed)} (see TARGET MISSED above)", flush=True)
    if failed:
        print(f"bench: failed: {', '.join(failed)}", flush=True)
    print(f"bench: figures written to {LAST_JSON.relative_to(HERE.parent)}", flush=True)
    return 1 if (missed or failed) else 0


if __name__ == "__main__":
    sys.exit(main())
