"""The first run after a wheel install: the FMUs a scenario needs are built once, into the build folder."""
from __future__ import annotations

from pathlib import Path

import pytest

import ipcosim
from ipcosim.harness.scenario import locations
from ipcosim.harness.scenario.files import SSD_NAME
from ipcosim.harness.scenario.ssp import load_scenario
from ipcosim.harness.support.paths import BUILD_FMU_DIR, SCENARIO_DIR


@pytest.mark.integration
def test_first_run_builds_the_missing_fmus_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    cache = tmp_path / "cache" / "fmus"
    monkeypatch.setattr(locations, "BUILD_FMU_DIR", cache)   # an empty user cache, as after `pip install`
    monkeypatch.delenv("IPCOSIM_FMU_PATH", raising=False)
    first = ipcosim.run("single-mass-lqr", stop_time=0.05)
    err = capsys.readouterr().err
    assert err.count("ipcosim: building the FMUs") == 1, err
    assert "(IP02SingleMass, LQRSingleMass, Setpoint)" in err and str(cache) in err
    assert sorted(p.name for p in cache.glob("*.fmu")) == ["IP02SingleMass.fmu", "LQRSingleMass.fmu", "Setpoint.fmu"]
    assert first.metrics["upright"] is True
    again = ipcosim.run("single-mass-lqr", stop_time=0.05)
    assert "building" not in capsys.readouterr().err
    assert again["plant.cart_position"][-1] == first["plant.cart_position"][-1]


def test_fmus_of_other_makers_are_not_built(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A scenario naming an FMU this project does not make still fails with binding's one line."""
    from ipcosim.harness.api.engine import build_missing

    folder = tmp_path / "mine"
    folder.mkdir()
    text = (SCENARIO_DIR / "single-mass-lqr" / SSD_NAME).read_text().replace("LQRSingleMass", "TheirLaw")
    (folder / SSD_NAME).write_text(text)
    for f in (SCENARIO_DIR / "single-mass-lqr").glob("*.ssv"):
        (folder / f.name).write_text(f.read_text())
    scenario = load_scenario(folder)
    assert build_missing(scenario) == []
    with pytest.raises(ipcosim.IpcosimError, match="TheirLaw.fmu"):
        ipcosim.run(folder, stop_time=0.01)


def test_packing_is_incremental(tmp_path: Path) -> None:
    """`make demo` re-packs an archive only when one of its files changed."""
    import os
    import shutil

    from ipcosim.harness.scenario.ssp_pack import pack_all

    root = tmp_path / "ssp"
    shutil.copytree(SCENARIO_DIR / "single-mass-lqr", root / "single-mass-lqr")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "fmus").symlink_to(BUILD_FMU_DIR)
    archive = tmp_path / "out" / "ssp" / "single-mass-lqr.ssp"
    assert pack_all(tmp_path / "out", root) == [archive]
    before = archive.stat().st_mtime_ns
    assert pack_all(tmp_path / "out", root) == [] and archive.stat().st_mtime_ns == before
    ssv = next((root / "single-mass-lqr").glob("*.ssv"))
    os.utime(ssv, ns=(before + 10**9, before + 10**9))
    assert pack_all(tmp_path / "out", root) == [archive] and archive.stat().st_mtime_ns > before
