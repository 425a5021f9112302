"""The clocked controller FMUs (FMI 3.0 input clock = the law's sample period) against the
standard's schema and against the unclocked variant, run by the master and by an importer in C
(``tests/c/clocked_host.c``) written from the standard's text."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

import ipcosim
from ipcosim.harness.master.clocks import clocking
from ipcosim.harness.native.clocked import SOURCES, all_names, build_clocked, clocked_names

#: The scenario that runs each law (its controller component is ``controller``).
SCENARIOS = {"PID": "pid", "CascadePID": "cascade-pid", "LQR": "lqr", "HSMC": "hsmc",
             "AdaptiveHSMC": "adaptive-hsmc", "LQG": "lqg", "SwingUp": "swing-up"}


@pytest.fixture(scope="module")
def clocked_fmus(native_fmus: tuple[Path, Path]) -> Path:
    out = native_fmus[1].parent / "fmus-clocked"
    build_clocked(native_fmus[0], out)
    return out


def _scenario(model: str) -> str:
    plant = "single-mass" if model.endswith("SingleMass") else "double-mass"
    return f"{plant}-{SCENARIOS[model.removesuffix('SingleMass').removesuffix('DoubleMass')]}"


def test_clocked_fmus_validate_and_declare_their_clock(clocked_fmus: Path) -> None:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    fmus = sorted(clocked_fmus.glob("*Clocked.fmu"))
    assert len(fmus) == len(all_names())
    for fmu in fmus:
        assert validate_fmu(str(fmu)) == [], fmu.name
        md = read_model_description(str(fmu), validate=True)
        assert md.coSimulation.hasEventMode
        (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
        period = next((float(v.start) for v in md.modelVariables if v.name == "sample_period"),
                      float(SOURCES.get(fmu.stem.removesuffix("Clocked"), "nan")))
        assert clock.causality == "input" and clock.intervalVariability == "constant"
        ours = clocking(fmu, "3.0", fmu.name)  # the attributes as written (fmpy does not read them all)
        (tick,) = ours.clocks
        assert float(tick.interval) == period and tick.shift == 0
        for v in md.modelVariables:
            if v.causality in ("input", "output") and v.type != "Clock":
                assert ours.clocked[v.valueReference] == (tick.vr,), (fmu.name, v.name)


@pytest.mark.parametrize("model", clocked_names())
def test_clocked_trajectory_equals_the_unclocked_one(model: str, native_fmus: tuple[Path, Path],
                                                     native_fmus3: Path, clocked_fmus: Path) -> None:
    scenario = _scenario(model)
    plain = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                        swap={"controller": str(native_fmus3 / f"{model}.fmu")})
    clocked = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                          swap={"controller": str(clocked_fmus / f"{model}Clocked.fmu")})
    assert plain.error is None and clocked.error is None, (plain.error, clocked.error)
    assert list(plain.data.dtype.names) == list(clocked.data.dtype.names)
    for name in plain.data.dtype.names:  # bit for bit
        assert np.array_equal(plain.data[name], clocked.data[name], equal_nan=True), (model, name)
    assert np.ptp(clocked.data["controller.voltage"]) > 0  # the law acted


def test_a_host_without_event_mode_is_told_to_take_the_unclocked_variant(clocked_fmus: Path) -> None:
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    fmu = clocked_fmus / "LQRSingleMassClocked.fmu"
    md = read_model_description(str(fmu))
    messages = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception):  # noqa: B017 -- fmpy raises a bare Exception on a NULL instance
        slave.instantiate(eventModeUsed=False, logMessage=lambda env, status, cat, msg: messages.append(msg))
    assert any(b"take the unclocked variant" in m for m in messages)


def test_a_step_that_misses_the_clock_is_refused_naming_it(native_fmus: tuple[Path, Path], clocked_fmus: Path) -> None:
    from ipcosim.harness.master.algorithm import StepSizeError
    from ipcosim.harness.master.clocks import ClockError

    with pytest.raises((StepSizeError, ClockError), match="0.0003 s.*choose --step"):
        ipcosim.run("single-mass-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.1, step=0.0003,
                    swap={"controller": str(clocked_fmus / "LQRSingleMassClocked.fmu")})


ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def clocked_host(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from ipcosim.harness.native.cbuild import fmi_header_dir
    from ipcosim.toolchain import find_compiler

    cc = find_compiler()
    if cc is None:
        pytest.skip("no C compiler")
    exe = tmp_path_factory.mktemp("clocked-host") / "clocked_host"
    subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-I", str(fmi_header_dir()),
                    str(ROOT / "tests" / "c" / "clocked_host.c"), "-o", str(exe), "-ldl", "-lm"], check=True)
    return exe


def _spec(fmu: Path, ins: list[str], outs: list[str], tmp: Path) -> str:
    from fmpy import extract, read_model_description

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ident = md.coSimulation.modelIdentifier
    folder = extract(str(fmu), unzipdir=str(tmp / fmu.stem))
    clock = [str(v.valueReference) for v in md.modelVariables if v.type == "Clock"]
    return ":".join([f"{folder}/binaries/x86_64-linux/{ident}.so", ident, md.instantiationToken,
                     ",".join(str(vr[n]) for n in ins), ",".join(str(vr[n]) for n in outs), *clock])


def _host(exe: Path, stop: float, setpoint: str, controller: str, plant: str, connections: str) -> list[float]:
    proc = subprocess.run([str(exe), str(stop), "0.001", setpoint, controller, plant, connections],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    values, events = proc.stdout.splitlines()
    return [float(x) for x in values.split()] + [int(events)]


def _loop(model: str, controller: Path, native_fmus3: Path, tmp: Path) -> tuple[str, str, str, str, list[str]]:
    """The host's arguments for the loop of ``model``: setpoint, controller, plant, connections, plant outputs."""
    from fmpy import read_model_description

    plant = native_fmus3 / ("IP02SingleMass.fmu" if model.endswith("SingleMass") else "IP02DoubleMass.fmu")
    ins = [v.name for v in read_model_description(str(controller)).modelVariables
           if v.causality == "input" and v.type == "Float64"]
    measured = [n for n in ins if n != "reference"]
    conn = ",".join("s0" if n == "reference" else f"p{measured.index(n)}" for n in ins)
    return (_spec(native_fmus3 / "Setpoint.fmu", [], ["reference"], tmp), _spec(controller, ins, ["voltage"], tmp),
            _spec(plant, ["voltage"], measured, tmp), conn, measured)


