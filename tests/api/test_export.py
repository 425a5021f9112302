"""``ipcosim export``: a scenario's closed loop as one FMU, against ``ipcosim run --fmus native``.

The exported FMU is simulated in fmpy, libcosim and a C host without Python; its outputs must
equal the scenario's run on the native FMUs (1e-9 of each column's largest magnitude asserted;
the differences seen are printed). Bad input ends in one line and a non-zero exit.
"""
from __future__ import annotations

import subprocess
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ipcosim.toolchain import find_compiler

ROOT = Path(__file__).resolve().parents[2]
CC = find_compiler()
pytestmark = [pytest.mark.integration, pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)")]
SCENARIOS = ("single-mass-lqr", "double-mass-lqr")
PLANT_OUTPUTS = {
    "single-mass-lqr": ["cart_position", "pendulum_angle", "cart_velocity", "pendulum_velocity", "motor_current"],
    "double-mass-lqr": ["active_cart_position", "passive_cart_position", "pendulum_angle", "active_cart_velocity",
                        "passive_cart_velocity", "pendulum_velocity", "motor_current"],
}


@pytest.fixture(scope="module")
def exported(native_fmus: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from ipcosim.harness.api.export import ExportOptions, export

    out = tmp_path_factory.mktemp("export")
    return {sc: export(ExportOptions(sc, out / f"{sc}.fmu", fmu_dirs=(native_fmus[1],))) for sc in SCENARIOS}


@pytest.fixture(scope="module")
def runs(native_fmus: tuple[Path, Path]) -> dict[str, np.ndarray]:
    """Each scenario's 10 s run on the native FMUs in the ipcosim master."""
    import ipcosim

    return {sc: ipcosim.run(sc, fmu_dirs=[native_fmus[1]], fmus="native").data for sc in SCENARIOS}


def _simulate(fmu: Path, step: float, **kwargs) -> np.ndarray:  # noqa: ANN003 -- fmpy.simulate_fmu's options
    import fmpy

    return fmpy.simulate_fmu(str(fmu), stop_time=10.0, step_size=step, output_interval=step, **kwargs)


def _worst(ours: np.ndarray, ref: np.ndarray, names: list[str], every: int = 1) -> dict[str, float]:
    """Largest difference of each column relative to the column's largest magnitude."""
    assert len(ours) == len(ref[::every])
    return {n: float(np.max(np.abs(ours[n] - ref[n][::every]))) / max(float(np.max(np.abs(ref[n]))), 1e-12)
            for n in names}


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("step", [0.001, 0.01])
def test_exported_loop_equals_the_scenario_run(exported: dict[str, Path], runs: dict[str, np.ndarray],
                                               scenario: str, step: float) -> None:
    """fmpy at the scenario's step (every sample) and at 10 ms (the scenario's samples at those times)."""
    from fmpy import read_model_description

    md = read_model_description(str(exported[scenario]))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert outputs == ["controller.voltage", *(f"plant.{n}" for n in PLANT_OUTPUTS[scenario])]
    data = _simulate(exported[scenario], step)
    every = round(step / 1e-3)
    assert np.max(np.abs(data["time"] - runs[scenario]["time"][::every])) < 1e-12
    worst = _worst(data, runs[scenario], outputs, every)
    print(f"{scenario} at {step:g} s: largest relative difference {max(worst.values()):.3g}")
    assert max(worst.values()) <= 1e-9, worst
    assert np.max(np.abs(data[outputs[1]])) > 0.04  # the cart did move (the comparison is not of zeros)


def test_reference_input_drives_the_loop(exported: dict[str, Path], runs: dict[str, np.ndarray]) -> None:
    """Setpoint amplitude 0 plus the reference input reproduces the scenario; without it the cart
    stays; a reference changed during the run is followed."""
    fmu, ref = exported["single-mass-lqr"], runs["single-mass-lqr"]
    names = ["plant.cart_position", "plant.pendulum_angle", "controller.voltage"]
    same = _simulate(fmu, 0.001, start_values={"setpoint.amplitude": 0.0, "reference": 0.05})
    worst = _worst(same, ref, names)
    print(f"amplitude 0 + reference input 0.05: largest relative difference {max(worst.values()):.3g}")
    assert max(worst.values()) <= 1e-9, worst
    still = _simulate(fmu, 0.001, start_values={"setpoint.amplitude": 0.0})
    assert np.max(np.abs(still["plant.cart_position"])) < 1e-9 < np.max(np.abs(ref["plant.cart_position"]))
    signal = np.array([(0.0, 0.05), (5.0, 0.05), (5.0, 0.1), (10.0, 0.1)],
                      dtype=[("time", float), ("reference", float)])
    moved = _simulate(fmu, 0.001, start_values={"setpoint.amplitude": 0.0}, input=signal)
    x = moved["plant.cart_position"]
    assert abs(x[4990] - 0.05) < 2e-3 and abs(x[-1] - 0.1) < 2e-3, (x[4990], x[-1])


def test_model_description_validates_and_carries_the_scenarios_values(exported: dict[str, Path],
                                                                      native_fmus: tuple[Path, Path],
                                                                      tmp_path: Path) -> None:
    from fmi_helpers import assert_vdmcheck_clean
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    from ipcosim.harness.api.engine import Prepared
    from ipcosim.harness.api.export import ExportOptions, export

    for sc, fmu in exported.items():
        assert validate_fmu(str(fmu)) == [], sc
        md = read_model_description(str(fmu))
        v = {x.name: x for x in md.modelVariables}
        assert (v["reference"].causality, v["reference"].unit, float(v["reference"].start)) == ("input", "m", 0.0)
        assert [u.variable.name for u in md.outputs] == [n for n in v if v[n].causality == "output"]
        assert all(u.dependencies == [] for u in md.outputs)  # no direct feedthrough
        with Prepared(sc, fmu_dirs=[native_fmus[1]], fmus="native") as prepared:
            for inst in prepared.system.instances:
                comp = {x.name: x for x in read_model_description(str(inst.model.path)).modelVariables}
                bound = {var.name: value for var, value in inst.parameters}
                params = [n for n, x in comp.items() if x.causality == "parameter"]
                assert params and all(v[f"{inst.name}.{n}"].causality == "parameter" for n in params)
                for n in params:
                    ours, theirs = v[f"{inst.name}.{n}"], comp[n]
                    assert (ours.unit, ours.type, ours.description) == (theirs.unit, theirs.type, theirs.description)
                    want = bound.get(n, theirs.start)
                    assert float({"true": 1, "false": 0}.get(str(ours.start), ours.start)) == float(
                        {"true": 1, "false": 0}.get(str(want), want)), (sc, inst.name, n)
    again = export(ExportOptions("single-mass-lqr", tmp_path / "again.fmu", fmu_dirs=(native_fmus[1],)))
    guids = [read_model_description(str(f)).guid for f in (exported["single-mass-lqr"], again,
                                                           exported["double-mass-lqr"])]
    assert guids[0] == guids[1] != guids[2]
    assert_vdmcheck_clean(exported["single-mass-lqr"])
    assert_vdmcheck_clean(exported["double-mass-lqr"])


def test_sources_compile_warning_free(exported: dict[str, Path], tmp_path: Path) -> None:
    from fmpy import read_model_description

    from ipcosim.harness.native.cbuild import compile_sources

    fmu = exported["double-mass-lqr"]
    md = read_model_description(str(fmu))
    files = [f for c in md.buildConfigurations for s in c.sourceFileSets for f in s.sourceFiles]
    assert files[:2] == ["container_table.c", "container.c"] and len(files) == 5
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path)
    assert CC is not None
    flags = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-fPIC", "-shared")
    compile_sources(tmp_path / "sources", files, tmp_path / "loop.so", CC, flags)  # fails on any warning
    symbols = subprocess.run(["nm", "-D", "--defined-only", str(tmp_path / "loop.so")], capture_output=True,
                             text=True).stdout
    assert " fmi2DoStep\n" in symbols and " ipcosim_plant_fmi2DoStep\n" in symbols


