"""The sweep engine: --vary grammar, cases, local pool and Dask executors, incremental results,
resume after interruption, failures recorded, clear errors. Uses cheap run functions (an
analytic function and the pure-Python plant loop) -- no FMUs."""
from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from ipcosim.harness.api.grammar import VaryError, parse_all, parse_vary
from ipcosim.harness.cli import main as cli_main
from ipcosim.harness.studies.cases import SweepCase, case_seed, make_cases
from ipcosim.harness.studies.executors import DaskExecutor, SchedulerError
from ipcosim.harness.studies.robustness import summarize, wilson_interval
from ipcosim.harness.studies.runners import PurePlantSpec, SyntheticSpec, classify_task
from ipcosim.harness.studies.store import read_results
from ipcosim.harness.studies.sweep import SweepMismatchError, SweepResultsGoneError, run_sweep

ROOT = Path(__file__).resolve().parents[2]
PARAMS = {"plant.Mp": 0.2, "plant.K": 140.0, "controller.c1": 4.7}


def strip_time(rows):
    return [{k: v for k, v in r.items() if k != "run_time_s"} for r in rows]


# ----------------------------------------------------------------------------- grammar


@pytest.mark.parametrize("expr, form, args, relative", [
    ("plant.Mp=uniform(0.8,1.2)*nominal", "uniform", (0.8, 1.2), True),
    ("plant.Mp = nominal * uniform(0.8, 1.2)", "uniform", (0.8, 1.2), True),
    ("plant.Mp=normal(0.2,0.01)", "normal", (0.2, 0.01), False),
    ("plant.K=grid(100,180,5)", "grid", (100.0, 180.0, 5.0), False),
    ("plant.K=[100, 1.2e2,140]", "values", (100.0, 120.0, 140.0), False),
    ("controller.c1=3.5", "values", (3.5,), False),
])
def test_parse_vary_forms(expr, form, args, relative):
    v = parse_vary(expr, PARAMS)
    assert (v.form, v.args, v.relative) == (form, args, relative)


@pytest.mark.parametrize("expr, fragment", [
    ("plant.Mp", "expected COMPONENT.VARIABLE=FORM"),
    ("plant.Mp=", "expected COMPONENT.VARIABLE=FORM"),
    ("Mp=uniform(0.8,1.2)", "is not a COMPONENT.VARIABLE name"),
    ("plant.Mp=unifrm(0.8,1.2)", "unknown form 'unifrm'"),
    ("plant.Mp=uniform(0.8)", "uniform takes 2 arguments, got 1"),
    ("plant.Mp=uniform(1.2,0.8)", "needs a < b"),
    ("plant.Mp=normal(1,0)", "needs std > 0"),
    ("plant.Mp=grid(1,2,2.5)", "whole n"),
    ("plant.Mp=uniform(a,1)", "'a' is not a number"),
    ("plant.Mp=uniform(0.8,1.2)*nominal*2", "'nominal' may only multiply"),
    ("plant.Mp=[]", "list of values is empty"),
    ("plant.Mp=[1,,2]", "empty argument"),
    ("plant.Mp=uniform(0.8,1.2", "malformed form"),
    ("plant.Mp=__import__('os')", "unknown form '__import__'"),
    ("plant.Mp=nan", "not a finite number"),
    ("plant.Mx=uniform(0.8,1.2)*nominal", "unknown parameter 'plant.Mx'; did you mean 'plant.Mp'?"),
    ("pump.Mp=1", "unknown parameter 'pump.Mp'; known: controller.c1, plant.K, plant.Mp"),
])
def test_bad_vary_is_one_clear_line(expr, fragment):
    with pytest.raises(VaryError) as info:
        parse_vary(expr, PARAMS)
    message = str(info.value)
    assert fragment in message
    assert "\n" not in message and repr(expr) in message
    assert isinstance(info.value, ValueError)


def test_vary_twice_is_an_error():
    with pytest.raises(VaryError, match="varied twice"):
        parse_all(["plant.Mp=1", "plant.Mp=2"], PARAMS)


def test_cases_grid_product_and_relative_values():
    varies = parse_all(["plant.K=grid(0.5,1.5,3)*nominal", "plant.Mp=[0.1,0.3]"], PARAMS)
    cases = make_cases(varies, PARAMS)
    assert len(cases) == 6
    assert [c.index for c in cases] == list(range(6))
    assert {(c.params["plant.K"], c.params["plant.Mp"]) for c in cases} == {
        (k, m) for k in (70.0, 140.0, 210.0) for m in (0.1, 0.3)}


