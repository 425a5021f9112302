"""A scenario that sets a parameter its FMU from the project's build folder does not have names the
command that rebuilds that folder (a checkout updated since the last ``ipcosim build``)."""
from __future__ import annotations

from pathlib import Path

import pytest

from ipcosim.harness import paths
from ipcosim.harness.master.system import Model
from ipcosim.harness.scenario.binding import _rebuild_hint


def _model(path: Path) -> Model:
    return Model(name="X", variables={}, feedthrough={}, path=path)


@pytest.mark.parametrize(("folder", "command"), [("fmus", "`ipcosim build`"),
                                                 ("fmus-native", "`ipcosim build --native`"),
                                                 ("fmus-native-fmi3", "`ipcosim build --native --fmi 3`")])
def test_an_fmu_of_the_build_folder_names_its_rebuild(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       folder: str, command: str) -> None:
    monkeypatch.setattr(paths, "BUILD_DIR", tmp_path / "build")
    hint = _rebuild_hint(_model(tmp_path / "build" / folder / "X.fmu"))
    assert hint.endswith(f"{command} rebuilds it") and str(tmp_path / "build" / folder) in hint


def test_an_fmu_from_elsewhere_gets_no_hint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(paths, "BUILD_DIR", tmp_path / "build")
    assert _rebuild_hint(_model(tmp_path / "mine" / "X.fmu")) == ""
    assert _rebuild_hint(Model(name="X", variables={}, feedthrough={})) == ""