@pytest.mark.parametrize("model", clocked_names())
def test_c_importer_runs_the_clocked_law_like_the_unclocked_one(model: str, native_fmus3: Path, clocked_fmus: Path,
                                                               clocked_host: Path, tmp_path: Path) -> None:
    *clocked_args, _ = _loop(model, clocked_fmus / f"{model}Clocked.fmu", native_fmus3, tmp_path / "c")
    *plain_args, _ = _loop(model, native_fmus3 / f"{model}.fmu", native_fmus3, tmp_path / "p")
    clocked = _host(clocked_host, 1.0, *clocked_args)
    plain = _host(clocked_host, 1.0, *plain_args)
    assert clocked[:-1] == plain[:-1]  # bit for bit (%.17g round-trips a double)
    assert clocked[-1] == 1001 and plain[-1] == 0  # a tick at 0, 1 ms, ..., 1 s: every one an Event Mode


@pytest.mark.parametrize("model", ["LQRSingleMass", "LQRDoubleMass"])
def test_c_importer_agrees_with_the_master(model: str, native_fmus3: Path, clocked_fmus: Path, clocked_host: Path,
                                           tmp_path: Path) -> None:
    scenario = _scenario(model)
    text = (ROOT / "ssp" / scenario / "SystemStructure.ssd").read_text()
    (tmp_path / scenario).mkdir()
    (tmp_path / scenario / "SystemStructure.ssd").write_text(  # every component at its FMU's defaults
        re.sub(r"<ssd:ParameterBindings>.*?</ssd:ParameterBindings>", "", text, flags=re.S))
    fmu = clocked_fmus / f"{model}Clocked.fmu"
    result = ipcosim.run(str(tmp_path / scenario), fmus="native", fmu_dirs=[native_fmus3], stop_time=1.0,
                         step=0.001, swap={"controller": str(fmu)})
    assert result.error is None, result.error
    *args, measured = _loop(model, fmu, native_fmus3, tmp_path / "c")
    host = _host(clocked_host, 1.0, *args)
    last = result.data[-1]
    assert [float(last[f"plant.{n}"]) for n in measured] + [float(last["controller.voltage"])] == host[:-1]
    assert np.ptp(result.data[f"plant.{measured[0]}"]) > 1e-3  # the loop moved the cart