def test_cases_random_samples_reproducible_and_in_range():
    varies = parse_all(["plant.Mp=uniform(0.8,1.2)*nominal", "plant.K=normal(140,5)"], PARAMS)
    a = make_cases(varies, PARAMS, samples=400, seed=7)
    b = make_cases(varies, PARAMS, samples=400, seed=7)
    c = make_cases(varies, PARAMS, samples=400, seed=8)
    assert a == b and a != c
    mp = np.array([x.params["plant.Mp"] for x in a])
    k = np.array([x.params["plant.K"] for x in a])
    assert mp.min() >= 0.16 and mp.max() <= 0.24
    assert abs(mp.mean() - 0.2) < 0.004             # 5 sigma of the sample mean
    assert abs(k.mean() - 140) < 5 * 5 / 20 and 4.2 < k.std() < 5.8
    # a run's values depend only on (seed, index): the same case in a longer sweep is identical
    longer = make_cases(varies, PARAMS, samples=500, seed=7)
    assert longer[:400] == a
    assert a[3].seed == case_seed(7, 3)
    assert len({x.seed for x in a}) == 400


def test_samples_default_and_fixed_values():
    varies = parse_all(["plant.Mp=uniform(0.8,1.2)*nominal"], PARAMS)
    assert len(make_cases(varies, PARAMS)) == 100
    grid = parse_all(["plant.K=[1,2]"], PARAMS)
    cases = make_cases(grid, PARAMS, samples=3, fixed={"controller.c1": 5.0})
    assert len(cases) == 6 and all(c.params["controller.c1"] == 5.0 for c in cases)
    with pytest.raises(VaryError):
        make_cases(varies, PARAMS, samples=0)


# ----------------------------------------------------------------------------- local executor


def test_local_sweep_rows_failures_recorded_and_file_written(tmp_path):
    spec = SyntheticSpec(fail_above=1.5)
    cases = make_cases(parse_all(["model.x=[0.5,1,2,1.25]", "model.y=[2,2.5]"], spec.parameters), spec.parameters)
    result = run_sweep(spec, cases, out=tmp_path, workers=2)
    assert len(result.rows) == 8
    for row in result.rows:
        x, y = row["model.x"], row["model.y"]
        if x > 1.5:
            assert row["status"] == "error" and row["success"] is False
            assert "RunFailure" in row["error"] and "model.x = 2" in row["error"]
            assert row["value"] is None
        else:
            assert row["error"] == ""
            assert row["value"] == pytest.approx((x - 1) ** 2 + (y - 2) ** 2, abs=1e-15)
            assert row["status"] == classify_task({"upright": row["upright"],
                                                   "settling_time_s": row["settling_time_s"]})
    assert result.counts["error"] == 2
    columns, on_disk = read_results(tmp_path / "results.csv")
    assert columns[:5] == ["index", "seed", "status", "success", "error"]
    assert strip_time(on_disk) == strip_time(result.rows)
    assert [r["index"] for r in on_disk] == list(range(8))
    meta = (tmp_path / "metadata.json").read_text()
    assert spec.key in meta and "numpy" in meta and str(cases[0].seed) in meta


