"""The plant-kind registry (``ipcosim.fmus.kinds``): an unknown kind is an error, and a third kind (a gantry
crane: the IP02 cart with its pendulum hanging, ``tests/data/kinds/crane.py``) runs through the plant, the FMU
build (its plant and HIL-adapter FMUs from scripts the build makes from the kind), ``describe``, a run and the
native build with nothing added but its module and its registry line."""
from __future__ import annotations

import difflib
import importlib.util
import math
import shutil
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from ipcosim.fmus import kinds
from ipcosim.fmus.params import KINDS, PRESETS, ParameterError, make, preset
from ipcosim.fmus.plant import Plant

ROOT = Path(__file__).resolve().parents[2]
TOY = ROOT / "tests" / "data" / "kinds" / "crane.py"
REGISTRY = Path("fmus") / "kinds" / "__init__.py"
REGISTRY_LINES = ("from ipcosim.fmus.kinds import double_mass, single_mass\n",
                  "for module in (single_mass, double_mass)}")


def _load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def crane() -> ModuleType:
    return _load(TOY, "_toy_crane_kind")


# ------------------------------------------------------------------------------------------- unknown kinds


def test_an_unknown_kind_is_an_error_naming_the_closest() -> None:
    with pytest.raises(ParameterError, match=r"unknown plant kind 'doubel-mass'; did you mean 'double-mass'"):
        make("doubel-mass")
    with pytest.raises(kinds.UnknownKindError, match=r"unknown plant kind 'singel-mass'; did you mean 'single-mass'"):
        kinds.get("singel-mass")
    from ipcosim.fmus.physics import MEASURED, state_names
    with pytest.raises(KeyError):
        state_names("triple-mass")
    assert "triple-mass" not in MEASURED


def test_parameters_of_no_kind_are_no_single_mass() -> None:
    """What used to fall through to the single mass: a parameter class no kind declares, parameters no kind has."""
    from ipcosim.fmus.linearize import linear_matrices
    from ipcosim.fmus.params import plant_kind_of

    class Stranger(type(preset("thesis-ch3"))):  # a subclass is not its base's kind
        pass

    with pytest.raises(kinds.UnknownKindError, match="no plant kind has parameters of type Stranger"):
        plant_kind_of(Stranger())
    with pytest.raises(kinds.UnknownKindError):
        linear_matrices(Stranger())
    assert kinds.plant_kind(parameters=["Mp", "spring_rate"]) is None
    assert kinds.plant_kind(parameters=["K", "Mp"]) == "double-mass"


@pytest.mark.parametrize("name", KINDS)
def test_a_carts_declared_damping_is_its_viscous_force_to_the_track(name: str) -> None:
    """Raising a cart's ``damping`` parameter by 1 N s/m, that cart moving at v alone, adds -v N to the force on
    it (``applied_forces``) and nothing to the other carts' (a damper between carts would move both)."""
    from dataclasses import replace

    kind = kinds.get(name)
    p = preset(kind.default_preset)
    for c, cart in enumerate(kind.carts):
        assert p.__dataclass_fields__[cart.damping].metadata["unit"] == "N.s/m"
        x = [0.0] * len(kind.states)
        x[kind.states.index(cart.velocity)] = 0.3
        before = kind.applied_forces(x, p)
        after = kind.applied_forces(x, replace(p, **{cart.damping: getattr(p, cart.damping) + 1.0}))
        change = np.subtract(after, before)
        assert change[c] == pytest.approx(-0.3, rel=1e-12)
        assert np.delete(change, c) == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------------------------------- the toy kind


