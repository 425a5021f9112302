"""Identification: the excitation, the estimator on logs with parameters it is not told (plant FMU and
virtual rig), its refusals, and ``--parameter-file``."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ipcosim.controllers.catalog import make_law
from ipcosim.controllers.laws.base import LawParameterError
from ipcosim.controllers.laws.excitation import ExcitationGains, multisine
from ipcosim.fmus.instruments import realism
from ipcosim.fmus.params import DEFAULT_PRESET, preset
from ipcosim.fmus.physics import MEASURED, state_names
from ipcosim.fmus.plant import replay
from ipcosim.harness.studies.identify import IdentifyError, IdentifyOptions, identify, read_log

ROOT = Path(__file__).resolve().parents[2]
#: Hidden truths, away from every preset (the estimator starts from thesis-ch3 / thesis-ch4).
SINGLE_TRUTH = {"Mc": 0.87, "Beq": 13.1, "Bp": 0.0031, "b": 0.072}
DOUBLE_TRUTH = {"Ma": 1.04, "Mc": 0.86, "K": 155.0, "Ba": 7.6, "Bf": 2.6, "b1": 0.065, "b2": 0.14}
#: The tests' logs: 12 s (the scenario's 20 s in the bench) keeps them short.
STOP_TIME = 12.0


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def check_targets(result, truth: dict[str, float], intervals: bool = True) -> None:
    """The accuracy targets of docs/identify.md and, with ``intervals``, each truth inside its 95 % interval
    (deterministic for a given log; how often it holds over seeds is the bench's coverage check)."""
    for name, true in truth.items():
        p = result.parameters[name]
        lo, hi = p["ci95"]
        tol = (0.02 if true < 0.13 else 0.15 * true) if name.startswith("b") and name != "Beq" else (
            0.03 * true if name in ("Mc", "Ma", "K") else 0.10 * true)
        assert abs(p["value"] - true) <= tol, (name, p, true)
        assert lo <= true <= hi or not intervals, (name, p, true)
    assert min(result.fit.values()) >= 0.90, result.fit
    assert result.valid and all(math.isclose(result.fit[k], 1 - result.nrmse[k]) for k in result.nrmse)


# ------------------------------------------------------------------------------------ the excitation

def test_multisine_has_its_peak_and_band():
    g = ExcitationGains(amplitude=2.0, seed=3, band_low=0.5, band_high=4.0, period=4.0)
    u = np.array(multisine(g, 1e-3))
    assert len(u) == 4000 and abs(np.abs(u).max() - 2.0) < 1e-12
    power = np.abs(np.fft.rfft(u)) ** 2
    f = np.fft.rfftfreq(len(u), 1e-3)
    inside = (f >= 0.5 - 1e-9) & (f <= 4.0 + 1e-9)
    assert power[~inside].sum() < 1e-20 * power[inside].sum()
    assert np.count_nonzero(power[inside] > 1e-6 * power.max()) == 15      # 0.5, 0.75, ... 4.0 Hz
    other = np.array(multisine(ExcitationGains(amplitude=2.0, seed=4, band_low=0.5, band_high=4.0, period=4.0), 1e-3))
    assert np.abs(other - u).max() > 0.1


@pytest.mark.parametrize("values, name", [({"band_high": 600.0}, "band_high"), ({"period": 0.0105}, "period"),
                                          ({"seed": 1.5}, "seed")])
def test_excitation_refuses_bad_parameters(values, name):
    with pytest.raises(LawParameterError) as info:
        make_law("single-mass", "Excitation", **values)
    assert name in str(info.value)


def test_weak_hold_pulls_the_cart_back():
    law = make_law("double-mass", "Excitation", amplitude=0.0)
    assert law.step([0.1, 0.0, math.pi], 0.0) == pytest.approx(-2.0)      # 20 V/m on the active cart


# ------------------------------------------------------------------------------------ from the plant FMU

def _identify_run(scenario: str, truth: dict[str, float], out: Path, refits: int | None = None, **run):
    import ipcosim

    values = {f"plant.{k}": v for k, v in truth.items()}
    result = ipcosim.run(scenario, stop_time=STOP_TIME, set={**values, **run.pop("set", {})}, out=out, **run)
    assert not result.error, result.error
    return identify(IdentifyOptions.create(out, plant=scenario.rsplit("-", 1)[0], refits=refits))


@pytest.mark.integration
@pytest.mark.slow
def test_single_mass_hidden_parameters_from_the_plant_fmu(tmp_path):
    result = _identify_run("single-mass-identify", SINGLE_TRUTH, tmp_path / "run")
    check_targets(result, SINGLE_TRUTH)
    assert result.held_out_from_s == pytest.approx(0.75 * STOP_TIME, abs=2e-3)
    assert set(result.largest_residual_counts) == {"cart_position", "pendulum_angle"}


def test_the_true_parameters_explain_every_reading_to_half_a_count(tmp_path):
    """What ``largest_residual_counts`` is read against: the replay of the true parameters on the lab bench
    is the plant FMU's motion, so every encoder reading is its rounding (and a fit stuck in the stick-slip
    roughness is told apart by a larger residual)."""
    import ipcosim

    truth = {"Mc": 0.87, "Beq": 13.1, "Bp": 0.0031, "b": 0.072}
    ipcosim.run("single-mass-identify", stop_time=3.0, set={f"plant.{k}": v for k, v in truth.items()},
                out=tmp_path / "run")
    log = read_log(tmp_path / "run", "single-mass")
    bench = realism("lab", "single-mass")[0]
    names = state_names("single-mass")
    x0 = [log.y[0, MEASURED["single-mass"].index(n)] if n in MEASURED["single-mass"] else 0.0 for n in names]

    def largest_counts(**values):
        sim = np.array(replay(replace(preset("thesis-ch3"), **values), log.voltage[:-1], log.step, x0, bench))
        return np.abs(sim - log.y).max(axis=0) / [bench.cart_resolution, bench.pendulum_resolution]

    assert np.all(largest_counts(**truth) <= 0.5 + 1e-6), largest_counts(**truth)
    # one per cent off in the mass, and the readings are no longer all explained
    off = largest_counts(**{**truth, "Mc": 0.99 * truth["Mc"]})
    assert off[0] > 0.5, off


@pytest.mark.parametrize("kind, truth", [("single-mass", SINGLE_TRUTH), ("double-mass", DOUBLE_TRUTH)])
def test_the_native_replay_is_the_python_replay(kind, truth):
    """The identification's simulation in C (``harness.native.replay``) moves as the Python replay on the lab
    bench: DAC codes, the one-sample delay and the carts sticking and breaking loose."""
    from ipcosim.harness.native.replay import native_replay

    bench, overrides = realism("lab", kind)
    assert bench.voltage_resolution > 0 and bench.input_delay > 0
    params = replace(preset(DEFAULT_PRESET[kind]), **{**overrides, **truth, "amplifier_gain": 0.93})
    t = np.arange(3000) * 1e-3
    voltage = 1.5 * np.sin(2 * np.pi * 0.8 * t) * (t % 1.0 < 0.6)    # bursts and pauses
    x0 = [math.pi if n == "pendulum_angle" else 0.0 for n in state_names(kind)]
    python = np.array(replay(params, voltage, 1e-3, x0, bench))
    native = native_replay(kind)(params, voltage, 1e-3, x0, bench)
    assert native.shape == python.shape == (len(t) + 1, len(MEASURED[kind]))
    assert np.abs(native - python).max() <= 1e-9
    carts = python[:, [i for i, n in enumerate(MEASURED[kind]) if n != "pendulum_angle"]]
    assert np.ptp(carts, axis=0).min() > 0.01                          # they move ...
    assert (np.diff(carts, axis=0) == 0).sum(axis=0).min() > 50        # ... and stick (a stuck cart holds still)


def test_without_a_c_compiler_the_log_is_replayed_in_python(monkeypatch):
    from ipcosim.harness.native.replay import native_replay
    from ipcosim.harness.studies.identify import simulator

    monkeypatch.setenv("CC", "no-such-compiler")
    native_replay.cache_clear()
    try:
        simulate, how = simulator("single-mass")
    finally:
        native_replay.cache_clear()
    assert simulate is replay and how == "python (no C compiler found (set CC, or install gcc or clang))"


@pytest.mark.integration
@pytest.mark.slow
def test_double_mass_hidden_parameters_from_the_plant_fmu(tmp_path):
    # the double mass keeps the targets; its intervals cover the truth in 7 to 9 of 10 seeded logs (docs/identify.md,
    # Figures), so they are not asserted, nor paid for (no refits)
    check_targets(_identify_run("double-mass-identify", DOUBLE_TRUTH, tmp_path / "run", refits=0), DOUBLE_TRUTH,
                  intervals=False)


# ------------------------------------------------------------------------------------ from the virtual rig

@pytest.fixture
def rig():
    """``start(plant, truth) -> card URI`` of a lockstep rig process set up for identification."""
    procs = []

    def start(plant: str, truth: dict[str, float]) -> str:
        sets = [a for k, v in truth.items() for a in ("--set", f"{k}={v}")]
        proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--plant", plant,
                                 "--experiment", "identify", "--clock", "lockstep", "--port", "0", "--duration",
                                 "300", *sets], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                                env=dict(os.environ, PYTHONPATH=str(ROOT)))
        procs.append(proc)
        line = proc.stdout.readline()
        assert "serving" in line, line + proc.stderr.read()
        return f"q4:0@tcpip://127.0.0.1:{int(line.split('127.0.0.1:')[1].split()[0])}"
    yield start
    for p in procs:
        p.terminate()
        p.wait(timeout=30)


