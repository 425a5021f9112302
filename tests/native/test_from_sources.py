"""Every native FMU (FMI 2.0 and 3.0) and an exported loop, compiled as an importing tool compiles
it: from nothing but the FMU's ``sources/`` folder and the file list the FMU itself gives (the
model description's ``<SourceFiles>`` for FMI 2.0, ``sources/buildDescription.xml`` for FMI 3.0),
with gcc and with clang under ``-std=c99 -Wall -Wextra -pedantic -Werror``, and through fmpy's
CMake build (``fmpy.build.build_platform_binary``, the successor of ``compile_platform_binary``).
Each binary so built replaces the shipped one in a copy of its FMU; every scenario the native
flavour runs then gives the shipped FMUs' results (and the exported loop its own).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from ipcosim.toolchain import find_compiler

CC = find_compiler()
pytestmark = [pytest.mark.integration, pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)")]
COMPILERS = ("gcc", "clang")
FLAGS = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-fPIC", "-shared")
LINUX = {"2.0": "linux64", "3.0": "x86_64-linux"}
STOP = 0.3  # s of every scenario (the shipped and the rebuilt FMUs)
TOLERANCE = 1e-12
#: Built through fmpy's CMake project too (a CMake configure costs seconds: one loop's FMUs).
CMAKE_MODELS = ("Setpoint", "LQRSingleMass", "IP02SingleMass")


def listed_sources(fmu: Path) -> tuple[str, str, list[str]]:
    """(FMI version, model identifier, C files) as the FMU's own description files give them."""
    with zipfile.ZipFile(fmu) as z:
        md = ElementTree.fromstring(z.read("modelDescription.xml"))
        identifier = md.find("CoSimulation").get("modelIdentifier")
        if md.get("fmiVersion") == "2.0":
            return "2.0", identifier, [f.get("name") for f in md.iterfind("CoSimulation/SourceFiles/File")]
        bd = ElementTree.fromstring(z.read("sources/buildDescription.xml"))
    config = next(c for c in bd.iterfind("BuildConfiguration") if c.get("modelIdentifier") == identifier)
    return md.get("fmiVersion"), identifier, [f.get("name") for f in config.iterfind("SourceFileSet/SourceFile")]


def sources_only(fmu: Path, dest: Path) -> Path:
    """Extract only ``sources/`` of ``fmu`` into ``dest``; returns ``dest``."""
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/") and not name.endswith("/"):
                (dest / name).parent.mkdir(parents=True, exist_ok=True)
                (dest / name).write_bytes(z.read(name))
    return dest


def with_binary(fmu: Path, binary: Path, dest: Path) -> Path:
    """A copy of ``fmu`` in folder ``dest`` whose Linux binary is ``binary``."""
    version, identifier, _ = listed_sources(fmu)
    member = f"binaries/{LINUX[version]}/{identifier}.so"
    dest.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest / fmu.name, "w", zipfile.ZIP_DEFLATED) as out:
        assert member in src.namelist(), member
        for item in src.infolist():
            out.writestr(item, binary.read_bytes() if item.filename == member else src.read(item.filename))
    return dest / fmu.name


def compile_from_sources(fmu: Path, compiler: str, work: Path) -> Path:
    """The FMU's listed files compiled from its sources alone; returns the library."""
    version, identifier, files = listed_sources(fmu)
    assert files, f"{fmu.name}: no source files listed"
    root = sources_only(fmu, work / f"{fmu.stem}-{version}-{compiler}")
    lib = root / f"{identifier}.so"
    proc = subprocess.run([compiler, *FLAGS, "-I", "sources", *(f"sources/{f}" for f in files), "-o", lib.name,
                           "-lm"], cwd=root, capture_output=True, text=True)
    assert proc.returncode == 0 and not proc.stderr.strip(), f"{fmu.name} (FMI {version}, {compiler}): {proc.stderr}"
    return lib


def cmake_build(fmu: Path, work: Path) -> Path:
    """The FMU's sources built by fmpy's CMake project (all warnings on); returns the library."""
    from fmpy.build import build_platform_binary

    version, identifier, _ = listed_sources(fmu)
    root = sources_only(fmu, work / f"{fmu.stem}-{version}-cmake")
    with zipfile.ZipFile(fmu) as z:  # fmpy reads the file list (and, for FMI 2.0, the identifier) from it
        (root / "modelDescription.xml").write_bytes(z.read("modelDescription.xml"))
    try:
        build_platform_binary(root.resolve(), all_warnings=True)
    except subprocess.CalledProcessError as exc:
        raise AssertionError(f"{fmu.name}: fmpy's CMake build failed ({exc})") from None
    return root / "binaries" / LINUX[version] / f"{identifier}.so"


