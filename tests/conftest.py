"""Shared fixtures: the project's FMUs, built once per test run into one temporary folder (never into
build/) that every test needing one of them reads, and never writes."""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Fixtures whose build compiles every native FMU (tens of seconds): a test that uses one is marked ``slow``.
SLOW_FIXTURES = frozenset({"native_fmus", "native_fmus3"})


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark ``slow`` every test that needs a fixture of SLOW_FIXTURES, directly or through another fixture
    (before ``-m`` selects)."""
    for item in items:
        if SLOW_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


def _run_folder(factory: pytest.TempPathFactory) -> Path:
    """The temporary folder of this test run that all its pytest-xdist workers share (each worker's own
    base folder is one level below it; without workers, the run's base folder itself)."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@contextmanager
def _locked(lock: Path) -> Iterator[None]:
    """Hold an exclusive lock on the file ``lock`` (POSIX; where there is no fcntl, as on Windows, the run
    is serial and needs none)."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(lock, "w") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def shared_build(factory: pytest.TempPathFactory, name: str, build: Callable[[Path], object]) -> Path:
    """The folder ``name`` of this test run, made by ``build(folder)`` once: the first worker to ask builds it
    under a file lock, the others wait for the lock and find it done."""
    folder = _run_folder(factory) / name
    with _locked(folder.with_name(f"{name}.lock")):
        done = folder.with_name(f"{name}.done")
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)  # what a build cut short left
            build(folder)
            done.touch()
    return folder


def _build_project_fmus(folder: Path) -> None:
    """Every FMU of ``ipcosim build`` into ``folder``. Those of build/fmus whose sources are unchanged (the
    build cache's digest: the script, every module it carries, the builder, pythonfmu) are copied from it,
    as ``make test`` has just built them; the others are built."""
    from ipcosim.fmus.pybuild import STAMP_FILE, build_all

    folder.mkdir(parents=True)
    built = ROOT / "build" / "fmus"
    if (built / STAMP_FILE).is_file():
        for f in (*built.glob("*.fmu"), built / STAMP_FILE):
            shutil.copy2(f, folder)
    build_all(folder)


@pytest.fixture(scope="session")
def project_fmu_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder of every FMU of the project (``ipcosim build``'s), built once per test run and shared by
    every test (and every pytest-xdist worker) that needs one of them; read only."""
    return shared_build(tmp_path_factory, "project-fmus", _build_project_fmus)


@pytest.fixture(scope="session")
def project_fmus(project_fmu_dir: Path) -> dict[str, Path]:
    """``{script path below the root (``fmus/fmu_ip02_single_mass.py``): its FMU in project_fmu_dir}``."""
    from ipcosim.fmus.pybuild import read_stamps

    return {key: project_fmu_dir / entry["fmu"] for key, entry in read_stamps(project_fmu_dir).items()
            if (ROOT / key).is_file()}


@pytest.fixture(scope="session")
def plant_fmus(project_fmus: dict[str, Path]) -> dict[str, Path]:
    """``{"single-mass": IP02SingleMass.fmu, "double-mass": IP02DoubleMass.fmu}`` of this run's build."""
    return {"single-mass": project_fmus["fmus/fmu_ip02_single_mass.py"],
            "double-mass": project_fmus["fmus/fmu_ip02_double_mass.py"]}


@pytest.fixture(scope="session")
def native_fmus(tmp_path_factory: pytest.TempPathFactory, project_fmu_dir: Path) -> tuple[Path, Path]:
    """(Python FMU folder, native FMU folder), built once per test run (tests/native/test_native.py,
    tests/api/test_export.py)."""
    from ipcosim.harness.native.cbuild import build_native

    return project_fmu_dir, shared_build(tmp_path_factory, "fmus-native",
                                         lambda out: build_native(project_fmu_dir, out))


@pytest.fixture(scope="session")
def native_fmus3(tmp_path_factory: pytest.TempPathFactory, native_fmus: tuple[Path, Path]) -> Path:
    """The FMI 3.0 variant of the native FMUs (``build_native(..., fmi="3")``), built once per test run
    next to ``native_fmus``' FMI 2.0 ones (tests/native/test_fmi3.py, test_from_sources.py)."""
    from ipcosim.harness.native.cbuild import build_native

    return shared_build(tmp_path_factory, "fmus-native-fmi3", lambda out: build_native(native_fmus[0], out, fmi="3"))


@pytest.fixture
def tracked(monkeypatch: pytest.MonkeyPatch) -> tuple[list, list]:
    """Every FMI 2.0 FMU slave instantiated and every FMU slave freed during the test: ``(made, freed)``."""
    from ipcosim.harness.master.slave import FMU2Slave, FMUSlave

    made, freed = [], []
    real_inst, real_free = FMU2Slave.instantiate, FMUSlave.free

    def inst(self):
        made.append(self)
        real_inst(self)

    def free(self):
        was = self.state
        real_free(self)
        if was not in ("freed", "created"):
            freed.append(self)

    monkeypatch.setattr(FMU2Slave, "instantiate", inst)
    monkeypatch.setattr(FMUSlave, "free", free)
    return made, freed