@pytest.mark.integration
@pytest.mark.parametrize("plant, truth", [("single-mass", SINGLE_TRUTH), ("double-mass", DOUBLE_TRUTH)])
@pytest.mark.slow
def test_hidden_parameters_through_the_rig(tmp_path, rig, monkeypatch, plant, truth):
    import ipcosim

    monkeypatch.setenv("IPCOSIM_HIL_URI", rig(plant, truth))
    run = ipcosim.run(f"{plant}-identify", stop_time=STOP_TIME, swap={"plant": "hil"}, out=tmp_path / "run")
    assert not run.error, run.error
    assert run.metadata.get("realtime") in (False, None)       # lockstep: not paced
    # through the rig the estimates keep the targets; how often the intervals cover is the bench's coverage
    # figure (docs/identify.md, Figures), so the refits behind them are left out here
    check_targets(identify(IdentifyOptions.create(tmp_path / "run", plant=plant, refits=0)), truth, intervals=False)


# ------------------------------------------------------------------------------------ refusals

def _log(path: Path, columns: dict[str, np.ndarray]) -> Path:
    names = list(columns)
    np.savetxt(path, np.column_stack([columns[n] for n in names]), delimiter=",", header=",".join(names),
               comments="")
    return path


def test_missing_columns_and_unknown_names_are_one_line_refusals(tmp_path):
    t = np.arange(2000) * 1e-3
    csv = _log(tmp_path / "log.csv", {"time": t, "plant.voltage": np.sin(t), "plant.cart_position": 0 * t})
    with pytest.raises(IdentifyError, match=r"log\.csv: no column plant\.pendulum_angle"):
        identify(IdentifyOptions.create(csv, plant="single-mass"))
    with pytest.raises(ValueError, match=r"--fit Bq: .*did you mean .Beq."):
        IdentifyOptions.create(csv, plant="single-mass", fit="Mc,Bq")
    with pytest.raises(ValueError, match=r"--preset thesis-ch4: not a single-mass preset"):
        IdentifyOptions.create(csv, plant="single-mass", preset="thesis-ch4")
    with pytest.raises(IdentifyError, match="no such file"):
        identify(IdentifyOptions.create(tmp_path / "nothing", plant="single-mass"))
    with pytest.raises(ValueError, match=r"--refits 1: give 0 \(the sandwich interval alone\) or a whole number >= 2"):
        IdentifyOptions.create(csv, plant="single-mass", refits=1)


