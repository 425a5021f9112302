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

from ipcosim.harness.api.grammar import parse_all
from ipcosim.harness.studies.cases import SweepCase, case_seed, make_cases
from ipcosim.harness.studies.executors import RECYCLE_RUNS, LocalExecutor
from ipcosim.harness.studies.runners import SyntheticSpec, stable_hash
from ipcosim.harness.studies.sweep import plan_hash

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.mark.slow
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


@pytest.mark.slow
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


# ----------------------------------------------------------------------------- the rows and the summary


class _InProcessRuns:
    """An executor that makes each run's row at once in this process (a cheap stand-in for a pool): metrics
    drawn from the run's seed, every 50th run an error, the others ok/fell/unsettled/hunting in turn."""

    description = "in-process rows"

    def run(self, spec, cases):
        for c in cases:
            rng = np.random.default_rng(c.seed)
            status = "error" if c.index % 50 == 0 else ("ok", "fell", "unsettled", "hunting")[c.index % 4]
            metrics = {} if status == "error" else {"value": float(rng.normal(1.0, 0.3)), "upright": status == "ok",
                                                    "settling_time_s": float(rng.exponential())}
            yield {"index": c.index, "seed": c.seed, "status": status, "success": status == "ok",
                   "error": "RunFailure: made up" if status == "error" else "", "params": dict(c.params),
                   "metrics": metrics, "run_time_s": 0.001}

    def abort(self):
        pass

    def close(self):
        pass


def _sweep_peak(tmp_path: Path, runs: int) -> tuple[int, dict]:
    """tracemalloc peak [bytes] of a sweep of ``runs`` in-process runs into a folder, its summary read back and
    the rows its figures would draw, with the sizes held in memory made small (so that a few thousand runs
    are already a large sweep); and the summary."""
    from ipcosim.harness.studies import columns, robustness, robustness_figures, store, sweep
    from ipcosim.harness.studies.sweep import run_sweep

    spec = SyntheticSpec()
    cases = make_cases(parse_all(["model.x=uniform(0,2)"], spec.parameters), spec.parameters, samples=runs, seed=4)
    out = tmp_path / str(runs)
    sizes = [(store, "SORT_CHUNK"), (robustness_figures, "FIGURE_RUNS"), (columns, "ROW_BLOCK"), (columns, "CHUNK"),
             (sweep, "RECORDED_SEEDS"), (store, "MERGE_FILES")]
    saved = [getattr(module, name) for module, name in sizes]
    for module, name in sizes:
        setattr(module, name, 8 if name == "MERGE_FILES" else 64)
    tracemalloc.start()
    try:
        result = run_sweep(spec, cases, out=out, executor=_InProcessRuns())
        summary = robustness.summarize_results(result.path, spec.metric_names, limit=64)
        drawn, total = robustness_figures.figure_rows(result.path)
        assert (len(drawn), total) == (64, runs) and result.counts["error"] == runs // 50
        return tracemalloc.get_traced_memory()[1], summary
    finally:
        tracemalloc.stop()
        for (module, name), value in zip(sizes, saved):
            setattr(module, name, value)


@pytest.mark.slow
def test_a_sweeps_memory_does_not_grow_with_its_runs(tmp_path):
    """Eight times the runs, the same peak, once what is held by the chunk or by the number (rows sorted or read
    at a time, values summarized at a time, runs drawn in the figures, seeds listed in the metadata) is made
    64, and sorted chunks merged 8 at a time: held in memory, 2800 more rows would take over 1.6 MB (about
    0.6 kB a row of this sweep's 11 columns); the runs done are one bit each (350 bytes more)."""
    _sweep_peak(tmp_path / "warm", 100)  # first-call allocations out of the way
    small, _ = _sweep_peak(tmp_path, 400)
    large, summary = _sweep_peak(tmp_path, 3200)
    assert large < small + 64_000, (small, large)
    # the summary read back in passes is the one of the rows held in memory, to the last bits of the sums
    from ipcosim.harness.studies.robustness import summarize
    from ipcosim.harness.studies.store import read_results

    held = summarize(read_results(tmp_path / "3200" / "results.csv")[1], SyntheticSpec().metric_names)
    assert summary["counts"] == held["counts"] and summary["runs"] == held["runs"] == 3200
    for name, s in held["metrics"].items():
        assert summary["metrics"][name] == pytest.approx(s, rel=1e-12, abs=1e-15), name


def test_order_statistics_found_in_passes_are_the_sorted_values():
    """Ranks of values with many ties, a heavy tail, one value: each equals the sorted array's element, with
    at most 40 values held at once (of 6001)."""
    from ipcosim.harness.studies.columns import order_statistic

    rng = np.random.default_rng(2)
    for x in (np.round(rng.normal(size=6001), 1), rng.standard_cauchy(6001), np.r_[np.ones(5990), rng.random(11)],
              np.full(6001, -3.5)):
        def chunks(x=x):
            return (x[i:i + 250] for i in range(0, x.size, 250))
        ordered = np.sort(x)
        for k in (0, 1, 299, 3000, 5700, 6000):
            assert order_statistic(chunks, k, limit=40) == ordered[k]
        with pytest.raises(IndexError):
            order_statistic(chunks, 6001, limit=40)


def test_a_distribution_from_passes_is_numpys():
    """Mean, std, min, percentiles (linear interpolation) and median from passes over chunks against numpy's
    functions of the whole array: equal to rounding (the sums are exactly rounded, numpy's pairwise)."""
    from ipcosim.harness.studies.columns import distribution

    rng = np.random.default_rng(3)
    for x in (rng.normal(2.0, 0.5, size=5000), rng.exponential(size=5001), np.r_[np.zeros(4000), np.ones(7)]):
        def chunks(x=x):
            return (x[i:i + 333] for i in range(0, x.size, 333))
        expected = {"n": x.size, "mean": np.mean(x), "std": np.std(x), "min": np.min(x),
                    "p5": np.percentile(x, 5), "median": np.median(x), "p90": np.percentile(x, 90),
                    "p95": np.percentile(x, 95), "max": np.max(x)}
        assert distribution(chunks, limit=100) == pytest.approx(expected, rel=1e-13, abs=1e-15)


def test_results_sorted_in_chunks_keep_each_rows_text(tmp_path):
    """300 rows shuffled, one twice, a line without an index and a half-written last line, sorted two rows at
    a time (150 chunks: merged in rounds): every index once, in order, the first of the twice-written row, and
    each line byte for byte as written (a float's text is not read and written again)."""
    from ipcosim.harness.studies.store import sort_results

    rng = np.random.default_rng(5)
    lines = [f"{i},{i * 7},ok,true,,{1.0 / (i + 3)!r},3\r\n".encode() for i in range(300)]
    order = rng.permutation(300)
    body = [lines[i] for i in order]
    body.insert(40, b"17,0,fell,false,,0.5,4\r\n")  # after or before the first row 17: only the earlier stays
    first_17 = min(body.index(lines[17]), 40)
    body.insert(100, b"not a row\r\n")
    path = tmp_path / "results.csv"
    path.write_bytes(b"index,seed,status,success,error,x,n\r\n" + b"".join(body) + b"250,1,o")
    sort_results(path, keep=lambda i: i != 13, chunk=2)
    expected = [body[first_17] if i == 17 else lines[i] for i in range(300) if i != 13]
    assert path.read_bytes() == b"index,seed,status,success,error,x,n\r\n" + b"".join(expected)
