"""Shared fixtures: FMUs built into a per-session temporary folder (never into build/)."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def plant_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``{"single-mass": IP02SingleMass.fmu, "double-mass": IP02DoubleMass.fmu}`` built for this session."""
    from ipcosim.fmus.pybuild import build_all

    out = tmp_path_factory.mktemp("plant-fmus")
    scripts = [ROOT / "fmus" / "fmu_ip02_single_mass.py", ROOT / "fmus" / "fmu_ip02_double_mass.py"]
    results = build_all(out, scripts=scripts)
    fmus = {r.fmu.stem: r.fmu for r in results}
    return {"single-mass": fmus["IP02SingleMass"], "double-mass": fmus["IP02DoubleMass"]}


@pytest.fixture(scope="session")
def native_fmus(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(Python FMU folder, native FMU folder), built for this session (tests/native/test_native.py,
    tests/api/test_export.py)."""
    from ipcosim.fmus.pybuild import build_all
    from ipcosim.harness.native.cbuild import build_native

    out = tmp_path_factory.mktemp("native")
    build_all(out / "fmus")
    build_native(out / "fmus", out / "fmus-native")
    return out / "fmus", out / "fmus-native"


@pytest.fixture(scope="session")
def native_fmus3(native_fmus: tuple[Path, Path]) -> Path:
    """The FMI 3.0 variant of the native FMUs (``build_native(..., fmi="3")``), built for this session
    next to ``native_fmus``' FMI 2.0 ones (tests/native/test_fmi3.py, test_from_sources.py)."""
    from ipcosim.harness.native.cbuild import build_native

    out = native_fmus[1].parent / "fmus-native-fmi3"
    build_native(native_fmus[0], out, fmi="3")
    return out


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