@pytest.mark.integration
@pytest.mark.slow
def test_a_log_that_does_not_move_a_parameter_is_refused(tmp_path):
    import ipcosim

    # 0.05 V does not break the cart loose (stick-slip friction): nothing about its mass is in the log
    ipcosim.run("single-mass-identify", stop_time=2.0, set={"controller.amplitude": 0.05}, out=tmp_path / "still")
    with pytest.raises(IdentifyError, match="cannot identify Mc: the excitation did not move it"):
        identify(IdentifyOptions.create(tmp_path / "still", plant="single-mass"))
    # a log that does not start hanging (pi on the plant FMU, 0 on an encoder zeroed there) is not the experiment's
    t = np.arange(2000) * 1e-3
    csv = _log(tmp_path / "tilted.csv", {"time": t, "plant.voltage": np.sin(t), "plant.cart_position": 0 * t,
                                         "plant.pendulum_angle": 0 * t + 1.0})
    with pytest.raises(IdentifyError, match="tilted.csv: the pendulum angle starts at 1 rad, neither hanging"):
        identify(IdentifyOptions.create(csv, plant="single-mass", fit="Mc"))


# ------------------------------------------------------------------------------------ the result feeds runs

@pytest.mark.integration
@pytest.mark.slow
def test_command_line_json_ssv_and_parameter_file(tmp_path):
    import ipcosim

    run = tmp_path / "run"
    # the fit names every parameter the log hides (one it held at the preset would leave its error in the readings:
    # a fit that is not valid, exit 4)
    hidden = {k: SINGLE_TRUTH[k] for k in ("Mc", "Beq", "b")}
    ipcosim.run("single-mass-identify", stop_time=STOP_TIME, set={f"plant.{k}": v for k, v in hidden.items()}, out=run)
    # the final pass's simulations on a shared machine: a generous limit, the speed target is make bench's
    p = cli("identify", str(run), "--plant", "single-mass", "--fit", "Mc,Beq,b", "--refits", "2", "--json", "--out",
            str(tmp_path / "id"), timeout=600)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert set(doc["parameters"]) == {"Mc", "Beq", "b"} and set(doc["nrmse"]) == {"cart_position", "pendulum_angle"}
    assert doc["parameters"]["Mc"]["unit"] == "kg" and len(doc["parameters"]["Mc"]["ci95"]) == 2
    assert set(doc["largest_residual_counts"]) == set(doc["nrmse"]) and doc["simulations"] > 0
    assert doc["replay"] == "native" and doc["refits"] == 2 and p.stderr == ""
    # the contract's nrmse is the NRMSE (0 = perfect); the fit is 1 - NRMSE
    assert doc["valid"] is True and all(v["valid"] for v in doc["parameters"].values())
    assert all(0 <= doc["nrmse"][k] < 0.1 and doc["fit"][k] == pytest.approx(1 - doc["nrmse"][k]) for k in doc["nrmse"])
    ssv = tmp_path / "id" / "identified.ssv"
    assert ssv.is_file() and (tmp_path / "id" / "identified.png").is_file()
    # the file's values reach the plant (after the scenario's sets), and --set still wins over it
    via_file = ipcosim.run("single-mass-lqr", stop_time=1.0, parameter_file=ssv, set={"plant.Mp": 0.2})
    by_hand = ipcosim.run("single-mass-lqr", stop_time=1.0, set={"plant.Mp": 0.2, **{
        f"plant.{k}": v["value"] for k, v in doc["parameters"].items()}})
    plain = ipcosim.run("single-mass-lqr", stop_time=1.0, set={"plant.Mp": 0.2})
    col = "plant.cart_position"
    assert np.array_equal(via_file.data[col], by_hand.data[col])
    assert not np.array_equal(via_file.data[col], plain.data[col])
    bad = cli("run", "single-mass-lqr", "--parameter-file", str(tmp_path / "missing.ssv"))
    assert bad.returncode != 0 and "missing.ssv: no such file" in bad.stderr and len(bad.stderr.splitlines()) == 1