def _changes(data: np.ndarray, column: str) -> np.ndarray:
    """The times at which ``column`` takes a new value."""
    return data["time"][1:][np.diff(data[column]) != 0]


def test_multirate_example_acts_at_exactly_each_clocks_instants(native_fmus: tuple[Path, Path],
                                                                clocked_fmus: Path) -> None:
    """A 100 Hz reference task (the setpoint's 10 ms clock) beside the 1 kHz LQR (its 1 ms clock), the
    master at 0.5 ms: each clocked output changes only at its own clock's ticks, the plant at every step."""
    result = ipcosim.run(str(ROOT / "examples" / "clocked" / "single-mass-lqr-multirate"), fmus="native",
                         fmu_dirs=[native_fmus[1], clocked_fmus], stop_time=2.0, step=0.0005,
                         set={"plant.integrator_step": 0.0005})
    assert result.error is None, result.error
    data = result.data
    ref, volt = _changes(data, "setpoint.reference"), _changes(data, "controller.voltage")
    plant = _changes(data, "plant.cart_position")
    ticks_100hz, ticks_1khz = np.arange(201) / 100, np.arange(2001) / 1000  # the ticks' exact times, rounded
    assert np.isin(ref, ticks_100hz).all()  # 10 ms ticks only
    assert len(ref) == 100  # the ramp reaches 0.05 m at 0.05 m/s in 1 s: one new sample per tick
    assert np.isin(volt, ticks_1khz).all() and len(volt) > 1900  # 1 ms ticks only, nearly every one
    assert not np.isin(plant, ticks_1khz).all()  # the plant moves between the law's ticks
    held = data["setpoint.reference"][(data["time"] > 0.5) & (data["time"] < 0.51)]
    assert len(set(held)) == 1 and held[0] == pytest.approx(0.025)  # held between 0.5 s and 0.51 s


