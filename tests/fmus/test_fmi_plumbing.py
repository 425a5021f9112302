"""ipcosim.fmus.fmi (the shared FMU plumbing over pythonfmu 0.7.0) and ipcosim.fmus.pybuild: model description
content, the status codes and log messages an importer sees, several instances per process,
tunable/fixed parameters, and the incremental build."""
from __future__ import annotations

import shutil
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import pytest
from fmi_helpers import assert_vdmcheck_clean, instantiate, private_resource
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from ipcosim.fmus.fmi import FmuBase, FmuError, parse_unit
from ipcosim.fmus.pybuild import BuildError, build_all, check_fmu

ROOT = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).resolve().parents[1] / "data" / "fmu_plumbing_probe.py"

FMI_OK, FMI_DISCARD, FMI_ERROR, FMI_FATAL = 0, 2, 3, 4


# --- pure ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("unit, exps", [
    ("m", {"m": 1}), ("m/s2", {"m": 1, "s": -2}), ("1", {}), ("N.m/A", {"kg": 1, "m": 2, "s": -2, "A": -1}),
    ("V.s/rad", {"kg": 1, "m": 2, "s": -2, "A": -1, "rad": -1}), ("kg.m2", {"kg": 1, "m": 2}),
    ("N.m.s/rad", {"kg": 1, "m": 2, "s": -1, "rad": -1}), ("Ohm", {"kg": 1, "m": 2, "s": -3, "A": -2}),
    ("H", {"kg": 1, "m": 2, "s": -2, "A": -2}), ("V/m", {"kg": 1, "m": 1, "s": -3, "A": -1}), ("1/s", {"s": -1}),
    ("N.s/m", {"kg": 1, "s": -1}), ("s-1", {"s": -1}),
])
def test_parse_unit(unit: str, exps: dict) -> None:
    assert parse_unit(unit) == exps


def test_parse_unit_rejects_unknown_symbols() -> None:
    with pytest.raises(ValueError, match="furlong"):
        parse_unit("furlong/s")