# ------------------------------------------------------------------------------------ what it cannot identify

@pytest.fixture(scope="module")
def step_run(tmp_path_factory):
    """An ordinary closed-loop step response of the single-mass LQR (4 s): no excitation experiment."""
    import ipcosim

    out = tmp_path_factory.mktemp("step") / "run"
    assert not ipcosim.run("single-mass-lqr", stop_time=4.0, out=out).error
    return out


def test_a_step_response_is_refused_before_fitting(step_run, tmp_path):
    p = cli("identify", str(step_run), "--plant", "single-mass", "--out", str(tmp_path / "id"))
    assert p.returncode != 0 and p.stdout == "" and len(p.stderr.splitlines()) == 1, p.stderr
    assert "the voltage does not excite the plant through the log" in p.stderr and "results.csv" in p.stderr
    # nothing written, identified.ssv least of all: the folder it made for --out is gone with its claim
    assert not (tmp_path / "id").exists()
    # a folder that was there stays, with what it held and nothing of the refused command's
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    p = cli("identify", str(step_run), "--plant", "single-mass", "--out", str(tmp_path / "mine"))
    assert p.returncode != 0 and "does not excite" in p.stderr
    assert sorted(q.name for q in (tmp_path / "mine").iterdir()) == ["notes.txt"]
    # the other plant kind's columns: named, with the kind to give
    p = cli("identify", str(step_run), "--plant", "double-mass")
    assert p.returncode != 0 and len(p.stderr.splitlines()) == 1
    assert "the log is a single-mass plant's" in p.stderr and "give --plant single-mass" in p.stderr


