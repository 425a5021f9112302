"""Bounded memory over long sweeps: the local pool is replaced after ``workers * recycle_runs``
runs, and a worker process that runs that many co-simulations grows by less than 5 MB (so a
sweep of 2000 runs, or any number, never has a worker larger than that)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest
from ssd_helpers import component, connection, connector, ssd, write_scenario

from ipcosim.harness.studies.cases import SweepCase
from ipcosim.harness.studies.executors import RECYCLE_RUNS, LocalExecutor
from ipcosim.harness.studies.runners import SyntheticSpec

DATA = Path(__file__).resolve().parent / "data"


def test_local_pool_is_replaced_after_its_share_of_runs(tmp_path):
    spec = SyntheticSpec(calls_dir=str(tmp_path))
    executor = LocalExecutor(1, recycle_runs=5)
    try:
        rows = list(executor.run(spec, [SweepCase(index=i, params={"model.x": 1.0}, seed=i) for i in range(12)]))
    finally:
        executor.close()
    assert sorted(r["index"] for r in rows) == list(range(12)) and all(r["status"] == "ok" for r in rows)
    per_process = Counter(p.name.split(".")[1] for p in tmp_path.iterdir())
    assert sorted(per_process.values()) == [2, 5, 5]  # three processes, none ran more than 5


@pytest.mark.integration
def test_worker_memory_growth_over_its_runs(tmp_path):
    """One process runs as many co-simulations (three pythonfmu FMUs each) as a worker of a
    2-worker pool can before it is replaced, and reports its resident memory growth."""
    from ipcosim.fmus.pybuild import build_all

    fmus = {r.fmu.stem: r.fmu for r in build_all(tmp_path / "fmus", scripts=[
        DATA / "fmu_master_source.py", DATA / "fmu_master_gain.py", DATA / "fmu_corpus_fault.py"])}
    gain = component("g", "MasterGain", [connector("u", "input"), connector("y", "output")])
    fault = component("f", "CorpusFault", [connector("u", "input"), connector("y", "output")])
    folder = write_scenario(tmp_path / "s", ssd("s", [component("src", "MasterSource", [connector("y", "output")]),
                                                      gain, fault],
                                                 [connection("src.y", "g.u"), connection("g.y", "f.u")], stop=0.05),
                            fmus)
    runs = 2 * RECYCLE_RUNS
    code = textwrap.dedent(f"""
        import gc, os, warnings
        warnings.simplefilter("ignore")
        import ipcosim as h
        def rss():
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        with h.prepare({str(folder)!r}, warn=False) as p:
            for _ in range(5):
                p.run(raise_on_error=False)
            gc.collect(); r0 = rss()
            for _ in range({runs}):
                assert p.run().ok
            gc.collect(); print(rss() - r0)
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    growth = int(proc.stdout.split()[-1])
    print(f"worker growth over {runs} runs: {growth / 1e6:.2f} MB ({growth / runs / 1e3:.1f} kB/run)")
    assert growth < 5e6