@pytest.mark.parametrize("plant", ["single-mass", "double-mass"])
def test_clocked_example_scenarios_equal_their_unclocked_scenario(plant: str, native_fmus: tuple[Path, Path],
                                                                  native_fmus3: Path, clocked_fmus: Path) -> None:
    model = "LQRSingleMass" if plant == "single-mass" else "LQRDoubleMass"
    example = ipcosim.run(str(ROOT / "examples" / "clocked" / f"{plant}-lqr-clocked"), fmus="native",
                          fmu_dirs=[native_fmus[1], clocked_fmus], stop_time=0.5)
    plain = ipcosim.run(f"{plant}-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                        swap={"controller": str(native_fmus3 / f"{model}.fmu")})
    assert example.error is None and plain.error is None
    for name in plain.data.dtype.names:
        assert np.array_equal(plain.data[name], example.data[name]), name


def test_the_python_event_calls_equal_the_compiled_ones(monkeypatch: pytest.MonkeyPatch,
                                                         native_fmus: tuple[Path, Path], clocked_fmus: Path) -> None:
    """Without a C compiler the slave makes the same calls from Python: the same trajectory, and the
    Python loop instead of the C one."""
    from ipcosim.harness.master import clockstep

    def run() -> ipcosim.Result:
        return ipcosim.run("single-mass-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.3,
                           swap={"controller": str(clocked_fmus / "LQRSingleMassClocked.fmu")})

    compiled = run()
    monkeypatch.setattr(clockstep, "functions", lambda: None)
    python = run()
    assert compiled.metadata["loop"] == "c" and python.metadata["loop"].startswith("python")
    for name in compiled.data.dtype.names:
        assert np.array_equal(compiled.data[name], python.data[name]), name


def test_describe_lists_each_clock_and_its_period(native_fmus: tuple[Path, Path], clocked_fmus: Path,
                                                  tmp_path: Path) -> None:
    from ipcosim.harness.api.describe import describe, describe_text

    text = (ROOT / "examples" / "clocked" / "single-mass-lqr-multirate" / "SystemStructure.ssd").read_text()
    (tmp_path / "resources").mkdir()
    (tmp_path / "SystemStructure.ssd").write_text(
        re.sub(r"<ssd:ParameterBindings>\s*<ssd:ParameterBinding source=\"thesis.ssv\"/>\s*</ssd:ParameterBindings>",
               "", text))
    for name in ("SetpointClocked", "LQRSingleMassClocked"):
        (tmp_path / "resources" / f"{name}.fmu").write_bytes((clocked_fmus / f"{name}.fmu").read_bytes())
    plant = native_fmus[0] / "IP02SingleMass.fmu"
    (tmp_path / "resources" / plant.name).write_bytes(plant.read_bytes())
    info = describe(tmp_path)
    clocks = {c["name"]: c["clocks"] for c in info["components"]}
    assert clocks["setpoint"] == ["sample_clock (input clock, constant, every 0.01 s = 100 Hz)"]
    assert clocks["controller"] == ["sample_clock (input clock, constant, every 0.001 s = 1000 Hz)"]
    assert clocks["plant"] == []
    assert "  clock sample_clock (input clock, constant, every 0.001 s = 1000 Hz)" in describe_text(info)


def test_the_master_holds_one_event_mode_per_tick(native_fmus: tuple[Path, Path], clocked_fmus: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """0.3 s at 1 ms: ticks at 0, 1 ms, ..., 0.3 s, each one Event Mode (leaving initialization is the first)."""
    from ipcosim.harness.master import clocked, clockstep

    made: list[clocked.ClockedSlave] = []
    original = clocked.ClockedSlave.__init__

    def keep(self: clocked.ClockedSlave, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        made.append(self)

    monkeypatch.setattr(clocked.ClockedSlave, "__init__", keep)
    for functions in (clockstep.functions, lambda: None):  # the compiled calls, then the Python ones
        monkeypatch.setattr(clockstep, "functions", functions)
        made.clear()
        result = ipcosim.run("single-mass-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.3,
                             swap={"controller": str(clocked_fmus / "LQRSingleMassClocked.fmu")})
        assert result.error is None and len(made) == 1
        assert made[0].event_count == 301


def test_jacobi_runs_the_clocked_law_like_the_unclocked_one(native_fmus: tuple[Path, Path], native_fmus3: Path,
                                                            clocked_fmus: Path) -> None:
    """Jacobi: the law samples the values of the start of its period in both variants."""
    runs = [ipcosim.run("single-mass-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                        algorithm="jacobi", swap={"controller": str(fmu)})
            for fmu in (native_fmus3 / "LQRSingleMass.fmu", clocked_fmus / "LQRSingleMassClocked.fmu")]
    assert runs[0].error is None and runs[1].error is None
    for name in runs[0].data.dtype.names:
        assert np.array_equal(runs[0].data[name], runs[1].data[name]), name
    assert np.ptp(runs[1].data["plant.cart_position"]) > 1e-3