def test_a_bad_out_is_refused_before_fitting(step_run, tmp_path):
    (tmp_path / "taken").write_text("")
    for out, needle in ((tmp_path / "taken", "is a file, not a folder"), (tmp_path / "taken" / "sub",
                                                                              "output folder is not writable")):
        p = cli("identify", str(step_run), "--plant", "single-mass", "--out", str(out))
        assert p.returncode != 0 and len(p.stderr.splitlines()) == 1, p.stderr
        assert f"--out {out}: {needle}" in p.stderr     # before the log is even read (it would be refused)


def test_torque_constant_and_resistance_cannot_be_told_apart(tmp_path):
    """Kt and Ra reach the motion as Kt / Ra (and through the armature's La / Ra): a fit of both is refused before
    it starts, naming the pair."""
    import ipcosim

    ipcosim.run("single-mass-identify", stop_time=3.0, out=tmp_path / "run")
    with pytest.raises(IdentifyError, match=r"cannot identify (Kt apart from Ra|Ra apart from Kt): the log moves"):
        identify(IdentifyOptions.create(tmp_path / "run", plant="single-mass", fit="Mc,Kt,Ra"))


def _fake_result(valid: bool):
    """An :class:`Identification` of made-up signals (no fit): what the figure and the files are drawn from."""
    from ipcosim.harness.studies.identify import Identification

    t = np.arange(2000) * 1e-3
    resolution = {"cart_position": 2.275e-5, "pendulum_angle": 1.534e-3}
    measured = np.column_stack([0.01 * np.sin(3 * t), math.pi + 0.1 * np.sin(6 * t)])
    simulated = measured + np.column_stack([1e-5 * np.cos(t), 4e-4 * np.cos(t)]) * (1 if valid else 10)
    result = Identification("single-mass", "thesis-ch3", {"Mc": {"value": 0.9, "ci95": [0.89, 0.91], "unit": "kg"}},
                            {"cart_position": 0.01, "pendulum_angle": 0.02}, 1.5, 1.0, 10, "somewhere/results.csv",
                            outputs=("cart_position", "pendulum_angle"), time=t, measured=measured,
                            simulated=simulated, resolutions=resolution)
    result.largest_residual_counts = {k: float(np.abs(measured[:, j] - simulated[:, j]).max() / resolution[k])
                                      for j, k in enumerate(resolution)}
    return result