def _probe_class():
    import importlib.util
    spec = importlib.util.spec_from_file_location("fmu_plumbing_probe", PROBE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.PlumbingProbe


def test_model_description_of_a_direct_instance() -> None:
    probe = _probe_class()(instance_name="direct")
    root = probe.to_xml()
    svs = {sv.get("name"): sv for sv in root.iter("ScalarVariable")}
    index = {name: k + 1 for k, name in enumerate(svs)}
    assert svs["y"].find("Real").get("unit") == "V.s"
    assert svs["y"].get("initial") == "calculated" and svs["y"].find("Real").get("start") is None
    assert svs["steps"].get("variability") == "discrete" and svs["steps"].get("initial") == "exact"
    assert svs["gain"].get("variability") == "fixed" and svs["offset"].get("variability") == "tunable"
    assert {u.get("name") for u in root.iter("Unit")} == {"V", "V.s", "1"}
    outputs = {int(u.get("index")): u.get("dependencies") for u in root.find("ModelStructure/Outputs")}
    assert outputs == {index["y"]: "", index["u_copy"]: str(index["u"]), index["steps"]: ""}
    initial = {int(u.get("index")): u.get("dependencies") for u in root.find("ModelStructure/InitialUnknowns")}
    assert initial == {index["y"]: str(index["y0"]), index["u_copy"]: str(index["u"])}
    assert root.get("description").startswith("Integrates its input")


def test_direct_instance_steps_and_reports() -> None:
    probe = _probe_class()(instance_name="direct")
    probe.set_real([probe.info["u"].value_reference], [2.0])
    probe.exit_initialization_mode()
    assert probe.do_step(0.0, 0.5) is True
    assert probe.get_real([probe.info["y"].value_reference]) == [1.0]
    probe.set_real([probe.info["u"].value_reference], [float("inf")])
    assert probe.do_step(0.5, 0.5) is False
    assert "y became inf in the step from t = 0.5 s" in probe.log_queue[-1].msg
    with pytest.raises(FmuError, match="parameter gain is fixed"):
        probe.set_real([probe.info["gain"].value_reference], [3.0])


def test_declaration_errors() -> None:
    class Clash(FmuBase):
        def __init__(self, **kw):
            super().__init__(**kw)
            self.add_parameter("description", start=1.0)

    with pytest.raises(FmuError, match="clashes"):
        Clash(instance_name="x")

    class BadDependency(FmuBase):
        def __init__(self, **kw):
            super().__init__(**kw)
            self.add_parameter("p", start=1.0)
            self.add_output("y", depends_on=("p",))

    with pytest.raises(FmuError, match="not an input"):
        BadDependency(instance_name="x").to_xml()


# --- built FMU --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def probe_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("probe-fmu")
    (result,) = build_all(out, scripts=[PROBE])
    return result.fmu


@pytest.fixture(scope="module")
def probe_dir(probe_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("probe-unzipped")


def start(fmu: Path, unzip: Path, **params: float):
    f = instantiate(fmu, unzip)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    for name, value in params.items():
        if name == "fail_mode":
            f.slave.setInteger([f.vr[name]], [int(value)])
        else:
            f.set(**{name: value})
    return f


@pytest.mark.integration
def test_probe_fmu_is_valid(probe_fmu: Path) -> None:
    assert validate_fmu(str(probe_fmu)) == []
    names = zipfile.ZipFile(probe_fmu).namelist()
    assert private_resource(names, "fmus/fmi.py") and not any(n.startswith("resources/fmus/") for n in names)
    # bytecode only as hash-checked .pyc next to its source (never stale bytecode that skips its check)
    z = zipfile.ZipFile(probe_fmu)
    pycs = [n for n in names if "__pycache__" in n]
    assert pycs
    for n in pycs:
        folder, _, file = n.rpartition("/__pycache__/")
        assert f"{folder}/{file.split('.')[0]}.py" in names, n
        flags = int.from_bytes(z.read(n)[4:8], "little")
        assert flags == 0b11, f"{n}: not a checked hash-based pyc (flags {flags})"


@pytest.mark.integration
def test_many_instances_in_one_process(probe_fmu: Path, probe_dir: Path) -> None:
    """pythonfmu 0.7.0 drops a reference to the script module's dict per instantiation; FmuBase
    compensates. (It also leaks the re-executed class, whose methods keep the dict referenced, so
    this probe would survive without the fix; the plant scripts, whose classes define no method,
    would not: tests/fmus/test_plant_fmu.py::test_many_instances.)"""
    for k in range(12):
        f = start(probe_fmu, probe_dir, y0=float(k))
        f.set(u=1.0)
        f.slave.exitInitializationMode()
        assert f.get("y") == [float(k)]
        f.slave.doStep(0.0, 0.25)
        assert f.get("y", "u_copy") == [k + 0.25, 1.0]
        f.slave.terminate()
        f.slave.freeInstance()


@pytest.mark.integration
def test_step_failure_is_discard_with_message(probe_fmu: Path, probe_dir: Path) -> None:
    f = start(probe_fmu, probe_dir)
    f.slave.exitInitializationMode()
    f.set(u=float("inf"))
    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, 0.1)
    assert info.value.status == FMI_DISCARD
    assert (FMI_ERROR, "logStatusError", "y became inf in the step from t = 0.0 s (u = inf)") in f.messages
    assert f.get("y") == [0.0]  # state kept at t
    f.set(u=1.0)
    f.slave.doStep(0.0, 0.1)  # the instance is still usable
    assert f.get("y") == [pytest.approx(0.1)]
    f.slave.freeInstance()


@pytest.mark.integration
@pytest.mark.parametrize("params, expected", [
    ({"gain": -2.0}, "parameter gain = -2.0: must be > 0"),
    ({"y0": float("nan")}, "parameter y0 = nan V.s: not a finite number"),
    ({"fail_mode": 1}, "RuntimeError: setup exploded at fmu_plumbing_probe.py:"),
])
def test_bad_parameter_is_an_fmi_error_with_message(probe_fmu: Path, probe_dir: Path, params, expected) -> None:
    f = start(probe_fmu, probe_dir, **params)
    with pytest.raises(FMICallException) as info:
        f.slave.exitInitializationMode()
    assert info.value.status == FMI_FATAL  # pythonfmu maps any Python exception to fmi2Fatal
    fatal = [m[2] for m in f.messages if m[0] == FMI_FATAL]
    assert len(fatal) == 1 and fatal[0].splitlines()[-1].startswith(expected), f.messages
    f.slave.freeInstance()


@pytest.mark.integration
def test_exception_in_step_is_fatal_with_message(probe_fmu: Path, probe_dir: Path) -> None:
    f = start(probe_fmu, probe_dir, fail_mode=2)
    f.slave.exitInitializationMode()
    with pytest.raises(FMICallException) as info:
        f.slave.doStep(0.0, 0.1)
    assert info.value.status == FMI_FATAL
    assert any(m[0] == FMI_FATAL and m[2].splitlines()[-1].startswith(
        "IndexError: list index out of range at fmu_plumbing_probe.py") for m in f.messages), f.messages
    f.slave.freeInstance()


@pytest.mark.integration
def test_fatal_instances_leave_the_process_sound(probe_fmu: Path, probe_dir: Path) -> None:
    """pythonfmu 0.7.0 releases the instance, its log queue and its class twice after an exception;
    FmuBase keeps them alive. Without that, freeing fatal instances crashes a later GC."""
    import gc
    for _ in range(6):
        f = start(probe_fmu, probe_dir, gain=-1.0)
        with pytest.raises(FMICallException):
            f.slave.exitInitializationMode()
        f.slave.freeInstance()
        gc.collect()
    f = start(probe_fmu, probe_dir)
    f.slave.exitInitializationMode()
    f.slave.doStep(0.0, 0.1)
    assert f.slave.getInteger([f.vr["steps"]]) == [1]
    f.slave.freeInstance()
    gc.collect()


@pytest.mark.integration
def test_tunable_and_fixed_parameters(probe_fmu: Path, probe_dir: Path) -> None:
    f = start(probe_fmu, probe_dir)
    f.slave.exitInitializationMode()
    f.set(offset=1.0)  # tunable: takes effect from the next step
    f.slave.doStep(0.0, 0.5)
    assert f.get("y") == [0.5]
    with pytest.raises(FMICallException):
        f.set(gain=2.0)  # fixed after initialization
    assert any(m[0] == FMI_FATAL and m[2].endswith("parameter gain is fixed: it cannot be set to 2.0 after "
                                                   "initialization") for m in f.messages), f.messages
    f.slave.freeInstance()


@pytest.mark.integration
def test_messages_need_logging_on(probe_fmu: Path, probe_dir: Path) -> None:
    """pythonfmu forwards log messages only to an instance created with loggingOn = true."""
    f = instantiate(probe_fmu, probe_dir, logging_on=False)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    f.set(gain=-1.0)
    with pytest.raises(FMICallException):
        f.slave.exitInitializationMode()
    assert f.messages == []
    f.slave.freeInstance()


@pytest.mark.integration
@pytest.mark.slow
def test_probe_passes_vdmcheck(probe_fmu: Path) -> None:
    assert_vdmcheck_clean(probe_fmu)


@pytest.mark.integration
def test_incremental_build(tmp_path: Path) -> None:
    script = tmp_path / "fmu_plumbing_probe.py"
    shutil.copy(PROBE, script)
    out = tmp_path / "fmus"
    first = build_all(out, scripts=[script])
    again = build_all(out, scripts=[script])
    assert [r.built for r in first] == [True] and [r.built for r in again] == [False]
    mtime = first[0].fmu.stat().st_mtime_ns
    script.write_text(script.read_text() + "\n# changed\n")
    third = build_all(out, scripts=[script])
    assert [r.built for r in third] == [True]
    assert third[0].fmu.stat().st_mtime_ns >= mtime
    assert [r.built for r in build_all(out, scripts=[script], force=True)] == [True]


def test_check_fmu_rejects_undefined_units(tmp_path: Path) -> None:
    md = ('<fmiModelDescription fmiVersion="2.0" modelName="X" guid="g"><ModelVariables>'
          '<ScalarVariable name="a" valueReference="0" causality="parameter" variability="fixed">'
          '<Real start="1" unit="m"/></ScalarVariable></ModelVariables></fmiModelDescription>')
    fmu = tmp_path / "X.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", md)
    with pytest.raises(BuildError, match="unit 'm' without a definition"):
        check_fmu(fmu)
    ElementTree.fromstring(md)  # the document itself is well-formed


def test_discover_finds_the_fmu_scripts() -> None:
    from ipcosim.fmus.pybuild import discover
    scripts = discover(ROOT)
    names = {s.name for s in scripts}
    assert {"fmu_ip02_single_mass.py", "fmu_ip02_double_mass.py"} <= names
    assert all(s.name.startswith("fmu_") and s.parent.name in ("fmus", "controllers") for s in scripts)
    assert len(names) == len(scripts)  # module names are unique