def test_closing_one_pool_while_another_lives_returns(tmp_path):
    """Two local pools share multiprocessing's resource tracker, whose pipe every worker holds: closing
    the first while the second's workers live must not wait for that tracker to end (it never would)."""
    script = textwrap.dedent("""
        from ipcosim.harness.api.grammar import parse_all
        from ipcosim.harness.studies.cases import make_cases
        from ipcosim.harness.studies.executors import LocalExecutor
        from ipcosim.harness.studies.runners import SyntheticSpec
        from ipcosim.harness.studies.sweep import run_sweep

        if __name__ == "__main__":
            spec = SyntheticSpec()
            cases = make_cases(parse_all(["model.x=[0.5,1]"], spec.parameters), spec.parameters)
            one, two = LocalExecutor(1), LocalExecutor(2)
            for ex in (one, two):
                assert len(run_sweep(spec, cases, executor=ex).rows) == 2
            one.close()
            assert len(run_sweep(spec, cases, executor=two).rows) == 2
            two.close()
            print("closed")
    """)
    (tmp_path / "two_pools.py").write_text(script)
    done = subprocess.run([sys.executable, str(tmp_path / "two_pools.py")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "closed", done.stderr


def test_worker_crash_is_recorded_not_fatal(tmp_path):
    spec = SyntheticSpec(crash_above=1.5, delay_s=0.02)
    cases = make_cases(parse_all(["model.x=[1,1.1,3,1.2,1.3]"], spec.parameters), spec.parameters)
    result = run_sweep(spec, cases, workers=2)
    status = {r["model.x"]: r["status"] for r in result.rows}
    assert status[3.0] == "error"
    assert all(status[x] != "error" for x in (1.0, 1.1, 1.2, 1.3))
    assert "worker process died" in next(r["error"] for r in result.rows if r["model.x"] == 3.0)


def test_finished_sweep_is_not_redone(tmp_path):
    calls = tmp_path / "calls"
    calls.mkdir()
    spec = SyntheticSpec(calls_dir=str(calls))
    cases = make_cases(parse_all(["model.x=uniform(0,2)"], spec.parameters), spec.parameters, samples=6, seed=1)
    first = run_sweep(spec, cases, out=tmp_path / "out", workers=2)
    assert len(list(calls.iterdir())) == 6
    again = run_sweep(spec, cases, out=tmp_path / "out", workers=2)
    assert len(list(calls.iterdir())) == 6 and again.resumed == 6
    assert strip_time(again.rows) == strip_time(first.rows)
    # a different sweep in the same folder is refused ...
    other = make_cases(parse_all(["model.x=uniform(0,2)"], spec.parameters), spec.parameters, samples=6, seed=2)
    with pytest.raises(SweepMismatchError, match="different sweep"):
        run_sweep(spec, other, out=tmp_path / "out")
    # ... unless asked to start afresh
    fresh = run_sweep(spec, other, out=tmp_path / "out", resume=False, workers=1)
    assert fresh.resumed == 0 and len(list(calls.iterdir())) == 12


def test_rows_of_a_sweep_whose_folder_was_removed_is_one_clear_error(tmp_path):
    """A sweep with an output folder holds no rows: they are read back from its results.csv, so once
    the folder is gone asking for them is a project error naming the file, not a raw FileNotFoundError."""
    import shutil

    from ipcosim.errors import IpcosimError

    spec = SyntheticSpec()
    cases = make_cases(parse_all(["model.x=[0.5,1.5]"], spec.parameters), spec.parameters)
    out = tmp_path / "out"
    result = run_sweep(spec, cases, out=out, workers=1)
    assert [r["model.x"] for r in result.rows] == [0.5, 1.5]  # read from the file while it is there
    shutil.rmtree(out)
    with pytest.raises(SweepResultsGoneError) as caught:
        _ = result.rows
    assert isinstance(caught.value, IpcosimError)
    message = str(caught.value)
    assert str(out / "results.csv") in message and "folder is gone" in message
    assert len(message.splitlines()) == 1


@pytest.mark.slow
def test_interrupted_sweep_resumes_without_redoing_finished_runs(tmp_path):
    out, calls1, calls2 = tmp_path / "out", tmp_path / "c1", tmp_path / "c2"
    calls1.mkdir()
    calls2.mkdir()
    script = textwrap.dedent(f"""
        import signal
        import sys
        from ipcosim.harness.studies.sweep import run_sweep
        from ipcosim.harness.api.grammar import parse_all
        from ipcosim.harness.studies.cases import make_cases
        from ipcosim.harness.studies.runners import SyntheticSpec
        if __name__ == "__main__":
            # Ctrl-C as a terminal delivers it, even when this test runs under a shell's background job
            # (which starts its children with SIGINT ignored)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            spec = SyntheticSpec(delay_s=0.3, calls_dir={str(calls1)!r})
            cases = make_cases(parse_all(["model.x=uniform(0,2)"], spec.parameters), spec.parameters,
                               samples=24, seed=5)
            try:
                run_sweep(spec, cases, out={str(out)!r}, workers=2)
            except KeyboardInterrupt:
                sys.exit(130)
            sys.exit(0)
        """)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT)
    results = out / "results.csv"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if results.exists() and len(results.read_text().splitlines()) >= 1 + 4:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    # simulate a kill in the middle of writing a row: a half line at the end
    with open(results, "a") as fh:
        fh.write("15,123,ok,tr")
    _, saved = read_results(results)
    assert 4 <= len(saved) < 24
    saved_seeds = {r["seed"] for r in saved}

    spec = SyntheticSpec(delay_s=0.3, calls_dir=str(calls2))  # the same sweep (calls_dir is no part of it)
    cases = make_cases(parse_all(["model.x=uniform(0,2)"], spec.parameters), spec.parameters, samples=24, seed=5)
    result = run_sweep(spec, cases, out=out, workers=2)
    rerun_seeds = {int(p.name.split(".")[0]) for p in calls2.iterdir()}
    assert result.resumed == len(saved)
    assert rerun_seeds.isdisjoint(saved_seeds)
    assert len(rerun_seeds) == 24 - len(saved)
    _, final = read_results(results)
    assert [r["index"] for r in final] == list(range(24))
    assert all(r["value"] == pytest.approx((r["model.x"] - 1) ** 2) for r in final)


# ----------------------------------------------------------------------------- dask


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_rows_as_the_process_pool(tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = PurePlantSpec(stop_time=2.0)
    cases = list(make_cases(parse_all(["plant.Mp=uniform(0.8,1.2)*nominal", "plant.Beq=[9,14]"], spec.parameters),
                            spec.parameters, samples=2, seed=11))
    cases.append(SweepCase(index=len(cases), params={"plant.Mp": -1.0}, seed=1))  # an invalid value: an error row
    local = run_sweep(spec, cases, workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        executor = DaskExecutor(cluster.scheduler_address)
        try:
            assert "2 workers" in executor.description
            on_dask = run_sweep(spec, cases, executor=executor, out=tmp_path)
        finally:
            executor.close()
    assert strip_time(on_dask.rows) == strip_time(local.rows)
    assert on_dask.rows[-1]["status"] == "error" and "Mp" in on_dask.rows[-1]["error"]
    assert sum(r["status"] != "error" for r in on_dask.rows) >= 1  # runs completed (2 s: too short to succeed)
    _, on_disk = read_results(tmp_path / "results.csv")
    assert strip_time(on_disk) == strip_time(local.rows)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_is_one_clear_line(capsys, tmp_path):
    address = f"tcp://127.0.0.1:{_closed_port()}"
    with pytest.raises(SchedulerError, match=f"cannot reach the Dask scheduler at {address}"):
        DaskExecutor(address, timeout=1)
    code = cli_main(["sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=uniform(0.8,1.2)*nominal",
                     "--samples", "2", "--scheduler", address, "--out", str(tmp_path / "sweep")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1
    assert err[0].startswith("ipcosim sweep: error: cannot reach the Dask scheduler at " + address)
    assert not (tmp_path / "sweep" / "results.csv").exists()  # no run, no row
    with pytest.raises(SchedulerError, match="expected an address like tcp://HOST:PORT"):
        DaskExecutor("localhost:8786")


# ----------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("vary, fragment", [
    ("plant.Mx=uniform(0.8,1.2)*nominal", "unknown parameter 'plant.Mx'"),
    ("plant.Mp=uniform(0.8;1.2)", "is not a number"),
    ("plant.Mp=triangle(1,2)", "unknown form 'triangle'"),
])
def test_cli_bad_vary_exits_nonzero_with_one_line(vary, fragment, capsys, tmp_path):
    code = cli_main(["sweep", "pure:single-mass-lqr", "--vary", vary, "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and fragment in err[0]
    assert err[0].startswith("ipcosim sweep: error: --vary")
    assert not (tmp_path / "results.csv").exists()


@pytest.mark.slow
def test_cli_sweep_writes_results_summary_and_figures(tmp_path, capsys):
    out = tmp_path / "sw"
    code = cli_main(["sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=uniform(0.8,1.2)*nominal",
                     "--vary", "plant.Lp=[0.3371,5]", "--samples", "2", "--stop-time", "0.8", "--workers", "2",
                     "--out", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    _, rows = read_results(out / "results.csv")
    assert len(rows) == 4
    summary = summarize(rows, ["max_abs_angle_rad", "upright"])
    assert f"success rate {100 * summary['success_rate']:.1f} %" in captured.out
    assert (out / "summary.md").read_text().count("| max_abs_angle_rad |") == 1
    assert (out / "figures" / "max_abs_angle_rad.png").stat().st_size > 1000
    assert "metadata.json" in os.listdir(out)


def test_wilson_interval_and_summary():
    lo, hi = wilson_interval(0, 10)
    assert lo == 0 and hi == pytest.approx(0.2775, abs=1e-4)   # textbook value for 0/10
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(1 - hi) and lo < 0.5 < hi
    rows = [{"status": "ok", "m": 1.0}, {"status": "fell", "m": 3.0}, {"status": "error", "m": None}]
    s = summarize(rows, ["m"])
    assert s["success_rate"] == pytest.approx(1 / 3) and s["metrics"]["m"]["mean"] == 2.0
    assert s["counts"] == {"ok": 1, "fell": 1, "error": 1}
    assert math.isnan(wilson_interval(0, 0)[0])


def test_parameter_figure(tmp_path):
    from ipcosim.harness.studies.robustness import plot_parameters

    rows = [{"status": s, "plant.K": k, "itae_position": v} for s, k, v in
            [("ok", 140.0, 0.1), ("fell", 110.0, 30.0), ("error", 100.0, None), ("unsettled", 120.0, 1.0)]]
    path = plot_parameters(rows, ["plant.K", "plant.absent"], "itae_position", tmp_path)
    assert path == tmp_path / "parameters.png" and path.stat().st_size > 5000
    assert plot_parameters(rows, ["plant.absent"], "itae_position", tmp_path / "none") is None


def test_sweep_study_checks_everything_before_it_touches_the_folder(tmp_path):
    from ipcosim.harness.studies.robustness import sweep_study
    from ipcosim.harness.studies.store import RESULTS_FILE

    old = tmp_path / RESULTS_FILE
    old.write_text("index,seed,status\n0,1,ok\n")
    with pytest.raises(VaryError, match="unknown parameter 'plant.Mq'"):
        sweep_study("pure:single-mass-lqr", ["plant.Mq=[1,2]"], out=tmp_path, fresh=True)
    with pytest.raises(VaryError, match="--samples 0"):
        sweep_study("pure:single-mass-lqr", ["plant.Mp=uniform(0.8,1.2)*nominal"], samples=0, out=tmp_path,
                    fresh=True)
    assert old.exists()                                     # a refused study discards nothing
    study = sweep_study("pure:single-mass-lqr", ["plant.Mp=uniform(0.8,1.2)*nominal", "plant.Lp=[0.3,0.4]"],
                        samples=3, seed=4, set={"plant.Beq": 5.0}, out=tmp_path, fresh=True)
    assert not old.exists()
    nominal = study.spec.parameters["plant.Mp"]
    assert study.spec.parameters["plant.Beq"] == 5.0
    assert len(study.cases) == 6 and sorted({c.params["plant.Lp"] for c in study.cases}) == [0.3, 0.4]
    assert all(0.8 * nominal <= c.params["plant.Mp"] <= 1.2 * nominal for c in study.cases)
    assert study.cases == make_cases(parse_all(["plant.Mp=uniform(0.8,1.2)*nominal", "plant.Lp=[0.3,0.4]"],
                                               study.spec.parameters), study.spec.parameters, samples=3, seed=4)
    assert study.metadata == {"vary": ["plant.Mp=uniform(0.8,1.2)*nominal", "plant.Lp=[0.3,0.4]"],
                              "set": {"plant.Beq": 5.0}, "samples": 3, "seed": 4, "parameter_set": None}
    assert study.flavour == "no FMUs (a pure-Python stand-in)"


def test_the_summary_gives_the_residual_amplitude_beside_the_success_rate():
    from ipcosim.harness.studies.robustness import summarize, summary_line, summary_markdown

    # 1, 2, ..., 10 mm: median 5.5 mm, 90th percentile (linear) 1 + 0.9 x 9 = 9.1 mm
    rows = [{"status": "ok" if i <= 3 else "hunting", "cart_peak_to_peak_m": 1e-3 * i} for i in range(1, 11)]
    s = summarize(rows, ["cart_peak_to_peak_m"])
    assert s["metrics"]["cart_peak_to_peak_m"]["p90"] == pytest.approx(9.1e-3)
    for text in (summary_line(s), summary_markdown(s)):
        assert "30.0 %" in text
        assert "median 5.5 mm, 90th percentile 9.1 mm" in text
