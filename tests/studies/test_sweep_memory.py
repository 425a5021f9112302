"""Bounded memory over long sweeps: the local pool is replaced after ``workers * recycle_runs``
runs, and a worker process that runs that many co-simulations grows by less than 5 MB (so a
sweep of 2000 runs, or any number, never has a worker larger than that)."""
from __future__ import annotations

import itertools
import subprocess
import sys
import textwrap
import tracemalloc
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from ssd_helpers import component, connection, connector, ssd, write_scenario

from ipcosim.harness.grammar import parse_all
from ipcosim.harness.studies.cases import SweepCase, case_seed, make_cases
from ipcosim.harness.studies.executors import RECYCLE_RUNS, LocalExecutor
from ipcosim.harness.studies.runners import SyntheticSpec, stable_hash
from ipcosim.harness.studies.sweep import plan_hash

DATA = Path(__file__).resolve().parents[1] / "data"


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


# ----------------------------------------------------------------------------- the case stream

NOMINAL = {"plant.Mp": 0.127, "plant.Beq": 4.3}


def _stream_peak(runs: int, iterate: int) -> int:
    """tracemalloc peak [bytes] of making a sweep of ``runs`` runs (a grid of runs/10 points x 10
    random samples), taking its last run by number and iterating its first ``iterate`` runs."""
    varies = parse_all([f"plant.Mp=grid(0.1,0.3,{runs // 10})", "plant.Beq=uniform(4,5)"], NOMINAL)
    tracemalloc.start()
    try:
        cases = make_cases(varies, NOMINAL, samples=10)
        assert len(cases) == runs and cases[runs - 1].index == runs - 1
        assert sum(1 for _ in itertools.islice(cases, iterate)) == iterate
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_making_and_iterating_the_cases_takes_memory_independent_of_the_sweep_size():
    _stream_peak(1000, 100)  # first-call allocations (numpy's generators) out of the way
    small, large = _stream_peak(1_000, 1_000), _stream_peak(100_000, 1_000)
    # a list of 10^5 cases would be ~ 40 MB (a SweepCase, its params dict and two floats, ~ 400 B each);
    # the stream holds one case and each --vary's description, whatever the size
    assert small < 32_000 and large < 32_000, (small, large)
    longer = _stream_peak(20_000, 20_000)  # iterating 20x more runs holds no more of them
    assert longer < 32_000, longer


def test_the_stream_gives_the_runs_of_the_nested_loop_over_grids_and_samples():
    """Run i of a sweep is, by definition, sample i % samples of grid point i // samples, the grid
    points in product order (the last --vary fastest), with its values drawn from the generator
    seeded by case_seed(seed, i): expanded here with the loops themselves."""
    varies = parse_all(["plant.Mp=grid(0.1,0.3,4)", "plant.Beq=[4,5,6]", "plant.K=normal(140,5)"],
                       {**NOMINAL, "plant.K": 140.0})
    cases = make_cases(varies, {**NOMINAL, "plant.K": 140.0}, samples=3, seed=9, fixed={"controller.c1": 2.0})
    expected, i = [], 0
    for mp in np.linspace(0.1, 0.3, 4):
        for beq in (4.0, 5.0, 6.0):
            for _ in range(3):
                seed = case_seed(9, i)
                k = float(np.random.default_rng(seed).normal(140, 5))
                params = {"controller.c1": 2.0, "plant.Mp": float(mp), "plant.Beq": beq, "plant.K": k}
                expected.append((i, seed, params))
                i += 1
    assert len(cases) == 36
    assert [(c.index, c.seed, dict(c.params)) for c in cases] == expected
    assert [(c.index, c.seed, dict(c.params)) for c in (cases[35], cases[-1], cases[17])] == [
        expected[35], expected[35], expected[17]]
    with pytest.raises(IndexError):
        cases[36]


def test_grid_points_taken_one_at_a_time_are_numpys_linspace():
    for start, stop, n in ((0.1, 0.3, 1), (0.1, 0.3, 2), (0.1, 0.3, 1001), (-7.3, 6.9, 4999), (1.0, 1.0 + 1e-12, 77)):
        varies = parse_all([f"plant.Mp=grid({start!r},{stop!r},{n})*nominal"], NOMINAL)
        cases = make_cases(varies, NOMINAL)
        assert [c.params["plant.Mp"] for c in cases] == [float(x) * 0.127 for x in np.linspace(start, stop, n)]


def test_the_plan_hash_is_the_hash_of_the_whole_plan():
    """Fed a case at a time, it is still the stable hash of the spec and every case's index, seed and values."""
    spec = SyntheticSpec()
    cases = make_cases(parse_all(["model.x=uniform(0,2)", "model.y=[1,2]"], spec.parameters), spec.parameters,
                       samples=5, seed=3)
    whole = stable_hash({"spec": spec.key, "cases": [[c.index, c.seed, sorted(c.params.items())] for c in list(cases)]})
    assert plan_hash(spec, cases) == whole == plan_hash(spec, list(cases))