def _host_run(host: Path, fmu: Path, tmp_path: Path, step: str, steps: int, out: str) -> subprocess.CompletedProcess:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path / fmu.stem)
    lib = tmp_path / fmu.stem / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    return subprocess.run([str(host), str(lib), md.guid, step, str(steps), "--", str(vr[out])],
                          capture_output=True, text=True, timeout=60)


@pytest.fixture(scope="module")
def host(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from ipcosim.harness.native.cbuild import fmi_header_dir

    exe = tmp_path_factory.mktemp("host") / "native_host"
    assert CC is not None
    subprocess.run([CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-D_POSIX_C_SOURCE=200809L",
                    "-I", str(fmi_header_dir()), str(ROOT / "tests" / "c" / "native_host.c"), "-o", str(exe),
                    "-ldl"], check=True)
    return exe


def test_c_host_runs_the_loop_without_python(exported: dict[str, Path], runs: dict[str, np.ndarray],
                                             host: Path, tmp_path: Path) -> None:
    """tests/c/native_host.c (exits 3 if a libpython is mapped) at 1 ms and 10 ms; a step that is no
    whole multiple of the scenario's is refused, naming both."""
    fmu = exported["double-mass-lqr"]
    final = runs["double-mass-lqr"]["plant.passive_cart_position"][-1]
    for step, steps in (("0.001", 10000), ("0.01", 1000)):
        p = _host_run(host, fmu, tmp_path, step, steps, "plant.passive_cart_position")
        assert p.returncode == 0, p.stderr
        assert float(p.stdout) == pytest.approx(final, rel=1e-9, abs=1e-12)
    bad = _host_run(host, fmu, tmp_path, "0.0015", 10, "plant.passive_cart_position")
    assert bad.returncode == 6
    assert "h = 0.0015 s is not a whole multiple of the scenario's step 0.001 s" in bad.stderr, bad.stderr


def test_runs_in_libcosim_as_in_fmpy(exported: dict[str, Path]) -> None:
    """libcosim (one local slave) at 1 ms and 10 ms gives fmpy's values; the real-time factors are printed."""
    pytest.importorskip("libcosimpy")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    fmu = exported["single-mass-lqr"]
    for step in (0.001, 0.01):
        n = round(10.0 / step)
        execution = CosimExecution.from_step_size(round(step * 1e9))
        s = execution.add_local_slave(CosimLocalSlave(fmu_path=str(fmu), instance_name="loop"))
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(s)}
        names = ["controller.voltage", "plant.cart_position", "plant.pendulum_angle", "plant.motor_current"]
        observer = CosimObserver.create_time_series(buffer_size=n + 10)
        execution.add_observer(observer)
        for name in names:
            observer.start_time_series(s, refs[name], CosimVariableType.REAL)
        t0 = time.perf_counter()
        assert execution.simulate_until(round(10.0 * 1e9))
        wall = time.perf_counter() - t0
        theirs = _simulate(fmu, step)
        for name in names:
            times, _, values = observer.time_series_real_samples(s, refs[name], from_step=1, sample_count=n + 5)
            assert len(values) == n and times[0] == round(step * 1e9)
            assert np.array_equal(np.asarray(values), theirs[name][1:]), name
        print(f"libcosim at {step:g} s: {10.0 / wall:.0f}x real time (with a time-series observer)")


