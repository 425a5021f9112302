"""Every FMI 3.0 FMU the project makes, run the way a strict FMI 3.0 importer runs it.

``tests/c/strict_host.c`` (compiled for Linux and, with mingw-w64, for Windows under wine, as in
``tests/native/test_win64.py``) instantiates each FMU with ``eventModeUsed`` and ``earlyReturnAllowed``
set (the first must be refused: the FMUs have no Event Mode, FMI 3.0 section 2.3.1), reads every
variable of its model description, grouped by type, in Instantiated, Initialization Mode, after
initialization, after every step and in Terminated, and checks that the independent variable
``time`` is the communication point: the start time, then ``t + h`` after ``fmi3DoStep(t, h)``.
The FMUs: the 16 native FMI 3.0 FMUs and an exported loop of each plant, all run by one host
process per platform (wine starts once), a few steps each. The FMI 2.0 native FMUs answer
``fmi2GetReal`` (and the other getters) for every variable of theirs, read through FMPy.
"""
from __future__ import annotations

import os
import subprocess
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import pytest
from loop_plans import MINGW, WINE, _binary
from loop_plans import host_path as _path

from ipcosim.harness.native.cbuild import model_names
from ipcosim.toolchain import find_compiler

ROOT = Path(__file__).resolve().parents[2]
CC = find_compiler()
pytestmark = [pytest.mark.integration, pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)")]
#: The exported loops: one per plant.
LOOPS = ("single-mass-lqr", "double-mass-lqr")
START, STEPS = 0.5, 4
FMI3_TYPES = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
              "Boolean", "String")


@pytest.fixture(scope="session")
def strict_hosts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """The strict host for each platform it can run on, as the command prefix that runs it."""
    from ipcosim.harness.native.cbuild import fmi_header_dir

    out = tmp_path_factory.mktemp("strict-host")
    src = ROOT / "tests" / "c" / "strict_host.c"
    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-I", str(fmi_header_dir())]
    subprocess.run([CC, *flags, str(src), "-o", str(out / "strict_host"), "-ldl"], check=True)
    hosts = {"linux64": [str(out / "strict_host")]}
    if MINGW is not None and WINE is not None:
        subprocess.run([MINGW, *flags, str(src), "-o", str(out / "strict_host.exe")], check=True)
        env = {**os.environ, "WINEPREFIX": os.environ.get("WINEPREFIX", str(out / "wineprefix")), "WINEDEBUG": "-all"}
        started = subprocess.run([WINE, str(out / "strict_host.exe")], env=env, capture_output=True, text=True,
                                 timeout=300)
        if "usage: strict_host" in started.stderr:
            os.environ.update(WINEPREFIX=env["WINEPREFIX"], WINEDEBUG="-all")
            hosts["win64"] = [WINE, str(out / "strict_host.exe")]
    return hosts


