"""The master on the real FMUs: every packed scenario runs in libcosim and in our master,
libcosim agrees with our Jacobi to 1e-9, the co-simulation equals a monolithic loop of the
same pure models to 1e-9, and the demo run writes its three files."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import ipcosim.harness
from evidence.crosscheck import run_libcosim
from ipcosim.fmus.kinds import plant_kind
from ipcosim.harness.scenario.ssp import load_scenario

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = sorted(p.name for p in (ROOT / "ssp").iterdir() if (p / "SystemStructure.ssd").is_file())


@pytest.fixture(scope="session")
def built(tmp_path_factory, request) -> Path:
    """Every FMU of the project (this run's build), and every scenario packed, in a session folder
    (``IPCOSIM_TEST_BUILD`` may name a ready build folder instead)."""
    ready = os.environ.get("IPCOSIM_TEST_BUILD")
    if ready:
        return Path(ready)
    from ipcosim.harness.scenario.ssp_pack import pack_all

    out = tmp_path_factory.mktemp("master-build")
    (out / "fmus").symlink_to(request.getfixturevalue("project_fmu_dir"), target_is_directory=True)
    pack_all(out)
    return out


def measured(kind: str) -> list[str]:
    from ipcosim.fmus.physics import MEASURED

    return list(MEASURED[kind])


@pytest.mark.slow
def test_every_scenario_is_packed_and_runs_in_libcosim_and_ours(built):
    for name in SCENARIOS:
        ssp = built / "ssp" / f"{name}.ssp"
        assert ssp.is_file(), f"{name}.ssp was not packed"
        cols = [f"plant.{m}" for m in measured(plant_kind(name))] + ["controller.voltage"]
        lib, _ = run_libcosim(ssp, 0.05, 1e-3, cols)
        assert len(lib) == 50 and all(np.isfinite(lib[c]).all() for c in cols), name
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the project's scenarios leave no input unconnected
            ours = ipcosim.run(ssp, stop_time=0.05)
        assert len(ours.data) == 51 and ours.metadata["order"] == ["setpoint", "plant", "controller"]


@pytest.mark.parametrize("name", ["single-mass-lqr", "double-mass-hsmc"])
def test_libcosim_agrees_with_our_jacobi_to_1e_9(built, name):
    ssp = built / "ssp" / f"{name}.ssp"
    cols = ([f"plant.{m}" for m in measured(plant_kind(name))] + ["plant.motor_current", "controller.voltage",
                                                                   "setpoint.reference"])
    lib, _ = run_libcosim(ssp, 2.0, 1e-3, cols)
    ours = ipcosim.run(ssp, stop_time=2.0, step=1e-3, algorithm="jacobi")
    assert np.array_equal(ours["time"][1:], lib["time"])  # the same integer-nanosecond time grid
    for c in cols:
        assert np.max(np.abs(ours[c][1:] - lib[c])) <= 1e-9, c
    # the runs moved: the comparison is not between two resting systems
    assert np.ptp(lib[f"plant.{measured(plant_kind(name))[0]}"]) > 1e-3


def _setpoint(scenario) -> tuple[float, float]:
    values = {p.name: p.value for b in scenario.component("setpoint").bindings for p in b.parameters}
    return values["amplitude"], values["step_time"]


@pytest.mark.parametrize("name, law", [("single-mass-lqr", "LQR"), ("double-mass-hsmc", "HSMC")])
def test_cosimulation_equals_a_monolithic_loop_of_the_pure_models(built, name, law):
    """Plant (ipcosim.fmus.plant.Plant) and control law (controllers' class) in one loop: the voltage
    is held over each 1 ms step (zero-order hold), the law samples the positions and the
    reference at every sample instant, the first sample at t = 0 (setpoint, plant,
    controller: the master's Gauss-Seidel order)."""
    from ipcosim.controllers.catalog import make_law
    from ipcosim.fmus.params import DEFAULT_PRESET, preset
    from ipcosim.fmus.plant import Plant

    kind = plant_kind(name)
    scenario = load_scenario(built / "ssp" / f"{name}.ssp")
    bound = scenario.bound_sets[0] if scenario.bound_sets else None
    stop, h = 3.0, 1e-3
    result = ipcosim.run(built / "ssp" / f"{name}.ssp", stop_time=stop, step=h)
    amplitude, step_time = _setpoint(scenario)
    ctrl = make_law(kind, law, bound)
    m = round(ctrl.sample_period / h)
    plant = Plant(preset(DEFAULT_PRESET[kind]))
    n = round(stop / h)
    states = np.empty((n + 1, len(plant.state_names)))
    volts = np.empty(n + 1)
    states[0] = plant.x

    def ref(k: int) -> float:
        return amplitude if k * h >= step_time - 1e-12 else 0.0

    u = ctrl.step(plant.measured(), ref(0))
    volts[0] = u
    for k in range(n):
        plant.do_step(k * h, h, u)
        states[k + 1] = plant.x
        if (k + 1) % m == 0:
            u = ctrl.step(plant.measured(), ref(k + 1))
        volts[k + 1] = u
    for j, state in enumerate(plant.state_names):
        assert np.max(np.abs(result[f"plant.{state}"] - states[:, j])) <= 1e-9, state
    assert np.max(np.abs(result["controller.voltage"] - volts)) <= 1e-9
    assert np.ptp(states[:, 0]) > 0.01  # the cart moved towards 0.05 m


@pytest.mark.slow
def test_demo_run_writes_results_metrics_and_plot(built, tmp_path):
    out = tmp_path / "demo"
    env = {**os.environ, "IPCOSIM_FMU_PATH": str(built / "fmus")}
    proc = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--plot",
                           "--out", str(out)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert {p.name for p in out.iterdir()} >= {"results.csv", "metrics.json", "plot.png"}
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["upright"] is True and metrics["settling_time_s"] is not None
    assert abs(metrics["steady_state_error_m"]) < 0.005
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    assert header[:2] == ["time", "setpoint.reference"] and "plant.cart_position" in header
    assert "settling_time_s" in proc.stdout  # the metrics are printed
    assert (out / "plot.png").stat().st_size > 10_000


def test_prepared_runs_many_times_with_different_overrides(built):
    from ipcosim.harness.master.slave import FMUSlave

    with ipcosim.prepare(built / "ssp" / "single-mass-lqr.ssp") as prepared:
        a = prepared.run(stop_time=0.5, set={"plant.Mp": 0.2303})
        b = prepared.run(stop_time=0.5, set={"plant.Mp": 0.30})
        c = prepared.run(stop_time=0.5, set={"plant.Mp": 0.2303})
        assert np.array_equal(a.data, c.data)  # runs are independent: nothing leaks from one to the next
        assert not np.array_equal(a["plant.pendulum_angle"], b["plant.pendulum_angle"])
        assert b.metadata["overrides"] == {"plant.Mp": 0.30}
        assert len(prepared._libraries) == 3  # each FMU loaded once for all runs
    default = ipcosim.run(built / "ssp" / "single-mass-lqr.ssp", stop_time=0.5)
    assert np.array_equal(default.data, a.data)  # Mp = 0.2303 is the FMU's default
    assert isinstance(FMUSlave, type)


def test_parameter_set_selection_changes_the_controller(built):
    ssp = built / "ssp" / "single-mass-hsmc.ssp"
    tuned = ipcosim.run(ssp, stop_time=1.0)
    thesis = ipcosim.run(ssp, stop_time=1.0, parameter_set="thesis")
    assert tuned.metadata["parameter_set"] == "tuned" and thesis.metadata["parameter_set"] == "thesis"
    assert not np.array_equal(tuned["controller.voltage"], thesis["controller.voltage"])
    with pytest.raises(Exception, match="has no parameter set 'best'"):
        ipcosim.run(ssp, stop_time=1.0, parameter_set="best")


def test_controller_sample_period_sets_its_step_multiple(built):
    r = ipcosim.run(built / "ssp" / "single-mass-lqr.ssp", stop_time=1.0,
                    set={"controller.sample_period": 0.002})
    assert r.metadata["step_multiples"]["controller"] == 2
    u = r["controller.voltage"]
    assert np.array_equal(u[1::2], u[0:-1:2])  # held over each 2 ms period
    assert r.metrics["upright"] is True
