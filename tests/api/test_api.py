"""The public API: one options object behind ``ipcosim run`` and ``ipcosim.run``, the same
one-line errors, relative overrides, baselines, the docstring examples (run as doctests)."""
from __future__ import annotations

import doctest
import importlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

import ipcosim
from ipcosim.harness import cli
from ipcosim.harness.api.options import RunOptions
from ipcosim.harness.testing.baseline import BaselineError, load_baseline, save_baseline


def _cli_options(argv: list[str]) -> RunOptions:
    return RunOptions.from_args(cli.build_parser().parse_args(["run", *argv]))


def test_command_line_and_keywords_build_the_same_options(tmp_path):
    argv = ["single-mass-lqr", "--stop-time", "2", "--step", "0.001", "--set", "plant.Mp=0.2", "--swap",
            "controller=my/C.fmu", "--parameter-set", "tuned", "--out", str(tmp_path), "--record",
            "plant.*,controller.voltage", "--save-baseline", str(tmp_path / "b.csv"), "--quiet"]
    from_keywords = RunOptions.create("single-mass-lqr", stop_time=2.0, step=0.001, set={"plant.Mp": "0.2"},
                                      swap={"controller": "my/C.fmu"}, parameter_set="tuned", out=tmp_path,
                                      record=["plant.*", "controller.voltage"], save_baseline=tmp_path / "b.csv")
    assert _cli_options(argv) == from_keywords


@pytest.mark.parametrize("argv, keywords, message", [
    (["--stop-time", "-1"], {"stop_time": -1}, "--stop-time -1: must be a positive number of seconds"),
    (["--step", "abc"], {"step": "abc"}, "--step 'abc': not a number of seconds"),
    (["--set", "plant.Mp"], {"set": ["plant.Mp"]}, "--set 'plant.Mp': expected COMPONENT.VARIABLE=VALUE"),
    (["--swap", "plant"], {"swap": ["plant"]}, "--swap 'plant': expected COMPONENT=FMU_OR_ALIAS"),
])
def test_python_raises_the_line_the_command_line_prints(capsys, argv, keywords, message):
    assert cli.main(["run", "single-mass-lqr", *argv, "--quiet"]) == 2  # a usage error (docs/robustness.md)
    assert capsys.readouterr().err.strip() == f"ipcosim run: error: {message}"
    with pytest.raises(ipcosim.UsageError) as info:
        ipcosim.run("single-mass-lqr", **keywords)
    assert str(info.value) == message


def test_unknown_scenario_and_missing_fmu_are_project_errors():
    with pytest.raises(ipcosim.IpcosimError, match="unknown scenario 'nope'; known: double-mass"):
        ipcosim.run("nope")
    with pytest.raises(FileNotFoundError, match="--swap controller=missing.fmu: FMU file does not exist"):
        ipcosim.run("single-mass-lqr", swap={"controller": "missing.fmu"})


@pytest.mark.integration
def test_relative_override_scales_the_scenario_value():
    r = ipcosim.run("single-mass-lqr", stop_time=0.002, set={"plant.Mp": "1.25*nominal"})
    with ipcosim.prepare("single-mass-lqr", warn=False) as p:
        bound = float(p.system.instance("plant").start_value("Mp"))
    assert r.metadata["overrides"]["plant.Mp"] == pytest.approx(1.25 * bound)
    with pytest.raises(ipcosim.UsageError, match="plant.nothing=2\\*nominal: expected NUMBER\\*nominal"):
        ipcosim.run("single-mass-lqr", stop_time=0.002, set={"plant.nothing": "2*nominal"})


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("api-run")
    return ipcosim.run("single-mass-lqr", stop_time=1.5, out=out / "run",
                       save_baseline=out / "base.csv", record=["plant.cart_position", "plant.pendulum_angle"])


@pytest.mark.integration
def test_result_data_plot_and_files(short_run):
    r = short_run
    assert r.data.dtype.names[0] == "time" and len(r.data) == 1501
    files = r.metadata["files"]
    header = open(files["results"]).readline().strip().split(",")
    assert header == ["time", "plant.cart_position", "plant.pendulum_angle"]
    assert json.loads(open(files["metrics"]).read())["upright"] is True
    png = r.plot(files["results"].replace("results.csv", "plot.png"))
    assert png.stat().st_size > 10_000
    assert len(r.plot().axes) == 3


