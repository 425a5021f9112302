"""The controller FMUs <Law><Plant> and Setpoint, built into a temporary folder: valid for fmpy and
VDMCheck2, the contract's variables/units/structure, outputs at t = 0, sampling, the same
closed-loop trajectory through fmpy as the pure loop, and one clear FMI error per bad parameter."""
from __future__ import annotations

import math
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmi_helpers import assert_vdmcheck_clean, instantiate
from fmpy.validation import validate_fmu

from ipcosim.controllers.catalog import KINDS, LAWS, make_law, model_name, schema
from ipcosim.controllers.reference import reference_at
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.params import DEFAULT_PRESET, preset
from ipcosim.fmus.physics import MEASURED

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
MODELS = [model_name(kind, law) for law in LAWS for kind in KINDS]
FMI_DISCARD, FMI_FATAL = 2, 4
H = 1e-3


@pytest.fixture(scope="session")
def controller_fmus(project_fmus: dict[str, Path]) -> dict[str, Path]:
    """Every controller FMU and Setpoint of this run's build: ``{model name: path}``."""
    return {fmu.stem: fmu for key, fmu in project_fmus.items() if key.startswith("controllers/")}


def plant_kind_of(model: str) -> str:
    return "single-mass" if model.endswith("SingleMass") else "double-mass"


def law_of(model: str) -> str:
    return model[: -len("SingleMass")]


def model_description(fmu: Path) -> ElementTree.Element:
    with zipfile.ZipFile(fmu) as z:
        return ElementTree.fromstring(z.read("modelDescription.xml"))


def start(fmu: Path, **params):
    f = instantiate(fmu)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    for name, value in params.items():
        if isinstance(value, bool):
            f.slave.setBoolean([f.vr[name]], [value])
        else:
            f.set(**{name: value})
    return f


