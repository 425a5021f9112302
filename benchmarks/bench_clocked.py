"""Clocked controller FMUs (``make bench``): what running the law in FMI 3.0 Event Mode at its clock's ticks
costs the master, on ``single-mass-lqr`` (native setpoint and plant, 10 s at 1 ms: 10 001 ticks of the
law's clock), runs alternating, the least disturbed of each:

* the master's C loop with the clocked LQR (``build/fmus-clocked``, every tick an Event Mode through the
  compiled event calls of ``ipcosim.harness.master.clockstep``) against the same loop with the unclocked
  FMI 2.0 LQR (``build/fmus-native``): target, the clocked run at most 1.2x the unclocked one;
* the same two in the Python loop (``loop="python"``), and the unclocked FMI 3.0 LQR
  (``build/fmus-native-fmi3``, whose ``fmi3DoStep`` is adapted from Python, so it runs in the Python loop):
  reference figures.
"""
from __future__ import annotations

import os
from pathlib import Path

from benchmarks.targets import figure, least_disturbed, target

ROUNDS = int(os.environ.get("IPCOSIM_BENCH_CLOCKED_ROUNDS", "7"))
SCENARIO, STOP = "single-mass-lqr", 10.0
#: Target: a clocked run / the unclocked one, both in the C loop (measured 1.05-1.10x).
CLOCKED_OVER_UNCLOCKED = 1.2


def _loop_seconds(controller: Path | None, loop: str) -> float:
    import ipcosim

    swap = {"controller": str(controller)} if controller is not None else {}
    result = ipcosim.run(SCENARIO, fmus="native", stop_time=STOP, swap=swap, loop=loop)
    if result.error is not None:
        raise RuntimeError(f"{SCENARIO} with {controller}: {result.error}")
    return float(result.metadata["loop_wall_time_s"])


def run() -> list[str]:
    """Lines for ``make bench``."""
    from ipcosim.harness.support.paths import BUILD_DIR

    clocked = Path(BUILD_DIR) / "fmus-clocked" / "LQRSingleMassClocked.fmu"
    fmi3 = Path(BUILD_DIR) / "fmus-native-fmi3" / "LQRSingleMass.fmu"
    for fmu in (clocked, fmi3):
        if not fmu.is_file():
            raise FileNotFoundError(f"{fmu} missing (run `ipcosim build --native --fmi 3`)")
    runs: dict[str, list[float]] = {k: [] for k in ("c fmi2", "c clocked", "py fmi2", "py clocked", "py fmi3")}
    for _ in range(ROUNDS):
        runs["c fmi2"].append(_loop_seconds(None, "auto"))
        runs["c clocked"].append(_loop_seconds(clocked, "auto"))
        runs["py fmi2"].append(_loop_seconds(None, "python"))
        runs["py clocked"].append(_loop_seconds(clocked, "python"))
        runs["py fmi3"].append(_loop_seconds(fmi3, "auto"))
    best = {k: least_disturbed(v) for k, v in runs.items()}
    ratio = best["c clocked"] / best["c fmi2"]
    c_clocked = figure("clocked.c_loop_s", best["c clocked"], "s", what="C loop, 10 s, clocked LQR")
    c_fmi2 = figure("clocked.c_loop_fmi2_s", best["c fmi2"], "s", what="C loop, 10 s, FMI 2.0 LQR")
    verdict = target("clocked.c_over_unclocked", ratio, CLOCKED_OVER_UNCLOCKED, "x",
                     what="C loop: clocked LQR / unclocked FMI 2.0 LQR")
    py = {k: figure(f"clocked.py_loop_{k}_s", best[f"py {k}"], "s", what=f"Python loop, 10 s, {k} LQR")
          for k in ("clocked", "fmi2", "fmi3")}
    over2 = figure("clocked.py_over_fmi2", best["py clocked"] / best["py fmi2"], "x",
                   what="Python loop: clocked / FMI 2.0")
    over3 = figure("clocked.py_over_fmi3", best["py clocked"] / best["py fmi3"], "x",
                   what="Python loop: clocked / FMI 3.0")
    return [f"C loop: clocked LQR {c_clocked}, unclocked FMI 2.0 LQR {c_fmi2}; clocked / unclocked {ratio:.3f}x, "
            f"{verdict}",
            f"Python loop: clocked {py['clocked']}, FMI 2.0 {py['fmi2']}, FMI 3.0 {py['fmi3']}; clocked / FMI 2.0 "
            f"{over2}, clocked / FMI 3.0 {over3}"]