@pytest.mark.parametrize("valid", [True, False])
def test_the_identify_figure_has_units_and_a_residual_panel(tmp_path, valid):
    import matplotlib.image

    from ipcosim.harness.studies.identify import identified_figure, write_identified

    result = _fake_result(valid)
    assert result.valid is valid
    fig = identified_figure(result)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert len(fig.axes) == 4                                           # each output over its residual
    assert "[mm]" in labels[0] and "[mrad]" in labels[2]
    assert labels[1].endswith("[counts]") and labels[3].endswith("[counts]")
    assert fig.axes[-1].get_xlabel().startswith("time [s]")
    # the residual panel shows measured - simulated in counts: the pendulum's 4e-4 rad is about 0.26 count
    line = fig.axes[3].get_lines()[0].get_ydata()
    assert np.abs(line).max() == pytest.approx(result.largest_residual_counts["pendulum_angle"], rel=1e-6)
    assert ("NOT VALID" in fig._suptitle.get_text()) is not valid
    written = write_identified(result, tmp_path)
    assert (tmp_path / "identified.ssv").exists() is valid              # no parameter file from a fit not valid
    image = matplotlib.image.imread(tmp_path / "identified.png")
    assert min(image.shape[:2]) > 500 and written[-1] == tmp_path / "identified.png"   # 2 x 2 panels, 110 dpi
    doc = result.to_json()
    assert doc["valid"] is valid and doc["parameters"]["Mc"]["valid"] is valid
    assert (doc["invalid_reason"] is None) is valid


# ------------------------------------------------------------------------------------ a model that is wrong

@pytest.mark.integration
@pytest.mark.slow
def test_a_hidden_torque_constant_error_is_identified(tmp_path):
    """The motor's torque constant 10 % off (an ordinary motor tolerance): the default fit carries it in Kt and
    every other parameter keeps its target (with Kt held, they were 9 to 14 % off with intervals excluding the
    truth)."""
    truth = {**SINGLE_TRUTH, "Kt": 1.1 * preset("thesis-ch3").Kt}
    result = _identify_run("single-mass-identify", truth, tmp_path / "run", refits=0)
    assert result.valid and abs(result.parameters["Kt"]["value"] / truth["Kt"] - 1) < 0.03, result.parameters
    check_targets(result, SINGLE_TRUTH, intervals=False)


@pytest.mark.integration
@pytest.mark.slow
def test_a_hidden_pendulum_length_error_is_flagged(tmp_path):
    """The pendulum 10 % longer than the preset, not fitted: the fit cannot explain the swing, says so in one line,
    marks every interval not valid, writes its plot but no parameter file, and exits 4."""
    import ipcosim

    run = tmp_path / "run"
    ipcosim.run("single-mass-identify", stop_time=STOP_TIME, set={"plant.Lp": 1.1 * preset("thesis-ch3").Lp}, out=run)
    p = cli("identify", str(run), "--plant", "single-mass", "--refits", "0", "--json", "--out", str(tmp_path / "id"),
            timeout=600)
    assert p.returncode == 4, p.stderr
    doc = json.loads(p.stdout)
    assert doc["valid"] is False and not any(v["valid"] for v in doc["parameters"].values())
    assert max(doc["largest_residual_counts"].values()) > 3
    assert len(p.stderr.splitlines()) == 1 and "the fit is not valid" in p.stderr
    assert (tmp_path / "id" / "identified.png").is_file() and not (tmp_path / "id" / "identified.ssv").exists()