def cosimulate(controller: Path, plant: Path, setpoint: Path, kind: str, n: int, controller_params=None,
               setpoint_params=None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Seidel through fmpy (setpoint, plant, controller; the controller samples the plant's new
    positions), 1 ms steps. Returns (measured positions (n+1, p), voltage (n+1,))."""
    sp = start(setpoint, **(setpoint_params or {}))
    pl = start(plant)
    ct = start(controller, **(controller_params or {}))
    meas = MEASURED[kind]
    sp.slave.exitInitializationMode()
    pl.slave.exitInitializationMode()
    ct.set(reference=sp.get("reference")[0], **dict(zip(meas, pl.get(*meas))))
    ct.slave.exitInitializationMode()
    ys, us = [], []
    u = ct.get("voltage")[0]
    for i in range(n + 1):
        t = i * H
        ys.append(pl.get(*meas))
        us.append(u)
        if i == n:
            break
        sp.slave.doStep(t, H)
        pl.set(voltage=u)
        pl.slave.doStep(t, H)
        ct.set(reference=sp.get("reference")[0], **dict(zip(meas, pl.get(*meas))))
        ct.slave.doStep(t, H)
        u = ct.get("voltage")[0]
    for f in (sp, pl, ct):
        f.slave.terminate()
        f.slave.freeInstance()
    return np.array(ys), np.array(us)


# --- validity ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("model", MODELS + ["Setpoint"])
def test_fmpy_validation_has_no_problems(controller_fmus, model: str) -> None:
    assert validate_fmu(str(controller_fmus[model])) == []


@pytest.mark.parametrize("model", MODELS + ["Setpoint"])
@pytest.mark.slow
def test_vdmcheck_reports_no_errors(controller_fmus, model: str) -> None:
    assert_vdmcheck_clean(controller_fmus[model])


@pytest.mark.parametrize("model", MODELS)
def test_contract_variables_units_and_structure(controller_fmus, model: str) -> None:
    kind, law = plant_kind_of(model), law_of(model)
    root = model_description(controller_fmus[model])
    assert root.get("modelName") == model
    svs = list(root.iter("ScalarVariable"))
    by_name = {sv.get("name"): sv for sv in svs}
    index = {sv.get("name"): k + 1 for k, sv in enumerate(svs)}
    inputs = [sv.get("name") for sv in svs if sv.get("causality") == "input"]
    assert inputs == ["reference", *MEASURED[kind]]
    assert [sv.get("name") for sv in svs if sv.get("causality") == "output"] == ["voltage"]
    assert by_name["voltage"].find("Real").get("unit") == "V"
    assert by_name["reference"].find("Real").get("unit") == "m"
    # every parameter of the law, documented, with a unit (Booleans excepted)
    for spec in schema(kind, law):
        sv = by_name[spec.name]
        assert sv.get("causality") == "parameter" and sv.get("description")
        if spec.constraint != "bool":
            assert sv.find("Real").get("unit") == spec.unit
    assert by_name["sample_period"].find("Real").get("start") in ("0.001", "1e-3", "0.0010")
    assert float(by_name["voltage_limit"].find("Real").get("start")) == 10.0
    # the output depends directly on every input (sampled without delay)
    unknown = root.find("ModelStructure/Outputs/Unknown")
    assert unknown.get("index") == str(index["voltage"])
    assert sorted(map(int, unknown.get("dependencies").split())) == sorted(index[n] for n in inputs)
    if law in ("LQR", "LQG"):
        # the gains are parameters too (designed at build time): K per state, N (LQR) or K_voltage and
        # K_integral (LQG), M per state and output
        from ipcosim.controllers.catalog import gain_specs
        n, p = (4, 2) if kind == "single-mass" else (6, 3)
        gains = gain_specs(kind, law)
        assert len(gains) == n + (1 if law == "LQR" else 2) + n * p
        for spec in gains:
            sv = by_name[spec.name]
            assert sv.get("causality") == "parameter" and sv.find("Real").get("unit") == spec.unit
            assert math.isfinite(float(sv.find("Real").get("start")))
        assert float(by_name["K_pendulum_angle"].find("Real").get("start")) != 0.0


@pytest.mark.parametrize("model", ["LQRSingleMass", "HSMCDoubleMass", "CascadePIDSingleMass"])
def test_output_is_right_at_time_zero(controller_fmus, model: str) -> None:
    kind, law = plant_kind_of(model), law_of(model)
    y0 = [0.01, -0.02] if kind == "single-mass" else [0.01, 0.005, -0.02]
    f = start(controller_fmus[model])
    f.set(reference=0.05, **dict(zip(MEASURED[kind], y0)))
    f.slave.exitInitializationMode()
    expected = make_law(kind, law).step(y0, 0.05)
    assert f.get("voltage")[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert f.get("voltage")[0] != 0.0


def test_setpoint_waveforms_and_time_zero(controller_fmus) -> None:
    f = start(controller_fmus["Setpoint"])
    f.slave.exitInitializationMode()
    assert f.get("reference")[0] == 0.05
    g = start(controller_fmus["Setpoint"], amplitude=0.04, step_time=0.5, ramp_rate=0.1)
    g.slave.setInteger([g.vr["waveform"]], [1])
    g.slave.exitInitializationMode()
    vals = [g.get("reference")[0]]
    for i in range(1000):
        g.slave.doStep(i * H, H)
        vals.append(g.get("reference")[0])
    expected = [reference_at(i * H, 1, 0.04, 0.5, 0.0, 0.1, 4.0) for i in range(1001)]
    assert np.allclose(vals, expected, atol=1e-15)
    assert vals[0] == 0.0 and vals[-1] == pytest.approx(0.04)


# --- same numbers as the pure loop ---------------------------------------------------------------------

@pytest.mark.parametrize("model", MODELS)
def test_closed_loop_through_fmpy_equals_the_pure_loop(controller_fmus, plant_fmus, model: str) -> None:
    kind, law = plant_kind_of(model), law_of(model)
    n = 3000
    ys, us = cosimulate(controller_fmus[model], plant_fmus[kind], controller_fmus["Setpoint"], kind, n)
    ref = run_loop(make_law(kind, law), preset(DEFAULT_PRESET[kind]), stop_time=n * H)
    idx = [ref.state_names.index(m) for m in MEASURED[kind]]
    assert np.allclose(ys, ref.states[:, idx], rtol=0, atol=1e-9)
    assert np.allclose(us, ref.voltage, rtol=0, atol=1e-7)


def test_sample_period_holds_the_output(controller_fmus, plant_fmus) -> None:
    """With sample_period = 4 ms and 1 ms communication steps the voltage changes only every 4th step,
    and the trajectory equals the pure loop's with the same sample period."""
    n = 400
    ys, us = cosimulate(controller_fmus["LQRSingleMass"], plant_fmus["single-mass"], controller_fmus["Setpoint"],
                        "single-mass", n, controller_params={"sample_period": 0.004})
    assert np.all(us[:-1].reshape(-1, 4) == us[:-1].reshape(-1, 4)[:, :1])
    ref = run_loop(make_law("single-mass", "LQR", sample_period=0.004), preset("thesis-ch3"), stop_time=n * H)
    assert np.allclose(us, ref.voltage, atol=1e-7)


def test_a_changed_weight_gives_the_gains_it_implies(controller_fmus) -> None:
    f = start(controller_fmus["LQRDoubleMass"], Q_pendulum_angle=3400.0, R=0.01)
    f.slave.exitInitializationMode()
    K = f.get("K_active_cart_position", "K_active_cart_velocity", "K_passive_cart_position",
              "K_passive_cart_velocity", "K_pendulum_angle", "K_pendulum_velocity")
    law = make_law("double-mass", "LQR", Q_pendulum_angle=3400.0, R=0.01)
    assert np.allclose(K, law.design.K[0], rtol=1e-9)
    assert f.get("N")[0] == pytest.approx(law.design.N, rel=1e-9)
    g = start(controller_fmus["LQRDoubleMass"])
    g.slave.exitInitializationMode()
    K0 = g.get("K_active_cart_position", "K_active_cart_velocity", "K_passive_cart_position",
               "K_passive_cart_velocity", "K_pendulum_angle", "K_pendulum_velocity")
    thesis = [1182.2, 38.6, -1292.9, -181.7, 885.9, 87.8]
    assert np.allclose(K0, thesis, rtol=1e-3)
    assert not np.allclose(K, K0, rtol=1e-2)


def test_step_longer_than_the_sample_period_is_discarded(controller_fmus) -> None:
    f = start(controller_fmus["PIDSingleMass"])
    f.slave.exitInitializationMode()
    from fmpy.fmi1 import FMICallException

    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, 0.002)
    assert info.value.status == FMI_DISCARD
    assert "longer than sample_period" in f.text()


