"""The plant FMUs IP02SingleMass and IP02DoubleMass, built into a temporary folder: valid for
fmpy and VDMCheck2, the contract's variables/units/structure, outputs at t = 0, the same
numbers as the pure model through fmpy (1e-12) and through libcosim (1e-9), and clear FMI
errors for bad parameters and non-finite states."""
from __future__ import annotations

import math
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmi_helpers import assert_vdmcheck_clean, instantiate
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from ipcosim.fmus.params import DEFAULT_PRESET, PLANT_KINDS, parameter_info, preset
from ipcosim.fmus.physics import MEASURED, STATE_UNITS, state_names
from ipcosim.fmus.plant import Plant

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
KINDS = ["single-mass", "double-mass"]
FMI_DISCARD, FMI_ERROR, FMI_FATAL = 2, 3, 4
H = 1e-3


@pytest.fixture(scope="module")
def unzipped(plant_fmus: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return {k: tmp_path_factory.mktemp(f"unzipped-{k}") for k in plant_fmus}


def model_description(fmu: Path) -> ElementTree.Element:
    with zipfile.ZipFile(fmu) as z:
        return ElementTree.fromstring(z.read("modelDescription.xml"))


def voltage_sequence(n: int) -> list[float]:
    """A test input: pulse, sine, and a stretch beyond the amplifier limit."""
    return [(6.0 if 50 <= k < 150 else 0.0) + 3.0 * math.sin(0.02 * k) + (15.0 if 300 <= k < 320 else 0.0)
            for k in range(n)]


def start(fmu: Path, unzip: Path, **params: float):
    f = instantiate(fmu, unzip)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    f.set(**params)
    return f


@pytest.mark.parametrize("kind", KINDS)
def test_fmpy_validation_has_no_problems(plant_fmus: dict[str, Path], kind: str) -> None:
    assert validate_fmu(str(plant_fmus[kind])) == []


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.slow
def test_vdmcheck_reports_no_errors(plant_fmus: dict[str, Path], kind: str) -> None:
    assert_vdmcheck_clean(plant_fmus[kind])


@pytest.mark.parametrize("kind", KINDS)
def test_variables_units_and_structure(plant_fmus: dict[str, Path], kind: str) -> None:
    root = model_description(plant_fmus[kind])
    assert root.get("modelName") == {"single-mass": "IP02SingleMass", "double-mass": "IP02DoubleMass"}[kind]
    svs = list(root.iter("ScalarVariable"))
    by_name = {sv.get("name"): sv for sv in svs}
    index = {sv.get("name"): k + 1 for k, sv in enumerate(svs)}
    unit = {n: sv.find("Real").get("unit") for n, sv in by_name.items()}
    defined = {u.get("name") for u in root.iter("Unit")}
    assert set(unit.values()) <= defined

    inputs = [sv.get("name") for sv in svs if sv.get("causality") == "input"]
    outputs = [sv.get("name") for sv in svs if sv.get("causality") == "output"]
    assert inputs == ["voltage"] and unit["voltage"] == "V"
    measured = list(MEASURED[kind])
    assert outputs[:len(measured)] == measured  # encoder positions first
    assert sorted(outputs) == sorted(state_names(kind))
    for name in state_names(kind):
        assert unit[name] == STATE_UNITS[name]
        p = by_name[f"initial_{name}"]
        assert p.get("causality") == "parameter" and unit[f"initial_{name}"] == STATE_UNITS[name]
        assert float(p.find("Real").get("start")) == 0.0

    defaults = dict(preset(DEFAULT_PRESET[kind]).__dict__)
    for info in parameter_info(PLANT_KINDS[kind]):
        sv = by_name[info["name"]]
        assert sv.get("causality") == "parameter" and sv.get("variability") == "fixed"
        assert unit[info["name"]] == info["unit"]
        assert info["doc"] in sv.get("description")
        assert float(sv.find("Real").get("start")) == pytest.approx(defaults[info["name"]], rel=1e-15)

    # no output depends directly on the voltage: no algebraic loop for a master
    deps = {int(u.get("index")): u.get("dependencies") for u in root.find("ModelStructure/Outputs")}
    assert deps == {index[n]: "" for n in outputs}
    initial = {int(u.get("index")): u.get("dependencies") for u in root.find("ModelStructure/InitialUnknowns")}
    assert initial == {index[n]: str(index[f"initial_{n}"]) for n in outputs}


@pytest.mark.parametrize("kind", KINDS)
def test_outputs_are_right_at_time_zero(plant_fmus, unzipped, kind: str) -> None:
    names = state_names(kind)
    x0 = {f"initial_{n}": 0.01 * (k + 1) for k, n in enumerate(names)}
    f = start(plant_fmus[kind], unzipped[kind], **x0)
    f.slave.exitInitializationMode()
    assert f.get(*names) == [x0[f"initial_{n}"] for n in names]
    f.slave.terminate()
    f.slave.freeInstance()


CASES = [("single-mass", {}, {}), ("single-mass", {"Lp": 0.6413}, {"initial_pendulum_angle": 0.05}),
         ("double-mass", {}, {"initial_pendulum_angle": -0.03, "initial_passive_cart_position": 0.01})]


@pytest.mark.parametrize("kind, overrides, initial", CASES)
def test_fmu_reproduces_pure_plant(plant_fmus, unzipped, kind: str, overrides: dict, initial: dict) -> None:
    """Driven through fmpy, the FMU gives the pure model's numbers (1e-12); Lp = 0.6413 is the
    long-pendulum preset thesis-appendix-a."""
    names = state_names(kind)
    params = preset(DEFAULT_PRESET[kind], **overrides)
    if overrides:
        assert params == preset("thesis-appendix-a")
    plant = Plant(params, [initial.get(f"initial_{n}", 0.0) for n in names])
    f = start(plant_fmus[kind], unzipped[kind], **overrides, **initial)
    f.slave.exitInitializationMode()
    worst = 0.0
    for k, v in enumerate(voltage_sequence(1000)):
        f.set(voltage=v)
        f.slave.doStep(k * H, H)
        plant.do_step(k * H, H, v)
        worst = max(worst, float(np.max(np.abs(np.array(f.get(*names)) - plant.x))))
    assert np.max(np.abs(plant.x[[0, names.index("pendulum_angle")]])) > 1e-3  # something happened
    assert worst <= 1e-12
    f.slave.terminate()
    f.slave.freeInstance()


@pytest.mark.parametrize("kind", KINDS)
def test_instances_are_independent(plant_fmus, unzipped, kind: str) -> None:
    a = start(plant_fmus[kind], unzipped[kind], Mp=0.1)
    b = start(plant_fmus[kind], unzipped[kind], Mp=0.3)
    a.slave.exitInitializationMode()
    b.slave.exitInitializationMode()
    for k in range(200):
        for f in (a, b):
            f.set(voltage=4.0)
            f.slave.doStep(k * H, H)
    pa, pb = a.get("pendulum_angle")[0], b.get("pendulum_angle")[0]
    ref = Plant(preset(DEFAULT_PRESET[kind], Mp=0.1))
    for k in range(200):
        ref.do_step(k * H, H, 4.0)
    assert pa == pytest.approx(ref.values()["pendulum_angle"], abs=1e-12)
    assert abs(pa - pb) > 1e-4
    for f in (a, b):
        f.slave.freeInstance()


@pytest.mark.parametrize("kind", KINDS)
def test_many_instances(plant_fmus, unzipped, kind: str) -> None:
    """The FMU script's class defines no method, so only ipcosim.fmus.fmi's compensation keeps the script
    module alive across pythonfmu 0.7.0's per-instantiation reference release."""
    import gc
    for k in range(8):
        f = start(plant_fmus[kind], unzipped[kind], initial_pendulum_angle=0.01 * k)
        f.slave.exitInitializationMode()
        assert f.get("pendulum_angle") == [0.01 * k]
        f.slave.freeInstance()
        gc.collect()


@pytest.mark.parametrize("kind", KINDS)
def test_libcosim_produces_the_same_trajectory(plant_fmus, kind: str) -> None:
    libcosim = pytest.importorskip("libcosimpy.CosimExecution")
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    execution = libcosim.CosimExecution.from_step_size(int(H * 1e9))
    index = execution.add_local_slave(CosimLocalSlave(fmu_path=str(plant_fmus[kind]), instance_name="plant"))
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
    assert execution.real_initial_value(index, vr["initial_pendulum_angle"], 0.1)
    override = CosimManipulator.create_override()
    execution.add_manipulator(override)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)

    names = state_names(kind)
    x0 = [0.1 if n == "pendulum_angle" else 0.0 for n in names]
    plant = Plant(preset(DEFAULT_PRESET[kind]), x0)
    worst = 0.0
    for k, v in enumerate(voltage_sequence(600)):
        assert override.slave_real_values(index, [vr["voltage"]], [v])
        assert execution.step()
        plant.do_step(k * H, H, v)
        got = observer.last_real_values(index, [vr[n] for n in names])
        worst = max(worst, float(np.max(np.abs(np.array(got) - plant.x))))
    assert execution.status().current_time == int(600 * H * 1e9)
    assert abs(plant.values()["pendulum_angle"] - 0.1) > 0.1  # it fell: a real trajectory
    assert worst <= 1e-9