@pytest.mark.integration
def test_task_metrics_and_the_plotter_come_from_the_api_not_the_master():
    """The master computes whatever task metrics it is given (the IP02 task's by default), and a
    result draws its figure only through the plotter the API set on it."""
    from ipcosim.errors import UsageError
    from ipcosim.fmus.metrics import METRIC_KEYS
    from ipcosim.harness.api.engine import Prepared

    def count_rows(chunks, names):
        return {"rows_seen": sum(len(c) for c in chunks()), "fields": len(names)}

    with Prepared("single-mass-lqr", warn=False, task_metrics=count_rows) as prepared:
        r = prepared.run(stop_time=0.05)
        assert r.metrics["rows_seen"] == len(r.data) == 51 and r.metrics["fields"] == len(r.columns)
        assert not set(METRIC_KEYS) & set(r.metrics)
        prepared.task_metrics = None
        r = prepared.run(stop_time=0.05)
        assert "wall_time_s" in r.metrics and not set(METRIC_KEYS) & set(r.metrics) and "rows_seen" not in r.metrics
    assert r.plotter is not None
    r.plotter = None
    with pytest.raises(UsageError, match="no plotter"):
        r.plot()


@pytest.mark.integration
def test_baseline_is_thinned_samples_of_the_run(short_run):
    base = load_baseline(short_run.metadata["files"]["baseline"])
    assert base.dtype.names == ("time", "plant.cart_position", "plant.pendulum_angle")
    assert len(base) <= 1001 and base["time"][-1] == pytest.approx(1.5)
    rows = np.searchsorted(short_run["time"], base["time"])
    assert np.allclose(base["plant.pendulum_angle"], short_run["plant.pendulum_angle"][rows], rtol=1e-9, atol=1e-15)
    ipcosim.assert_close_to(short_run, short_run.metadata["files"]["baseline"], tol=1e-9)


@pytest.mark.integration
def test_baseline_mismatch_names_the_column_and_writes_a_difference_plot(short_run, tmp_path):
    base = load_baseline(short_run.metadata["files"]["baseline"])
    base["plant.cart_position"][base["time"] > 1.0] += 0.002
    moved = tmp_path / "moved.csv"
    np.savetxt(moved, np.column_stack([base[c] for c in base.dtype.names]), delimiter=",",
               header=",".join(base.dtype.names), comments="")
    with pytest.raises(ipcosim.CheckFailed) as info:
        ipcosim.assert_close_to(short_run, moved, tol={"plant.cart_position": 1e-3, "plant.pendulum_angle": 1e-3})
    text = str(info.value)
    assert text.startswith("single-mass-lqr: differs from baseline")
    assert re.search(r"plant.cart_position: max \|run - baseline\| = 0.002 at t = 1\.\d+ s \(exceeds tol 0.001\)", text)
    assert re.search(r"plant.pendulum_angle: max \|run - baseline\| = \S+ at t = \S+ s \(ok tol 0.001\)", text)
    plot = text.split("difference plot: ")[1].splitlines()[0].strip()
    assert plot.endswith("baseline-diff.png") and Path(plot).stat().st_size > 10_000
    with pytest.raises(ipcosim.CheckFailed, match="column 'plant.voltage' is not in the baseline"):
        ipcosim.assert_close_to(short_run, moved, columns=["plant.voltage"])
    with pytest.raises(BaselineError, match="the first column must be 'time'"):
        load_baseline(short_run.metadata["files"]["metrics"])
    with pytest.raises(ipcosim.UsageError, match="--record plant.nothing: no such variable"):
        save_baseline(short_run, tmp_path / "x.csv", ["plant.nothing"])


def test_cases_span_plants_times_values():
    params = ipcosim.cases(vary={"plant.Mp": "[0.8,1.2]*nominal", "plant.Lp": [0.3, 0.35]})
    cases = [p.values[0] for p in params]
    assert len(cases) == 8 and {c.plant for c in cases} == {"single-mass", "double-mass"}
    assert cases[0].set == {"plant.Mp": "0.8*nominal", "plant.Lp": 0.3}
    assert cases[0].scenario("lqr") == "single-mass-lqr"
    with pytest.raises(ipcosim.UsageError, match="random forms make tests flaky"):
        ipcosim.cases(vary={"plant.Mp": "uniform(0.1,0.2)"})
    with pytest.raises(ipcosim.UsageError, match="unknown plant 'triple-mass'"):
        ipcosim.cases(plants=["triple-mass"])


@pytest.mark.integration
@pytest.mark.parametrize("module", ["ipcosim.harness.api.public", "ipcosim.harness.testing"])
def test_docstring_examples_run(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS, verbose=False)
    assert result.attempted > 5 and result.failed == 0