def test_non_finite_measurement_discards_the_step(controller_fmus) -> None:
    f = start(controller_fmus["HSMCSingleMass"])
    f.slave.exitInitializationMode()
    f.set(pendulum_angle=math.nan)
    from fmpy.fmi1 import FMICallException

    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, H)
    assert info.value.status == FMI_DISCARD and "pendulum_angle" in f.text()


# --- bad parameters: one clear FMI error naming the parameter ---------------------------------------------

BAD = [
    ("PIDSingleMass", dict(sample_period=0.0), "parameter sample_period = 0.0 s: must be > 0"),
    ("PIDDoubleMass", dict(Kp=math.nan), "parameter Kp = nan V/m: not a finite number"),
    ("CascadePIDSingleMass", dict(Kd_th=math.inf), "parameter Kd_th = inf"),
    ("LQRSingleMass", dict(Q_pendulum_angle=-1.0), "parameter Q_pendulum_angle = -1.0 1/rad2: must be >= 0"),
    ("LQRSingleMass", dict(R=0.0), "parameter R = 0.0 1/V2: must be > 0"),
    ("LQRDoubleMass", dict(model_K=0.0, model_Bf=0.0), "parameters model_*: design model is not controllable"),
    ("LQRSingleMass", dict(observer_pole_1_re=-100.0, observer_pole_1_im=0.0, observer_pole_2_re=-100.0,
                           observer_pole_2_im=0.0), "parameters observer_pole_*"),
    ("LQRSingleMass", dict(Q_cart_position=0.0, Q_cart_velocity=0.0, Q_pendulum_angle=0.0,
                           Q_pendulum_velocity=0.0), "parameters Q_*: LQR has no stabilizing solution"),
    ("LQRDoubleMass", dict(model_Mp=-0.1), "parameter model_Mp = -0.1 kg: must be > 0"),
    ("HSMCSingleMass", dict(c1=0.0), "parameter c1 = 0.0 1/s: must be > 0"),
    # lambda1 b1 + lambda2 b2 = 0 for the default design model (b2/b1 = 0.224733...)
    ("HSMCSingleMass", dict(lambda1=-0.22473333333333334, lambda2=1.0), "denominator"),
    ("AdaptiveHSMCDoubleMass", dict(k_delta=-100.0), "parameter k_delta = -100.0: the schedule k(t)"),
    ("AdaptiveHSMCSingleMass", dict(voltage_limit=-1.0), "parameter voltage_limit = -1.0 V: must be > 0"),
]