BAD = [("single-mass", "Mp", 0.0, "parameter Mp = 0.0 kg must be > 0"),
       ("single-mass", "Lp", -0.3, "parameter Lp = -0.3 m must be > 0"),
       ("single-mass", "Mc", float("nan"), "parameter Mc = nan kg: not a finite number"),
       ("single-mass", "initial_pendulum_angle", float("inf"), "parameter initial_pendulum_angle = inf rad: not a"),
       ("double-mass", "K", float("inf"), "parameter K = inf N/m: not a finite number"),
       ("double-mass", "Ma", -1.0, "parameter Ma = -1.0 kg must be > 0"),
       ("double-mass", "Bf", -2.0, "parameter Bf = -2.0 N.s/m must be >= 0")]


@pytest.mark.parametrize("kind, name, value, expected", BAD, ids=[f"{k}-{n}={v}" for k, n, v, _ in BAD])
def test_bad_parameter_is_an_fmi_error_naming_it(plant_fmus, unzipped, kind, name, value, expected) -> None:
    f = start(plant_fmus[kind], unzipped[kind], **{name: value})
    with pytest.raises(FMICallException) as info:
        f.slave.exitInitializationMode()
    assert info.value.status == FMI_FATAL
    fatal = [m[2] for m in f.messages if m[0] == FMI_FATAL]
    assert fatal and fatal[0].splitlines()[-1].startswith(expected), f.messages
    f.slave.freeInstance()


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("kind", KINDS)
def test_non_finite_state_fails_the_step_with_time_and_state(plant_fmus, unzipped, kind) -> None:
    f = start(plant_fmus[kind], unzipped[kind], initial_pendulum_velocity=1e160, initial_pendulum_angle=0.2)
    f.slave.exitInitializationMode()
    f.set(voltage=1.0)
    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, H)  # the first step starts at the start time (FMI call order)
    assert info.value.status == FMI_DISCARD
    errors = [m[2] for m in f.messages if m[0] == FMI_ERROR]
    assert len(errors) == 1
    assert "non-finite" in errors[0] and "t = 0 s" in errors[0]
    assert "pendulum_velocity = 1e+160" in errors[0] and "pendulum_angle = 0.2" in errors[0]
    assert f.get("pendulum_angle", "pendulum_velocity") == [0.2, 1e160]  # kept at t
    f.slave.freeInstance()


@pytest.mark.parametrize("kind", KINDS)
def test_non_finite_voltage_fails_the_step(plant_fmus, unzipped, kind) -> None:
    f = start(plant_fmus[kind], unzipped[kind])
    f.slave.exitInitializationMode()
    f.set(voltage=float("nan"))
    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, H)  # the first step starts at the start time (FMI call order)
    assert info.value.status == FMI_DISCARD
    assert any(m[0] == FMI_ERROR and "voltage = nan V at t = 0.0 s" in m[2] for m in f.messages), f.messages
    f.slave.freeInstance()