def test_a_registered_kind_is_in_every_table_and_gone_after(crane: ModuleType) -> None:
    from ipcosim.controllers.laws.base import PLANT_SUFFIX
    from ipcosim.fmus.instruments import realism
    from ipcosim.fmus.physics import MEASURED
    from ipcosim.harness.hil.swap import ADAPTERS
    from ipcosim.harness.scenario.scenarios import PLANTS

    with kinds.registered(crane.KIND):
        assert KINDS[-1] == "crane" and PRESETS["crane-long"] == ("crane", {"Lp": 0.6413}, "long pendulum hanging")
        assert MEASURED["crane"] == ("cart_position", "pendulum_angle")
        assert kinds.PLANT_MODELS["IP02Crane"] == "crane" and ADAPTERS["crane"] == "IP02HILCrane"
        assert PLANTS["crane"]["model"] == "IP02Crane" and PLANT_SUFFIX["crane"] == "Crane"
        assert realism("lab", "crane")[1] == {"b": 0.1047, "voltage_limit": 10.0}
        assert kinds.plant_kind("crane-pid") == "crane"
        with pytest.raises(kinds.KindError, match="registered already"):
            kinds.register(crane.KIND)
    assert "crane" not in KINDS and "crane-long" not in PRESETS and "IP02Crane" not in kinds.PLANT_MODELS


def test_the_crane_is_the_upright_plant_turned_over(crane: ModuleType) -> None:
    """Physics: the same cart and pendulum, the angle measured from the other end (th_upright = th + pi), under
    the same voltage; the two kinds integrate different forms (plain state, momenta), so they agree to the
    integrators' error (4e-5 rad after 2 s at 1 ms, 1.2e-6 at 0.25 ms), not to the bit."""
    h = 2.5e-4
    with kinds.registered(crane.KIND):
        hanging = Plant(preset("crane-medium"), [0.0, 0.0, 0.1, 0.0, 0.0])
        upright = Plant(preset("thesis-ch3"), [0.0, 0.0, 0.1 + math.pi, 0.0, 0.0])
        for k in range(8000):
            voltage = 2.0 * math.sin(7.0 * k * h)
            hanging.do_step(k * h, h, voltage)
            upright.do_step(k * h, h, voltage)
    turned = np.array(upright.state) - np.array([0.0, 0.0, math.pi, 0.0, 0.0])
    assert np.allclose(hanging.state, turned, rtol=0.0, atol=5e-6)
    assert abs(hanging.state[0]) > 1e-3  # the voltage did move the cart


def test_the_hanging_pendulum_swings_at_its_closed_form_frequency(crane: ModuleType) -> None:
    """A cart too heavy to move: the pendulum alone, omega^2 = Mp g (Lp/2) / (Mp Lp^2 / 3) = 3 g / (2 Lp)."""
    with kinds.registered(crane.KIND):
        p = preset("crane-medium", Mc=1e7, Bp=0.0)
        plant = Plant(p, [0.0, 0.0, 0.01, 0.0, 0.0])
        angles = []
        for k in range(6000):
            plant.do_step(k * 1e-3, 1e-3, 0.0)
            angles.append(plant.state[2])
    a = np.array(angles)
    up = np.flatnonzero((a[:-1] < 0.0) & (a[1:] >= 0.0))
    t = (up + (-a[up]) / (a[up + 1] - a[up]) + 1) * 1e-3  # crossing times, interpolated
    period = float(np.mean(np.diff(t)))
    assert period == pytest.approx(2.0 * math.pi / math.sqrt(3.0 * p.g / (2.0 * p.Lp)), rel=1e-4)


