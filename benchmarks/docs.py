"""The speed and memory figures of the docs, written from one ``make bench`` run: ``python -m benchmarks.docs``.

Every such figure in ``README.md`` and ``docs/*.md`` sits in a marked block (``devtools.docblocks``)::

    <!-- bench:NAME -->
    (written here)
    <!-- /bench:NAME -->

rendered from ``benchmarks/last.json`` (``make bench`` writes it) as a table of the figures whose keys
:data:`BLOCKS` lists for ``NAME``: what was measured, the figure, its target (and whether it was met)
or, for a reference figure, the anchor it is read against; under it the machine, its load average
and the date of the run. ``--update`` rewrites the blocks; without it the stale blocks are listed
and the exit status is 1. ``tests/project/test_docblocks.py`` checks the committed docs against the
committed JSON, ``tests/project/test_bench_docs.py`` that no speed figure is written anywhere else
(:func:`stray_figures`).
"""
from __future__ import annotations

import difflib
import json
import re
import sys
from pathlib import Path
from typing import Any, Iterator, Sequence

from benchmarks.bench import LAST_JSON
from benchmarks.targets import fmt
from devtools import docblocks

ROOT = Path(__file__).resolve().parents[1]
#: Block name -> the figure keys it shows (a key ending in "." takes every figure of that prefix, in
#: the order the bench recorded them).
BLOCKS: dict[str, tuple[str, ...]] = {
    "headline": ("runtime.native_run_s", "runtime.native_over_fmpy", "runtime.cold_run_cpu_s",
                 "runtime.python_over_libcosim", "master.c_loop_rtf", "native.sweep_ratio"),
    "master-overhead": ("master.c_loop_rtf", "master.c_floor_rtf", "master.c_loop_over_floor",
                        "master.python_loop_rtf", "master.python_floor_rtf", "master.python_loop_over_floor"),
    "master-others": ("master.single_mass_lqr_", "master.double_mass_hsmc_"),
    "runtime": ("runtime.",),
    "native": ("native.",),
    "plant": ("plant.",),
    "controllers": ("controllers.",),
    "sweep": ("sweep.",),
    "hil": ("hil.",),
    "hil-floor-targets": ("hil_floor.target_",),
    "hil-floor": ("hil_floor.quiet_", "hil_floor.loaded_", "hil_floor.2khz_"),
    "identify": ("identify.",),
    "robustness": ("robustness.",),
}
#: A speed or memory figure written as prose: a time in us, a time per step / tick / run / cycle,
#: a memory size, any "Nx" (real-time factors, "Nx faster", ratios of times; other multiples are
#: written "N times").
_N = r"\b\d+(?:[.,]\d+)*"
SPEED = re.compile(
    _N + r"\s?(?:us|µs|μs)\b"
    r"|" + _N + r"\s?(?:ms|s|us)\s?(?:/\s?|per\s)(?:step|tick|run|cycle|sample|call)\b"
    r"|" + _N + r"\s?(?:kB|MB|GB|KiB|MiB|GiB)\b"
    r"|" + _N + r"x\b(?!\.\d)"
    r"|runs?/min",
    re.I)


def load(path: Path = LAST_JSON) -> dict[str, Any]:
    """``benchmarks/last.json`` (one entry per bench module)."""
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise SystemExit(f"{path}: missing (run `make bench`)") from None


def _figures(data: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    for module, entry in data.get("modules", {}).items():
        for key, f in entry.get("figures", {}).items():
            yield module, key, f


def select(data: dict[str, Any], keys: Sequence[str]) -> list[tuple[str, str, dict[str, Any]]]:
    """The figures of ``keys`` (a key ending in ``.`` or ``_`` is a prefix), in the order given."""
    every = list(_figures(data))
    out = []
    for want in keys:
        found = [row for row in every if (row[1].startswith(want) if want[-1] in "._" else row[1] == want)]
        if not found:
            known = [k for _, k, _ in every]
            close = difflib.get_close_matches(want, known, n=1)
            raise KeyError(f"{LAST_JSON.name} has no figure {want!r}"
                           + (f" (closest: {close[0]})" if close else "")
                           + " -- run its bench module (`python -m benchmarks.bench NAME`)")
        out += [row for row in found if row not in out]
    return out


def _unit(value: float | None, unit: str) -> str:
    return fmt(value) + (unit if unit in ("", "x") else f" {unit}")


def render(name: str, data: dict[str, Any]) -> str:
    """The text of block ``name`` (between its markers) from the bench run ``data``."""
    if name not in BLOCKS:
        close = difflib.get_close_matches(name, list(BLOCKS), n=1)
        raise KeyError(f"no bench block {name!r}" + (f" (closest: {close[0]})" if close else ""))
    rows = select(data, BLOCKS[name])
    lines = ["| measured | figure | target, or read against |", "|---|---:|---|"]
    for _, _key, f in rows:
        if "limit" in f:
            op = "<=" if f["at_most"] else ">="
            against = f"{op} {_unit(f['limit'], f['unit'])} ({'met' if f['met'] else '**missed**'})"
            if f.get("speed_factor", 1.0) > 1.0:
                against += (f"; {_unit(f['limit_at_reference'], f['unit'])} at the reference speed,"
                            f" x{f['speed_factor']:.2f} for this machine's")
        else:
            against = f["anchor"] if f.get("anchor") else ""
        lines.append(f"| {f['what']} | {_unit(f['value'], f['unit'])} | {against} |")
    modules = sorted({m for m, _, _ in rows})
    runs = "; ".join(f"`benchmarks/{m}.py` {e['date']}, load average {e['load'][0]:g} at start, "
                     f"{e['load'][-1]:g} at end" for m in modules for e in [data["modules"][m]])
    machines = sorted({data["modules"][m]["machine"] for m in modules})
    lines += ["", f"`make bench` on {', '.join(machines)}: {runs}."]
    return "\n".join(lines) + "\n"


documents = docblocks.documents


def block(name: str) -> str:
    """The text of the block ``bench:<name>`` (``devtools.docblocks``), from the committed bench run."""
    return render(name, load())


def stray_figures(text: str) -> list[tuple[int, str]]:
    """``(line number, figure)`` of every speed or memory figure outside the generated blocks (bench figures,
    the results page's tables: ``devtools.docblocks``), code fences and inline code."""
    found, fence, block = [], False, False
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            fence = not fence
            continue
        if docblocks.OPEN.match(stripped):
            block = True
        elif re.match(r"^<!-- /[\w-]+:[\w-]+ -->$", stripped):
            block = False
            continue
        if fence or block or line.startswith("    "):
            continue
        prose = re.sub(r"`[^`]*`", "", line)
        found += [(n, m.group(0)) for m in SPEED.finditer(prose)]
    return found


def main(argv: Sequence[str]) -> int:
    """``--update``: rewrite the blocks; else list the stale ones (exit status 1 if any)."""
    try:
        stale = docblocks.update(documents(), tools=("bench",), write_back="--update" in argv)
    except docblocks.BlockError as exc:
        print(f"benchmarks.docs: {exc}", file=sys.stderr)
        return 1
    verb = "rewrote" if "--update" in argv else "stale (run with --update)"
    for doc in stale:
        print(f"{verb}: {doc.relative_to(ROOT)}")
    return 0 if ("--update" in argv or not stale) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