def native_scenarios(native_dir: Path) -> dict[str, np.ndarray]:
    """Every scenario the native flavour runs, STOP seconds on the FMUs in ``native_dir``."""
    import ipcosim
    from ipcosim.harness.scenario.flavour import FlavourError
    from ipcosim.harness.scenario.locations import scenario_names

    runs = {}
    for name in scenario_names():
        try:
            runs[name] = ipcosim.run(name, fmus="native", stop_time=STOP, fmu_dirs=[native_dir]).data
        except FlavourError:
            continue  # a scenario with instruments: Python flavour only (tests/native/test_native.py)
    return runs


@pytest.fixture(scope="module")
def exported(native_fmus: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from ipcosim.harness.api.export import ExportOptions, export

    out = tmp_path_factory.mktemp("exported")
    return {fmi: export(ExportOptions("single-mass-lqr", out / f"SingleMassLqrLoop{fmi}.fmu",
                                      fmu_dirs=(native_fmus[1],), fmi=fmi)) for fmi in ("2", "3")}


@pytest.fixture(scope="module")
def shipped(native_fmus: tuple[Path, Path]) -> dict[str, np.ndarray]:
    return native_scenarios(native_fmus[1])


@pytest.mark.parametrize("compiler", COMPILERS)
def test_every_native_fmu_builds_from_its_sources(compiler: str, native_fmus: tuple[Path, Path], native_fmus3: Path,
                                                  exported: dict[str, Path], shipped: dict[str, np.ndarray],
                                                  tmp_path: Path) -> None:
    import fmpy

    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed")
    fmus = {"2": sorted(native_fmus[1].glob("*.fmu")), "3": sorted(native_fmus3.glob("*.fmu"))}
    assert [f.name for f in fmus["2"]] == [f.name for f in fmus["3"]] and len(fmus["2"]) >= 14
    jobs = [(fmi, fmu) for fmi in fmus for fmu in (*fmus[fmi], exported[fmi])]
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        libs = list(pool.map(lambda job: compile_from_sources(job[1], compiler, tmp_path / "work"), jobs))
    rebuilt = {(fmi, fmu.name): with_binary(fmu, lib, tmp_path / f"fmi{fmi}") for (fmi, fmu), lib in zip(jobs, libs)}
    assert len(shipped) >= 11, sorted(shipped)
    for fmi in fmus:
        runs = native_scenarios(tmp_path / f"fmi{fmi}")
        assert sorted(runs) == sorted(shipped)
        worst = max(float(np.max(np.abs(runs[sc][n] - shipped[sc][n]))) for sc in runs for n in runs[sc].dtype.names)
        print(f"{compiler}, FMI {fmi}.0, built from sources: {len(runs)} scenarios, {STOP} s each, max |diff| to "
              f"the shipped FMI 2.0 FMUs {worst:.3g}")
        assert worst <= TOLERANCE
        loop = exported[fmi].name
        mine, theirs = (fmpy.simulate_fmu(str(f), stop_time=2.0, step_size=0.01, output_interval=0.01)
                        for f in (rebuilt[(fmi, loop)], exported[fmi]))
        assert max(float(np.max(np.abs(mine[n] - theirs[n]))) for n in mine.dtype.names) <= TOLERANCE, loop


def test_fmpy_cmake_build_of_the_sources(native_fmus: tuple[Path, Path], native_fmus3: Path,
                                         shipped: dict[str, np.ndarray], tmp_path: Path) -> None:
    import ipcosim

    if shutil.which("cmake") is None:
        pytest.skip("cmake is not installed (fmpy's build_platform_binary needs it)")
    jobs = [(fmi, folder / f"{m}.fmu") for fmi, folder in (("2", native_fmus[1]), ("3", native_fmus3))
            for m in CMAKE_MODELS]
    with ThreadPoolExecutor(max_workers=2) as pool:
        libs = list(pool.map(lambda job: cmake_build(job[1], tmp_path / "work"), jobs))
    for (fmi, fmu), lib in zip(jobs, libs):
        with_binary(fmu, lib, tmp_path / f"fmi{fmi}")
    for fmi in ("2", "3"):
        run = ipcosim.run("single-mass-lqr", fmus="native", stop_time=STOP, fmu_dirs=[tmp_path / f"fmi{fmi}"]).data
        ref = shipped["single-mass-lqr"]
        worst = max(float(np.max(np.abs(run[n] - ref[n]))) for n in ref.dtype.names)
        print(f"fmpy CMake build, FMI {fmi}.0, single-mass-lqr: max |diff| to the shipped FMUs {worst:.3g}")
        assert worst <= TOLERANCE