def test_bad_input_ends_in_one_line(native_fmus: tuple[Path, Path], tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from ipcosim.harness.cli import main

    fmu_dir = ["--fmu-dir", str(native_fmus[1])]
    cases = [  # exit 2: the command line is wrong; 1: the export cannot be done (docs/robustness.md)
        (["nosuch-scenario", "--out", str(tmp_path / "a.fmu")], "unknown scenario 'nosuch-scenario'", 2),
        (["single-mass-identify", "--out", str(tmp_path / "a.fmu")],
         "only the native flavour can be exported: ", 1),
        (["single-mass-lqr", "--out", str(tmp_path / "missing" / "a.fmu")], "missing is not a writable folder", 2),
        (["single-mass-lqr", "--out", str(tmp_path)], "is a folder", 2),
        (["single-mass-lqr", "--out", str(tmp_path / "a.zip")], "must end in .fmu", 2),
        (["single-mass-lqr", "--out", str(tmp_path / "a.fmu"), "--set", "controller.R=1"],
         "the native flavour of LQRSingleMass has no parameter 'R'", 1),
        (["single-mass-lqr", "--out", str(tmp_path / "a.fmu"), "--set", "controller.K_cart_position"],
         "expected COMPONENT.VARIABLE=VALUE", 2),
    ]
    for argv, words, status in cases:
        assert main(["export", *argv, *fmu_dir]) == status, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("ipcosim export: error: ") and words in err, err
    # the refusal names the component without a native flavour
    assert main(["export", "single-mass-identify", "--out", str(tmp_path / "a.fmu"), *fmu_dir]) == 1
    assert "component 'controller'" in capsys.readouterr().err
    monkeypatch.setenv("CC", "no-such-compiler")
    assert main(["export", "single-mass-lqr", "--out", str(tmp_path / "a.fmu"), *fmu_dir]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no C compiler found" in err, err
    assert not (tmp_path / "a.fmu").exists()


def test_unconnected_inputs_become_container_inputs(native_fmus: tuple[Path, Path], tmp_path: Path) -> None:
    """A loop left open (setpoint and LQR without the plant): the controller's measurement inputs are
    the container's inputs ``controller.<input>`` and act as on the controller FMU alone."""
    import fmpy

    from ipcosim.harness.native.container import ComponentSpec, ContainerSpec, InputSpec, build_container

    native = native_fmus[1]
    spec = ContainerSpec(
        name="OpenLoop", description="setpoint and controller", step=0.001, order=("setpoint", "controller"),
        outputs=(("controller", "voltage"),),
        components=(
            ComponentSpec("setpoint", native / "Setpoint.fmu", 1, (), ("reference",)),
            ComponentSpec("controller", native / "LQRSingleMass.fmu", 1,
                          (InputSpec("reference", ("setpoint", "reference"), add_reference=True),
                           InputSpec("cart_position"), InputSpec("pendulum_angle")), ("voltage",))))
    fmu = build_container(spec, tmp_path / "open.fmu")
    inputs = {v.name: v for v in fmpy.read_model_description(str(fmu)).modelVariables if v.causality == "input"}
    assert sorted(inputs) == ["controller.cart_position", "controller.pendulum_angle", "reference"]
    assert inputs["controller.cart_position"].unit == "m"
    signal = np.array([(0.0, 0.01, 0.002), (0.05, 0.01, 0.002), (0.05, -0.02, 0.0), (0.2, -0.02, 0.0)],
                      dtype=[("time", float), ("controller.cart_position", float),
                             ("controller.pendulum_angle", float)])
    ours = fmpy.simulate_fmu(str(fmu), stop_time=0.2, step_size=0.001, output_interval=0.001, input=signal)
    alone_signal = signal.copy()
    alone_signal.dtype.names = ("time", "cart_position", "pendulum_angle")
    alone = fmpy.simulate_fmu(str(native / "LQRSingleMass.fmu"), stop_time=0.2, step_size=0.001,
                              output_interval=0.001, input=alone_signal, start_values={"reference": 0.05})
    assert np.array_equal(ours["controller.voltage"], alone["voltage"])
    u = ours["controller.voltage"]
    assert len(set(u[:50])) > 1 and u[60] != u[40]  # the inputs act, and the change at 0.05 s too


def test_multi_rate_loop_equals_the_scenario_run(native_fmus: tuple[Path, Path], tmp_path: Path) -> None:
    """``--set controller.sample_period=0.002`` (redesigned as in ``ipcosim run``): the controller
    steps every second tick, by the master's multi-rate rule, in the exported FMU too."""
    from fmpy import read_model_description

    import ipcosim
    from ipcosim.harness.api.export import ExportOptions, export

    values = {"controller.sample_period": 0.002}
    fmu = export(ExportOptions("single-mass-lqr", tmp_path / "mr.fmu", fmu_dirs=(native_fmus[1],), set=values))
    start = {v.name: v.start for v in read_model_description(str(fmu)).modelVariables}
    assert float(start["controller.sample_period"]) == 0.002
    ref = ipcosim.run("single-mass-lqr", fmu_dirs=[native_fmus[1]], fmus="native", set=values).data
    names = ["controller.voltage", "plant.cart_position", "plant.pendulum_angle", "plant.motor_current"]
    for step in (0.001, 0.01):
        worst = _worst(_simulate(fmu, step), ref, names, round(step / 1e-3))
        print(f"multi-rate at {step:g} s: largest relative difference {max(worst.values()):.3g}")
        assert max(worst.values()) <= 1e-9, worst
    u = ref["controller.voltage"]
    assert np.all(u[1::2] == u[0:-1:2]) and not np.all(u[2::2] == u[1:-1:2])  # held over two ticks
