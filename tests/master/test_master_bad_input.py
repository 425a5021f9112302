"""Every bad input of ``ipcosim run``, through the command line with real (small test) FMUs:
one line on stderr naming what and where, a non-zero exit, results up to the failure written,
every FMU instance freed."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from ssd_helpers import component, connection, connector, ssd, write_scenario

from ipcosim.harness import cli

pytestmark = pytest.mark.integration
DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="session")
def test_fmus(tmp_path_factory) -> dict[str, Path]:
    from ipcosim.fmus.pybuild import build_all

    out = tmp_path_factory.mktemp("master-test-fmus")
    results = build_all(out, scripts=[DATA / "fmu_master_source.py", DATA / "fmu_master_gain.py"])
    return {r.fmu.stem: r.fmu for r in results}


SRC = lambda **inline: component("src", "MasterSource", [connector("y", "output")], inline=inline or None)  # noqa: E731
GAIN = component("g", "MasterGain", [connector("u", "input"), connector("aux", "input", "rad"),
                                     connector("y", "output"), connector("z", "output", "rad")])
OK_CONNECTIONS = [connection("src.y", "g.u")]


def scenario(tmp_path, fmus, comps=None, conns=None, name="s", units=""):
    text = ssd(name, comps if comps is not None else [SRC(), GAIN], OK_CONNECTIONS if conns is None else conns,
               units=units)
    return write_scenario(tmp_path / name, text, fmus)


def run_cli(capsys, *argv):
    rc = cli.main(["run", *map(str, argv), "--quiet"])
    err = capsys.readouterr().err
    return rc, [line for line in err.splitlines() if line.strip()]


def read_csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True, deletechars="")


# ------------------------------------------------------------------ good run, for reference
def test_good_run_writes_results_and_metrics(tmp_path, capsys, test_fmus, tracked):
    folder = scenario(tmp_path, test_fmus, comps=[SRC(value=3.0), GAIN],
                      conns=[connection("src.y", "g.u", factor=2.0, offset=1.0)])
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    assert rc == 0
    assert err == ["ipcosim run: warning: " + next(line for line in err if "g.aux" in line).split("warning: ", 1)[1]]
    assert "input g.aux is not connected" in err[0]
    data = read_csv(tmp_path / "out" / "results.csv")
    assert data.dtype.names == ("time", "src.y", "g.u", "g.aux", "g.y", "g.z")
    assert np.all(data["g.u"] == 7.0) and np.all(data["g.y"] == 14.0)  # transformation 2*3+1, gain 2
    assert data["time"][-1] == 1.0 and len(data) == 101
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["wall_time_s"] > 0 and metrics["real_time_factor"] > 0
    made, freed = tracked
    assert len(made) == 2 and set(map(id, freed)) == set(map(id, made))


def test_record_flag_selects_columns(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus)
    rc, _ = run_cli(capsys, folder, "--out", tmp_path / "out", "--record", "g.*", "--record", "src.y")
    assert rc == 0
    header = (tmp_path / "out" / "results.csv").read_text().splitlines()[0]
    assert header == "time,src.y,g.u,g.aux,g.y,g.z"
    rc, _ = run_cli(capsys, folder, "--out", tmp_path / "out2", "--record", "g.y")
    assert (tmp_path / "out2" / "results.csv").read_text().splitlines()[0] == "time,g.y"
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out3", "--record", "g.nothing")
    assert rc == 2 and "--record g.nothing: no such variable" in err[-1]


# ------------------------------------------------------------------ bad input before anything runs
def _one_error_line(err):
    errors = [line for line in err if not line.startswith("ipcosim run: warning:")]
    assert len(errors) == 1, err
    assert errors[0].startswith("ipcosim run: error: ")
    return errors[0]


def test_unknown_scenario_name_and_path(tmp_path, capsys):
    rc, err = run_cli(capsys, "single-mass-nothing")
    assert rc == 2 and "unknown scenario 'single-mass-nothing'" in _one_error_line(err)
    rc, err = run_cli(capsys, tmp_path / "missing.ssp")
    assert rc == 2 and "missing.ssp' does not exist" in _one_error_line(err)


def test_ssp_not_a_zip_or_without_ssd(tmp_path, capsys):
    bad = tmp_path / "bad.ssp"
    bad.write_bytes(b"\x00\x01 not a zip")
    rc, err = run_cli(capsys, bad)
    assert rc == 1 and "bad.ssp: not an SSP archive" in _one_error_line(err)
    empty = tmp_path / "empty.ssp"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("other.txt", "x")
    rc, err = run_cli(capsys, empty)
    assert rc == 1 and "empty.ssp: no SystemStructure.ssd" in _one_error_line(err)


def test_ssd_failing_the_schema(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus)
    path = folder / "SystemStructure.ssd"
    path.write_text(path.read_text().replace("<ssd:Elements>", "<ssd:Elements><ssd:Bogus/>"))
    rc, err = run_cli(capsys, folder)
    line = _one_error_line(err)
    assert rc == 1 and "SystemStructure.ssd:" in line and "fails the SSP 1.0 schema" in line and "Bogus" in line


def test_component_whose_fmu_is_missing(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, {"MasterSource": test_fmus["MasterSource"]})
    rc, err = run_cli(capsys, folder)
    line = _one_error_line(err)
    assert rc == 1 and "component 'g': FMU resources/MasterGain.fmu not found" in line


def test_connection_to_a_variable_the_fmu_does_not_have(tmp_path, capsys, test_fmus):
    comps = [SRC(), component("g", "MasterGain", [connector("u", "input"), connector("w", "input")])]
    folder = scenario(tmp_path, test_fmus, comps=comps, conns=[connection("src.y", "g.w")])
    rc, err = run_cli(capsys, folder)
    line = _one_error_line(err)
    assert rc == 1 and "component 'g' (MasterGain.fmu): connector 'w' is not a variable of the FMU" in line


def test_connecting_two_outputs_or_two_inputs(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus, conns=[connection("src.y", "g.y")], name="oo")
    rc, err = run_cli(capsys, folder)
    assert rc == 1 and "connection src.y -> g.y connects two outputs" in _one_error_line(err)
    folder = scenario(tmp_path, test_fmus, conns=[connection("g.aux", "g.u")], name="ii")
    rc, err = run_cli(capsys, folder)
    assert rc == 1 and "connection g.aux -> g.u connects two inputs" in _one_error_line(err)


def test_mismatched_units(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus, conns=[connection("src.y", "g.aux")])
    rc, err = run_cli(capsys, folder)
    line = _one_error_line(err)
    assert rc == 1 and "connection src.y -> g.aux: unit 'm' does not match 'rad' (mismatched units" in line


def test_ssd_connector_unit_contradicting_the_fmu(tmp_path, capsys, test_fmus):
    comps = [component("src", "MasterSource", [connector("y", "output", "rad")]), GAIN]
    folder = scenario(tmp_path, test_fmus, comps=comps, conns=[])
    rc, err = run_cli(capsys, folder)
    assert rc == 1 and "connector 'y' has unit 'rad' but the FMU variable has 'm'" in _one_error_line(err)


def test_unconnected_input_is_a_warning_and_the_run_goes_on(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus)
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    assert rc == 0 and err == [line for line in err if line.startswith("ipcosim run: warning:")]
    assert len(err) == 1 and "input g.aux is not connected; it keeps its start value 0.0" in err[0]


@pytest.mark.parametrize("setting, expected", [
    ("g.nothing=1", "component 'g' (MasterGain.fmu) has no variable 'nothing'"),
    ("g.gain=fast", "--set g.gain: 'fast' is not a valid Real value"),
    ("g.y=1", "'y' is output/continuous and cannot be set"),
    ("gain=2", "expected COMPONENT.VARIABLE=VALUE"),
    ("q.gain=2", "no component 'q'"),
])
def test_bad_set(tmp_path, capsys, test_fmus, tracked, setting, expected):
    folder = scenario(tmp_path, test_fmus)
    rc, err = run_cli(capsys, folder, "--set", setting)
    assert rc == 2 and expected in _one_error_line(err)  # a command-line mistake
    assert tracked[0] == []  # nothing instantiated


@pytest.mark.parametrize("args, expected, status", [
    (("--stop-time", "0"), "--stop-time 0: must be a positive number of seconds", 2),
    (("--stop-time", "-2"), "--stop-time -2: must be a positive number of seconds", 2),
    (("--stop-time", "soon"), "--stop-time 'soon': not a number", 2),
    (("--step", "0"), "--step 0: must be a positive number of seconds", 2),
    (("--step", "-0.001"), "--step -0.001: must be a positive number of seconds", 2),
    # well-formed values the scenario's FMUs cannot be run with: a failure, not a usage error
    (("--step", "0.004"), "g.sample_period = 0.01 s is not a whole multiple of the step 0.004 s", 1),
    (("--set", "g.sample_period=0.015"), "g.sample_period = 0.015 s is not a whole multiple of the step 0.01 s", 1),
])
def test_bad_times(tmp_path, capsys, test_fmus, tracked, args, expected, status):
    folder = scenario(tmp_path, test_fmus)
    rc, err = run_cli(capsys, folder, *args)
    assert rc == status and expected in _one_error_line(err)
    assert tracked[0] == []


def test_bad_swap(tmp_path, capsys, test_fmus):
    folder = scenario(tmp_path, test_fmus)
    rc, err = run_cli(capsys, folder, "--swap", "g=nothing-here")
    assert rc == 1 and "--swap g=nothing-here: not an .fmu file and not a known alias" in _one_error_line(err)
    rc, err = run_cli(capsys, folder, "--swap", "g=" + str(test_fmus["MasterSource"]))
    assert rc == 1 and "connector 'u' is not a variable of the FMU (swapped-in FMU lacks a connected connector)" \
        in _one_error_line(err)
    rc, err = run_cli(capsys, folder, "--swap", "x=" + str(test_fmus["MasterSource"]))
    assert rc == 1 and "has no component 'x'" in _one_error_line(err)


def test_swap_with_a_compatible_fmu(tmp_path, capsys, test_fmus):
    other = tmp_path / "other" / "MasterSource.fmu"
    other.parent.mkdir()
    other.write_bytes(test_fmus["MasterSource"].read_bytes())
    folder = scenario(tmp_path, test_fmus)
    rc, err = run_cli(capsys, folder, "--swap", f"src={other}", "--set", "src.value=4", "--out", tmp_path / "out")
    assert rc == 0
    data = read_csv(tmp_path / "out" / "results.csv")
    assert np.all(data["g.y"] == 8.0)


# ------------------------------------------------------------------ failures while running
@pytest.mark.parametrize("mode, expected", [
    # pythonfmu reports fmi2Terminated true after any Discard; the error the FMU logged makes it a failure
    (1, "component src (MasterSource): fmi2DoStep returned fmi2Discard at t = 0.5 s: source cannot step from t = 0.5 s "
        "(fmi2GetBooleanStatus(fmi2Terminated) returned fmi2True, but it logged an error in that step: a failure)"),
    (3, "component src (MasterSource): output src.y = nan at t = 0.51 s (non-finite value)"),
])
def test_fmu_failure_writes_results_so_far_and_frees_every_instance(tmp_path, capsys, test_fmus, tracked, mode,
                                                                   expected):
    folder = scenario(tmp_path, test_fmus, comps=[SRC(fail_time=0.5, fail_mode=float(mode)), GAIN])
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out", "--plot")
    line = _one_error_line(err)
    assert rc == 1 and expected in line
    data = read_csv(tmp_path / "out" / "results.csv")
    last = 0.5 if mode != 3 else 0.51
    assert data["time"][-1] == pytest.approx(last, abs=1e-12)
    assert np.all(data["src.y"][data["time"] <= 0.5] == 1.0)
    assert (tmp_path / "out" / "metrics.json").exists() and (tmp_path / "out" / "plot.png").exists()
    made, freed = tracked
    assert len(made) == 2 and set(map(id, freed)) == set(map(id, made))


def test_fmu_raising_an_exception_is_fatal_and_reported_with_its_message(tmp_path, test_fmus):
    # In its own process: pythonfmu 0.7.0 releases objects twice after a Python exception in
    # an FMU (see ipcosim.fmus.fmi), which can corrupt the heap of a process that goes on loading FMUs
    # for a long time, as a test session does; the command line exits right after the run.
    import subprocess
    import sys

    folder = scenario(tmp_path, test_fmus, comps=[SRC(fail_time=0.5, fail_mode=2.0), GAIN])
    proc = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "run", str(folder),
                           "--out", str(tmp_path / "out"), "--quiet"], capture_output=True, text=True, timeout=120)
    errors = [line for line in proc.stderr.splitlines() if line.strip() and "warning:" not in line]
    assert proc.returncode == 1 and len(errors) == 1, proc.stderr
    assert errors[0].startswith("ipcosim run: error: component src (MasterSource): fmi2DoStep returned fmi2Fatal "
                                "at t = 0.5 s: ")
    assert "source exploded at t = 0.5 s" in errors[0]
    data = read_csv(tmp_path / "out" / "results.csv")
    assert data["time"][-1] == 0.5 and len(data) == 51


@pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")
def test_fmu_failure_through_the_api_keeps_the_partial_result(tmp_path, test_fmus):
    import ipcosim.harness

    folder = scenario(tmp_path, test_fmus, comps=[SRC(fail_time=0.2, fail_mode=1.0), GAIN])
    with pytest.raises(ipcosim.SimulationError) as info:
        ipcosim.run(folder)
    assert len(info.value.result.data) == 21 and "fmi2Discard" in str(info.value)
    with ipcosim.prepare(folder) as prepared:
        result = prepared.run(raise_on_error=False)
    assert result.error.startswith("component src (MasterSource): fmi2DoStep returned fmi2Discard")
