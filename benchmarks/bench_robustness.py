"""Robustness study speed (``make bench``): one 200-run lab robustness row on the native flavour, two workers.

The row is the ``all together`` cell of ``docs/results.md``'s robustness table for the thesis's
double-mass LQR (``ipcosim.harness.studies.robustness.factor_cases``: masses, dampings, spring,
pendulum length, Kt and Ra drawn, the lab bench with its friction drawn, one more sample of delay),
15 s per run, through the sweep engine on a warmed-up pool of two local workers (processes started,
FMUs loaded). Its wall time, the least disturbed of ``ROUNDS`` rounds of the same row, is the
figure (a wall time over two processes is the one figure here that other load on the machine's two
cores stretches whole: 9.1 s in one run at load 4.7 against 3.3 s quiet); the issue's target is
30 s. The CPU time of the runs themselves (summed in the workers) is printed beside it: the part
of the wall time the engine does not add.
"""
from __future__ import annotations

import time

from benchmarks.targets import target

SCENARIO = "double-mass-lqr"
RUNS = 200
STOP_TIME = 15.0
WORKERS = 2
#: Target: wall time of the row on two workers, at the reference machine speed
#: (``targets.REFERENCE_SPEED_MS``; scaled on a slower machine): 2.69-3.32 s there in two runs
#: (3.29 s at 28.1 ms, 3.85 s at 26.8 ms: a wall time over two processes moves more than the CPU
#: figures), the limit a third above the slower; the issue's own limit, 30 s, is far above.
LIMIT_S = 4.4
#: Rounds of the row; the fastest counts, as the other benches take their least disturbed rounds.
ROUNDS = 2


def measure() -> dict[str, float]:
    """Wall time [s] of the row, the runs' own time summed [s] and the row's success rate."""
    from ipcosim.harness.studies import robustness as rob
    from ipcosim.harness.studies.executors import LocalExecutor
    from ipcosim.harness.studies.specs import for_executor, spec_for
    from ipcosim.harness.studies.sweep import run_sweep

    factors = tuple(rob.FACTORS)
    ex = LocalExecutor(WORKERS)
    try:
        spec = for_executor(spec_for(SCENARIO, stop_time=STOP_TIME, fmus="native"), ex)
        cases = rob.factor_cases(spec, "double-mass", factors, RUNS + 2 * WORKERS, seed=1)
        run_sweep(spec, cases[:2 * WORKERS], executor=ex)  # start the workers, load the FMUs
        walls = []
        for _ in range(ROUNDS):
            t0 = time.perf_counter()
            result = run_sweep(spec, cases[2 * WORKERS:], executor=ex)
            walls.append(time.perf_counter() - t0)
        wall = min(walls)
    finally:
        ex.close()
    errors = sum(r["status"] == "error" for r in result.rows)
    if errors:
        raise RuntimeError(f"{errors} of {RUNS} robustness runs failed (status error)")
    summary = rob.summarize(result.rows, ())
    return {"wall_s": wall, "runs_s": sum(r["run_time_s"] or 0.0 for r in result.rows),
            "success": summary["success_rate"]}


def run() -> list[str]:
    """Lines for ``make bench``."""
    m = measure()
    verdict = target("robustness.lab_200_runs_s", m["wall_s"], LIMIT_S, "s",
                     what=f"{RUNS}-run lab robustness row, native flavour, {WORKERS} workers", per_speed=True)
    return [f"robustness row ({SCENARIO}, every factor, lab bench, {RUNS} runs x {STOP_TIME:g} s, native, "
            f"{WORKERS} workers):",
            f"  wall time {m['wall_s']:6.1f} s, the faster of {ROUNDS} rounds ({verdict}); "
            f"the runs themselves {m['runs_s']:.1f} s of CPU; "
            f"success {100 * m['success']:.1f} %"]


if __name__ == "__main__":
    print("\n".join(run()))