@pytest.mark.parametrize("model,params,message", BAD, ids=[f"{m}-{'-'.join(p)}" for m, p, _ in BAD])
def test_bad_parameter_is_an_fmi_error_naming_it(controller_fmus, model: str, params: dict, message: str) -> None:
    from fmpy.fmi1 import FMICallException

    f = start(controller_fmus[model], **params)
    with pytest.raises(FMICallException):
        f.slave.exitInitializationMode()
    fatal = [m for m in f.messages if m[0] == FMI_FATAL]
    assert fatal, f.messages
    last = fatal[-1][2].strip().splitlines()[-1]
    assert message in last, last


def test_hsmc_denominator_case_is_really_degenerate() -> None:
    """The HSMCSingleMass case above: lambda1 b1 + lambda2 b2 ~ 0 for the default design model."""
    from ipcosim.controllers.design import design_model
    from ipcosim.controllers.laws.hsmc import subsystem_models

    b = [m.b for m in subsystem_models(design_model(preset("thesis-ch3")))]
    assert abs(-0.22473333333333334 * b[0] + b[1]) < 1e-3
    assert abs(-0.35 * b[0] + b[1]) > 0.5  # the thesis's lambda1 is far from it


def test_bad_setpoint_parameter(controller_fmus) -> None:
    from fmpy.fmi1 import FMICallException

    f = start(controller_fmus["Setpoint"], ramp_rate=0.0)
    f.slave.setInteger([f.vr["waveform"]], [1])
    with pytest.raises(FMICallException):
        f.slave.exitInitializationMode()
    assert "ramp_rate" in f.text()


def test_a_controller_fmu_packs_only_its_own_law() -> None:
    """The project files a controller FMU carries (``pybuild.runtime_modules``, the closure of its script's
    imports) hold one law's modules, its own and its companions (``<law>_*.py``, e.g. the HSMC's numbers) --
    the swing-up's also the LQR it balances with -- and never the registry that knows every law."""
    import importlib.util
    import sys

    from ipcosim.controllers.catalog import REGISTRY
    from ipcosim.controllers.controller_fmu import ControllerFmu
    from ipcosim.fmus.pybuild import ROOT, discover, runtime_modules

    laws = ROOT / "controllers" / "laws"
    seen = set()
    for script in discover():
        spec = importlib.util.spec_from_file_location(f"_script_{script.stem}", script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        cls = next((c for c in vars(module).values() if isinstance(c, type) and issubclass(c, ControllerFmu)
                    and c is not ControllerFmu), None)
        if cls is None:
            continue  # a plant or the setpoint
        own = Path(sys.modules[cls.law.build.__module__].__file__).resolve()
        files = {f.resolve() for f in runtime_modules(script)}
        packed = {f for f in files if f.parent == laws and f.name not in ("__init__.py", "base.py")}
        own_modules = {own, *laws.glob(f"{own.stem}_*.py")}
        expected = own_modules | {laws / "lqr.py"} if cls.law.name == "SwingUp" else own_modules
        assert packed == expected, f"{script.name} packs {sorted(p.name for p in packed)}"
        assert ROOT / "controllers" / "catalog.py" not in files, f"{script.name} packs the registry"
        seen.add(cls.law.name)
    assert seen == set(REGISTRY), f"laws without an FMU script: {set(REGISTRY) - seen}"
