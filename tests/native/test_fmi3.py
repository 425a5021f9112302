"""The FMI 3.0 variant of the native FMUs and of an exported loop, against the FMI 2.0 one.

Same generator, same model definitions: the FMI 3.0 FMUs must carry the same variables (names,
value references, units, start values, causalities, variabilities), validate in fmpy, run in
fmpy's ``simulate_fmu`` and in the ipcosim master, and give the FMI 2.0 variant's results to
1e-12 (the differences seen are printed).
"""
from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ipcosim.toolchain import find_compiler, find_cross_compiler

CC = find_compiler()
pytestmark = [pytest.mark.integration, pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)")]
TOLERANCE = 1e-12
SCENARIOS = ("single-mass-lqr", "double-mass-lqr")


def _max_diff(a: np.ndarray, b: np.ndarray, names: list[str]) -> float:
    assert len(a) == len(b) > 1
    return max(float(np.max(np.abs(np.asarray(a[n], float) - np.asarray(b[n], float)))) for n in names)


def test_fmi3_fmus_validate_and_describe_their_sources(native_fmus3: Path) -> None:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    from ipcosim.harness.native.cbuild import model_names

    fmus = sorted(native_fmus3.glob("*.fmu"))
    assert [f.stem for f in fmus] == sorted(model_names())
    for fmu in fmus:
        assert validate_fmu(str(fmu)) == [], fmu.name
        md = read_model_description(str(fmu))
        assert md.fmiVersion == "3.0" and md.coSimulation.modelIdentifier == fmu.stem
        listed = [f for c in md.buildConfigurations for fs in c.sourceFileSets for f in fs.sourceFiles]
        assert listed == ["model.c", "fmi3glue.c"], fmu.name
        with zipfile.ZipFile(fmu) as z:
            names = set(z.namelist())
        assert {f"sources/{f}" for f in listed} <= names and f"binaries/x86_64-linux/{fmu.stem}.so" in names
        assert (f"binaries/x86_64-windows/{fmu.stem}.dll" in names) == (find_cross_compiler() is not None)
        assert (f"binaries/aarch64-linux/{fmu.stem}.so" in names) == (find_cross_compiler("aarch64") is not None)


def test_fmi3_variables_are_the_fmi2_ones(native_fmus: tuple[Path, Path], native_fmus3: Path) -> None:
    from fmpy import read_model_description

    types = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
    for fmu in sorted(native_fmus3.glob("*.fmu")):
        two = read_model_description(str(native_fmus[1] / fmu.name))
        three = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
        assert three.pop("time").causality == "independent"
        assert set(three) == {v.name for v in two.modelVariables}, fmu.name
        for v in two.modelVariables:
            w = three[v.name]
            assert (w.valueReference, w.causality, w.variability, w.initial, w.unit, w.type) == (
                v.valueReference, v.causality, v.variability, v.initial, v.unit, types[v.type]), (fmu.name, v.name)
            assert (w.start is None) == (v.start is None) and (v.start is None or float(w.start) == float(v.start))
        outputs2 = [(o.variable.name, sorted(d.name for d in o.dependencies or [])) for o in two.outputs]
        outputs3 = [(o.variable.name, sorted(d.name for d in o.dependencies or [])) for o in
                    read_model_description(str(fmu)).outputs]
        assert outputs2 == outputs3, fmu.name


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_master_runs_fmi3_like_fmi2(scenario: str, native_fmus: tuple[Path, Path], native_fmus3: Path) -> None:
    import ipcosim
    from ipcosim.harness.api.engine import Prepared

    with Prepared(scenario, fmus="native", fmu_dirs=[native_fmus3], warn=False) as prepared:
        assert {i.model.fmi_version for i in prepared.system.instances} == {"3.0"}
    two = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]]).data
    three = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus3]).data
    worst = _max_diff(two, three, list(two.dtype.names))
    print(f"{scenario}: ipcosim master, FMI 2.0 vs FMI 3.0 native FMUs, 10 s: max |diff| {worst:.3g}")
    assert worst <= TOLERANCE
    assert np.abs(three["plant.pendulum_angle"]).max() > 1e-6  # the loop moved


def test_fmi3_plant_in_fmpy_like_fmi2(native_fmus: tuple[Path, Path], native_fmus3: Path) -> None:
    import fmpy

    t = np.arange(0.0, 2.0005, 0.001)
    signal = np.array(list(zip(t, 2.0 * np.sin(3.0 * t))), dtype=[("time", float), ("voltage", float)])
    runs = [fmpy.simulate_fmu(str(d / "IP02DoubleMass.fmu"), stop_time=2.0, step_size=0.001, output_interval=0.001,
                              input=signal) for d in (native_fmus[1], native_fmus3)]
    worst = _max_diff(*runs, [n for n in runs[0].dtype.names if n != "time"])
    print(f"IP02DoubleMass under a 2 V sine in fmpy, FMI 2.0 vs 3.0: max |diff| {worst:.3g}")
    assert worst <= TOLERANCE and np.abs(runs[1]["passive_cart_position"]).max() > 1e-4


def test_exported_loop_fmi3_like_fmi2(native_fmus: tuple[Path, Path], tmp_path: Path) -> None:
    import fmpy
    from fmpy.validation import validate_fmu

    from ipcosim.harness.api.export import ExportOptions, export

    fmus = {"2": export(ExportOptions("single-mass-lqr", tmp_path / "loop2.fmu", fmu_dirs=(native_fmus[1],))),
            "3": tmp_path / "loop3.fmu"}
    proc = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "export", "single-mass-lqr", "--fmi", "3",
                           "--fmu-dir", str(native_fmus[1]), "--out", str(fmus["3"])], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert validate_fmu(str(fmus["3"])) == []
    runs = [fmpy.simulate_fmu(str(fmus[f]), stop_time=10.0, step_size=0.01, output_interval=0.01) for f in "23"]
    worst = _max_diff(*runs, [n for n in runs[0].dtype.names if n != "time"])
    print(f"single-mass-lqr exported, fmpy at 10 ms, FMI 2.0 vs 3.0: max |diff| {worst:.3g}")
    assert worst <= TOLERANCE and np.abs(runs[1]["plant.cart_position"]).max() > 1e-2


def test_build_fmi3_needs_native() -> None:
    proc = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "build", "--fmi", "3"], capture_output=True,
                          text=True)
    assert proc.returncode != 0
    assert proc.stderr.strip().splitlines()[-1].endswith("only the native FMUs have an FMI 3.0 variant (add --native)")


def test_missing_cross_compiler_is_one_line(native_fmus: tuple[Path, Path], tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    from ipcosim.harness.native.cbuild import build_native

    monkeypatch.setenv("MINGW_CC", "no-such-cross-compiler")
    monkeypatch.setenv("AARCH64_CC", "no-such-cross-compiler")
    (result,) = build_native(native_fmus[0], tmp_path, names=["Setpoint"], fmi="3")
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == ["ipcosim build --native: no mingw-w64 cross compiler found (set MINGW_CC, or install Debian's "
                     "gcc-mingw-w64-x86-64): no win64 binary, Linux only",
                     "ipcosim build --native: no aarch64 cross compiler found (set AARCH64_CC, or install Debian's "
                     "gcc-aarch64-linux-gnu): no aarch64 binary, x86-64 only"]
    assert result.platforms == ("linux64",)
    with zipfile.ZipFile(result.fmu) as z:
        assert [n for n in z.namelist() if n.startswith("binaries/")] == ["binaries/x86_64-linux/Setpoint.so"]
