"""Instantiate and free one FMU again and again with fmpy, as a host looping over runs does.

    python fmpy_instance_cycles.py FMU WARM_UP CYCLES [RSS_WINDOWS]

Each cycle loads the FMU's binary (``FMU2Slave`` on the extracted folder), instantiates, initializes,
steps 5 times, terminates and frees the instance (fmpy's ``freeInstance`` also closes the binary).
After WARM_UP cycles, the growth of the resident memory over CYCLES cycles, RSS_WINDOWS times in a row
(default 1); then, under tracemalloc (after up to 50 cycles more, traced), the growth of the Python heap
(which the FMU's code shares with a Python host) over CYCLES cycles.
Prints one JSON line ``{"rss_per_cycle": B, "rss_windows": [B, ...], "traced_per_cycle": B,
"seconds_per_cycle": s}`` (``rss_per_cycle``: the first window's, right after the warm-up).
"""
from __future__ import annotations

import gc
import json
import sys
import tempfile
import time
import tracemalloc
import zipfile
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave


def rss() -> int:
    return int(Path("/proc/self/statm").read_text().split()[1]) * 4096


def main(fmu: str, warm_up: int, cycles: int, rss_windows: int = 1) -> int:
    md = read_model_description(fmu)
    unzip_dir = tempfile.mkdtemp(prefix="cycles-")
    zipfile.ZipFile(fmu).extractall(unzip_dir)
    count = 0

    def cycle() -> None:
        nonlocal count
        count += 1
        slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"cycle{count}")
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(5):
            slave.doStep(k * 1e-3, 1e-3)
        slave.terminate()
        slave.freeInstance()

    for _ in range(warm_up):
        cycle()
    gc.collect()
    marks, t0 = [rss()], time.perf_counter()
    for _ in range(rss_windows):
        for _ in range(cycles):
            cycle()
        gc.collect()
        marks.append(rss())
    t1 = time.perf_counter()
    tracemalloc.start()
    for _ in range(min(warm_up, 50)):  # what tracing itself starts (caches filled again under it)
        cycle()
    gc.collect()
    m0 = tracemalloc.get_traced_memory()[0]
    for _ in range(cycles):
        cycle()
    gc.collect()
    m1 = tracemalloc.get_traced_memory()[0]
    windows = [(b - a) / cycles for a, b in zip(marks, marks[1:])]
    print(json.dumps({"rss_per_cycle": windows[0], "rss_windows": windows, "traced_per_cycle": (m1 - m0) / cycles,
                      "seconds_per_cycle": (t1 - t0) / (cycles * rss_windows)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], *map(int, sys.argv[2:5])))