def _package_with(crane_source: Path, dest: Path) -> Path:
    """A copy of the package with the toy kind added as a project kind would be: its module, its registry line."""
    pkg = dest / "ipcosim"
    pkg.mkdir()
    for name in ("__init__.py", "errors.py", "toolchain.py"):
        shutil.copy(ROOT / name, pkg / name)
    for name in ("fmus", "controllers", "harness"):
        shutil.copytree(ROOT / name, pkg / name, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(crane_source, pkg / "fmus" / "kinds" / "crane.py")
    registry = pkg / REGISTRY
    text = registry.read_text()
    assert all(line in text for line in REGISTRY_LINES)
    text = text.replace(REGISTRY_LINES[0], "from ipcosim.fmus.kinds import crane, double_mass, single_mass\n")
    registry.write_text(text.replace(REGISTRY_LINES[1], "for module in (single_mass, double_mass, crane)}"))
    return pkg


def _changed(original: Path, copy: Path) -> dict[str, int]:
    """File (relative) -> number of changed lines, over the copied folders."""
    out = {}
    for f in sorted(copy.rglob("*.py")):
        rel = f.relative_to(copy)
        before = (original / rel).read_text().splitlines() if (original / rel).is_file() else []
        diff = [d for d in difflib.unified_diff(before, f.read_text().splitlines(), n=0, lineterm="")
                if d[:1] in "+-" and not d.startswith(("+++", "---"))]
        if diff:
            out[str(rel)] = len([d for d in diff if d.startswith("+")])
    return out


def test_the_crane_runs_through_the_fmu_build_describe_a_run_and_the_native_build(tmp_path: Path) -> None:
    from fmpy import read_model_description

    import ipcosim
    from ipcosim.fmus.pybuild import build_all, discover
    from ipcosim.harness.api.describe import describe
    from ipcosim.harness.native.cbuild import build_native

    pkg = _package_with(TOY, tmp_path)
    assert _changed(ROOT, pkg) == {str(REGISTRY): 2, "fmus/kinds/crane.py": len(TOY.read_text().splitlines())}

    scenario = tmp_path / "crane-pid"
    resources = scenario / "resources"
    shutil.copytree(ROOT / "ssp" / "single-mass-pid", scenario)
    ssd = scenario / "SystemStructure.ssd"
    ssd.write_text(ssd.read_text().replace("IP02SingleMass", "IP02Crane").replace("single-mass-pid", "crane-pid"))
    with kinds.registered(_load(pkg / "fmus" / "kinds" / "crane.py", "_toy_crane_kind_build").KIND):
        generated = [s for s in discover(pkg) if not s.is_relative_to(pkg)]  # no script file: made from the kind
        assert sorted(s.name for s in generated) == ["fmu_ip02_crane.py", "fmu_ip02_hil_crane.py"]
        built = build_all(resources, root=pkg, scripts=generated)
    assert sorted(r.fmu.name for r in built) == ["IP02Crane.fmu", "IP02HILCrane.fmu"]
    adapter = read_model_description(str(resources / "IP02HILCrane.fmu"))  # the plant's connectors on a card
    ports = {v.name: v.causality for v in adapter.modelVariables}
    assert ports["voltage"] == "input" and [ports[m] for m in ("cart_position", "pendulum_angle")] == ["output"] * 2
    build_all(resources, scripts=[ROOT / "controllers" / "fmu_pid_single_mass.py",
                                  ROOT / "controllers" / "fmu_setpoint.py"])

    info = describe(ssd)
    plant = next(c for c in info["components"] if c["name"] == "plant")
    names = {v["name"]: v for v in plant["variables"]}
    assert plant["model"] == "IP02Crane" and names["Lp"]["start"] == 0.6413  # the kind's default preset
    assert {"cart_position", "pendulum_angle", "initial_pendulum_angle", "b"} <= set(names)

    start = {"plant.initial_pendulum_angle": 0.2}
    python = ipcosim.run(ssd, stop_time=1.0, set=start, out=tmp_path / "out-python", progress=False)
    assert python.data["plant.pendulum_angle"].min() < -0.05  # from +0.2 rad through 0: it hangs, it does not fall

    # the FMU ran the toy kind's equations: its plant in-process under the run's voltages gives the run's states
    with kinds.registered(_load(pkg / "fmus" / "kinds" / "crane.py", "_toy_crane_kind_copy").KIND) as kind:
        replay = Plant(preset("crane-long"), [0.0, 0.0, 0.2, 0.0, 0.0])
        volts = python.data["controller.voltage"]
        for k in range(len(volts) - 1):
            replay.do_step(k * 1e-3, 1e-3, float(volts[k]))
        assert replay.state[2] == pytest.approx(float(python.data["plant.pendulum_angle"][-1]), abs=1e-12)

        native = tmp_path / "native"
        build_native(resources, native, names=[kind.model])
    swapped = ipcosim.run(ssd, stop_time=1.0, set=start, swap={"plant": str(native / "IP02Crane.fmu")},
                          out=tmp_path / "out-native", progress=False)
    for column in ("plant.cart_position", "plant.pendulum_angle", "controller.voltage"):
        assert np.allclose(swapped.data[column], python.data[column], rtol=0.0, atol=1e-9), column