@pytest.fixture(scope="session")
def exported_loops3(native_fmus: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``ipcosim export SCENARIO --fmi 3`` of one loop per plant."""
    from ipcosim.harness.api.export import ExportOptions, export

    out = tmp_path_factory.mktemp("loops3")
    return {s: export(ExportOptions(s, out / f"{s}.fmu", fmu_dirs=(native_fmus[1],), fmi="3")) for s in LOOPS}


def variables(fmu: Path) -> tuple[list[tuple[str, int]], int | None, float]:
    """Every variable of the FMU's model description as (FMI 3.0 type, value reference), the value
    reference of its independent variable, and its default step (1 ms if it gives none)."""
    root = ElementTree.fromstring(zipfile.ZipFile(fmu).read("modelDescription.xml"))
    assert root.get("fmiVersion") == "3.0", fmu
    out, time_vr = [], None
    for v in root.find("ModelVariables"):
        assert v.tag in FMI3_TYPES, f"{fmu.name}: variable {v.get('name')} of type {v.tag}"
        out.append((v.tag, int(v.get("valueReference"))))
        if v.get("causality") == "independent":
            assert time_vr is None, f"{fmu.name}: two independent variables"
            time_vr = int(v.get("valueReference"))
    experiment = root.find("DefaultExperiment")
    step = float(experiment.get("stepSize")) if experiment is not None and experiment.get("stepSize") else 1e-3
    return out, time_vr, step


@pytest.fixture(scope="session")
def strict_runs(strict_hosts, native_fmus3: Path, exported_loops3, tmp_path_factory: pytest.TempPathFactory):
    """``runs(platform)``: the strict host's output for every FMI 3.0 FMU (name -> its lines, from
    "fmu ..." to "ok" or "error: ..."), all run by one host process per platform (wine starts once)."""
    fmus = {**{f.stem: f for f in sorted(native_fmus3.glob("*.fmu"))}, **exported_loops3}
    dest = tmp_path_factory.mktemp("strict-runs")
    cache: dict[str, dict[str, list[str]]] = {}

    def runs(platform: str) -> dict[str, list[str]]:
        if platform not in strict_hosts:
            pytest.skip("no mingw-w64 cross compiler or wine here")
        if platform not in cache:
            cache[platform] = _run_all(strict_hosts[platform], platform, fmus, dest / platform)
        return cache[platform]

    return runs


def _run_all(host: list[str], platform: str, fmus: dict[str, Path], dest: Path) -> dict[str, list[str]]:
    lines, names = [], {}
    for name, fmu in fmus.items():
        lib, token, _ = _binary(fmu, dest / name, platform)
        found, time_vr, step = variables(fmu)
        names[_path(lib, platform)] = name
        lines += [f"fmu {_path(lib, platform)} {token}", *(f"var {t} {vr}" for t, vr in found)]
        lines += [f"time {time_vr}"] if time_vr is not None else []
        lines.append(f"run {START!r} {step!r} {STEPS}")
    plan = dest / "all.plan"
    plan.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([*host, _path(plan, platform)], capture_output=True, text=True, timeout=600)
    assert proc.returncode in (0, 1), f"{platform} host: {proc.stderr.strip()[-600:]}"
    out: dict[str, list[str]] = {}
    for line in proc.stdout.splitlines():
        if line.startswith("fmu "):
            current = out.setdefault(names[line[4:]], [])
        current.append(line)
    return out


def check_run(lines: list[str], fmu: Path) -> list[list[str]]:
    """The rounds of reads of one FMU's run (asserts it ended with "ok": every check passed)."""
    assert lines and lines[-1] == "ok", f"{fmu.name}: " + (lines[-1] if lines else "not run")
    found, _, _ = variables(fmu)
    states = ["instantiated", "initialization", "initialized", *(f"step{k}" for k in range(1, STEPS + 1)),
              "terminated"]
    rows = [line.split() for line in lines[1:-1]]
    assert [r[0] for r in rows] == states, lines
    assert all(int(r[2]) == len(found) for r in rows), lines  # every variable, in every state
    return rows


def _expected_times(step: float) -> list[float]:
    """``time`` the standard asks for after each round of reads from Initialization Mode on:
    the start time twice, then after the step from t, t + h (the host's own sums), then the last."""
    times, t = [START, START], START
    for _ in range(STEPS):
        t = t + step
        times.append(t)
    return times + [t]


@pytest.mark.parametrize("platform", ("linux64", pytest.param("win64", marks=pytest.mark.cross)))
@pytest.mark.parametrize("model", sorted(model_names()))
def test_native_fmi3_fmu_in_a_strict_host(model: str, platform: str, strict_runs, native_fmus3: Path) -> None:
    fmu = native_fmus3 / f"{model}.fmu"
    rows = check_run(strict_runs(platform)[model], fmu)
    _, time_vr, step = variables(fmu)
    assert time_vr is not None, f"{model}: FMI 3.0 asks for an independent variable"
    assert [float(r[1]) for r in rows[1:]] == _expected_times(step)


@pytest.mark.parametrize("platform", ("linux64", pytest.param("win64", marks=pytest.mark.cross)))
@pytest.mark.parametrize("scenario", LOOPS)
def test_exported_fmi3_loop_in_a_strict_host(scenario: str, platform: str, strict_runs, exported_loops3) -> None:
    fmu = exported_loops3[scenario]
    rows = check_run(strict_runs(platform)[scenario], fmu)
    _, time_vr, step = variables(fmu)
    assert time_vr is not None
    assert [float(r[1]) for r in rows[1:]] == _expected_times(step)


def test_native_fmi2_fmus_answer_every_getter(native_fmus: tuple[Path, Path], tmp_path: Path) -> None:
    """FMI 2.0 has no independent variable to declare; every variable the FMI 2.0 native FMUs do
    declare answers its getter after initialization and after a step."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    fmus = sorted(native_fmus[1].glob("*.fmu"))
    assert len(fmus) == 16
    for fmu in fmus:
        md = read_model_description(str(fmu))
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / fmu.stem)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="all")
        by_type: dict[str, list[int]] = {}
        for v in md.modelVariables:
            by_type.setdefault(v.type, []).append(v.valueReference)
        assert set(by_type) <= {"Real", "Integer", "Boolean"}, (fmu.name, set(by_type))
        slave.instantiate()
        slave.setupExperiment(startTime=START)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(2):
            for t, vrs in by_type.items():
                values = getattr(slave, f"get{t}")(vrs)  # raises on a status above fmi2Warning
                assert len(values) == len(vrs)
            slave.doStep(currentCommunicationPoint=START + k * 1e-3, communicationStepSize=1e-3)
        slave.terminate()
        slave.freeInstance()
