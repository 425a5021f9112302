"""Sweep engine speed (``make bench``): throughput with 1 and 2 local workers, the scaling
between them, and the per-run overhead of the engine beyond the run itself.

Measured side by side in one process, on the same scenario and cases:

* ``serial``: the run function called in a loop in this process (warmed up, models loaded
  once) -- the co-simulation itself;
* ``sweep, 1 worker`` / ``sweep, 2 workers``: the same cases through :func:`ipcosim.harness.studies.sweep.run_sweep`
  on a warmed-up local pool, writing results.csv as in a real sweep.

Overhead = wall time per run with 1 worker / time of the run itself inside the worker - 1:
everything the engine adds (pickling, inter-process transfer, bookkeeping, the results file).
The same ratio against the serial loop in this process is printed beside it (it also holds
any speed difference between the two processes).
Target: overhead < 5 %. The scaling (1.7x and more on an idle two-core machine) is a reference
figure: it is bounded by the cores other load leaves free.
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from typing import Any

from benchmarks.targets import figure, target

SCENARIO = os.environ.get("IPCOSIM_BENCH_SCENARIO", "single-mass-lqr")
STOP_TIME = float(os.environ.get("IPCOSIM_BENCH_STOP_TIME", "2.0"))
RUNS = int(os.environ.get("IPCOSIM_BENCH_RUNS", "8"))
REPEATS = int(os.environ.get("IPCOSIM_BENCH_REPEATS", "2"))
#: Target: what the engine adds to a run, in % of the run's own time.
OVERHEAD_PCT = 5.0


def _spec() -> Any:
    """The co-simulation of SCENARIO, checked to run here (a bench that cannot run its subject fails)."""
    from ipcosim.harness.studies.specs import spec_for

    spec = spec_for(SCENARIO, stop_time=STOP_TIME)
    spec.build()(dict(), 0)
    return spec


def measure(spec: Any, runs: int = RUNS, repeats: int = REPEATS) -> dict[str, float]:
    """Serial, 1-worker and 2-worker timings of ``runs`` (2 workers: ``2 * runs``) runs.

    The three are measured in turn, ``repeats`` times, on pools kept warm; each figure is the
    best of its repeats (the least disturbed by other load on the machine).
    """
    from ipcosim.harness.api.grammar import parse_all
    from ipcosim.harness.studies.cases import make_cases
    from ipcosim.harness.studies.executors import LocalExecutor
    from ipcosim.harness.studies.sweep import run_sweep

    name = "plant.Mp"
    varies = parse_all([f"{name}=uniform(0.9,1.1)*nominal"], spec.parameters)
    cases = make_cases(varies, spec.parameters, samples=2 * runs + 4, seed=1)
    warm, cases = cases[:4], cases[4:]

    runner = spec.build()
    runner(dict(warm[0].params), warm[0].seed)
    executors = {1: LocalExecutor(1), 2: LocalExecutor(2)}
    best: dict[str, float] = {}
    try:
        for workers, ex in executors.items():
            run_sweep(spec, warm[:workers * 2], executor=ex)  # start processes, load models
        for _ in range(repeats):
            t0 = time.perf_counter()
            for c in cases[:runs]:
                runner(dict(c.params), c.seed)
            best["serial"] = min(best.get("serial", math.inf), (time.perf_counter() - t0) / runs)
            for workers, n in ((1, runs), (2, 2 * runs)):
                with tempfile.TemporaryDirectory() as tmp:
                    t0 = time.perf_counter()
                    result = run_sweep(spec, cases[:n], executor=executors[workers], out=tmp)
                    wall = (time.perf_counter() - t0) / n
                    rows = result.rows  # read back from tmp/results.csv: before the folder goes
                inside = sum(r["run_time_s"] or 0.0 for r in rows) / n
                if wall < best.get(f"w{workers}", math.inf):
                    best[f"w{workers}"], best[f"w{workers}_inside"] = wall, inside
                best[f"w{workers}_errors"] = sum(r["status"] == "error" for r in rows)
    finally:
        for ex in executors.values():
            ex.close()
    out = {"serial_s_per_run": best["serial"], "w1_s_per_run": best["w1"], "w2_s_per_run": best["w2"],
           "w1_run_s": best["w1_inside"], "w2_run_s": best["w2_inside"],
           "w1_runs_per_min": 60.0 / best["w1"], "w2_runs_per_min": 60.0 / best["w2"],
           "w1_errors": best["w1_errors"], "w2_errors": best["w2_errors"]}
    out["scaling"] = out["w2_runs_per_min"] / out["w1_runs_per_min"]
    out["overhead"] = out["w1_s_per_run"] / out["w1_run_s"] - 1.0
    out["overhead_vs_serial"] = out["w1_s_per_run"] / out["serial_s_per_run"] - 1.0
    return out


def run() -> list[str]:
    """Lines for ``make bench``."""
    m = measure(_spec())
    if m["w1_errors"] or m["w2_errors"]:
        raise RuntimeError(f"sweep of {SCENARIO}: {m['w1_errors'] + m['w2_errors']} runs ended in an error")
    load = os.getloadavg()[0]
    return [
        f"sweep engine on co-simulation {SCENARIO}, {STOP_TIME:g} s per run, {RUNS} runs (2 workers: {2 * RUNS}), "
        f"best of {REPEATS}, {os.cpu_count()} cores:",
        f"  serial (the run itself)  {m['serial_s_per_run'] * 1e3:8.1f} ms/run  "
        f"{60 / m['serial_s_per_run']:7.1f} runs/min",
        f"  sweep, 1 worker          {m['w1_s_per_run'] * 1e3:8.1f} ms/run  {m['w1_runs_per_min']:7.1f} runs/min",
        f"  sweep, 2 workers         {m['w2_s_per_run'] * 1e3:8.1f} ms/run  {m['w2_runs_per_min']:7.1f} runs/min",
        "  scaling 2 vs 1 worker    "
        + figure("sweep.scaling", m["scaling"], "x", what="sweep scaling, 2 vs 1 worker",
                 anchor=f"free cores: {os.cpu_count()} cores, load average {load:.1f}")
        + f" (reference: bounded by the cores the machine leaves free, load average {load:.1f})",
        f"  per-run overhead         {100 * m['overhead']:+.1f} % of the run in the worker "
        f"({(m['w1_s_per_run'] - m['w1_run_s']) * 1e3:+.2f} ms; "
        + target("sweep.overhead_pct", 100 * m["overhead"], OVERHEAD_PCT, "%", what="sweep per-run overhead")
        + f"); vs the serial loop {100 * m['overhead_vs_serial']:+.1f} %",
    ]
