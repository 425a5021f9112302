"""A scenario that sets a parameter its FMU from the project's build folder does not have names the
command that rebuilds that folder (a checkout updated since the last ``ipcosim build``)."""
from __future__ import annotations

from pathlib import Path

import pytest

from ipcosim.harness.master.system import Model
from ipcosim.harness.scenario.rebuild import rebuild_hint
from ipcosim.harness.support import paths


def _model(path: Path) -> Model:
    return Model(name="X", variables={}, feedthrough={}, path=path)


@pytest.mark.parametrize(("folder", "command"), [("fmus", "`ipcosim build`"),
                                                 ("fmus-native", "`ipcosim build --native`"),
                                                 ("fmus-native-fmi3", "`ipcosim build --native --fmi 3`")])
def test_an_fmu_of_the_build_folder_names_its_rebuild(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       folder: str, command: str) -> None:
    monkeypatch.setattr(paths, "BUILD_DIR", tmp_path / "build")
    hint = rebuild_hint(_model(tmp_path / "build" / folder / "X.fmu"))
    assert hint.endswith(f"{command} rebuilds it") and str(tmp_path / "build" / folder) in hint


def test_an_fmu_from_elsewhere_gets_no_hint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(paths, "BUILD_DIR", tmp_path / "build")
    assert rebuild_hint(_model(tmp_path / "mine" / "X.fmu")) == ""
    assert rebuild_hint(Model(name="X", variables={}, feedthrough={})) == ""


def _run_error(capsys: pytest.CaptureFixture[str], out: Path, flavour: str, folder: Path, *sets: str) -> str:
    from ipcosim.harness.cli import main

    argv = ["run", "single-mass-lqr", "--fmus", flavour, "--fmu-dir", str(folder), "--out", str(out),
            "--stop-time", "0.01", "--quiet"]
    status = main([*argv, *(a for s in sets for a in ("--set", s))])
    err = capsys.readouterr().err.strip()
    assert status != 0 and len(err.splitlines()) == 1, err
    return err


def _stale_copy(python_dir: Path, build: Path) -> Path:
    """A copy of the Python FMU folder as ``build/fmus`` whose build cache records other sources than today's."""
    import json
    import shutil

    folder = build / "fmus"
    shutil.copytree(python_dir, folder)
    stamps = folder / ".build-stamps.json"
    entries = json.loads(stamps.read_text())
    stamps.write_text(json.dumps({k: {**v, "sha256": "0" * 64} for k, v in entries.items()}))
    return folder


def test_is_stale_reads_the_build_cache(native_fmus: tuple[Path, Path], tmp_path: Path) -> None:
    """An FMU the build cache names is stale when its recorded digest is not the sources' digest now; one the
    cache does not name is not known."""
    from ipcosim.fmus.pybuild import is_stale

    python_dir, native_dir = native_fmus
    assert is_stale(python_dir / "LQRSingleMass.fmu") is False
    assert is_stale(_stale_copy(python_dir, tmp_path / "build") / "LQRSingleMass.fmu") is True
    assert is_stale(native_dir / "LQRSingleMass.fmu") is None


def test_a_set_parameter_the_build_folder_lacks_names_its_rebuild(native_fmus: tuple[Path, Path], tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``--set`` of a parameter an FMU of the build folder lacks: with a Python folder older than the sources,
    the error says so and ends with the command that rebuilds it; with a current one, no such hint (the name
    is a slip); the native folder, whose cache says nothing, may be older; a design parameter the native
    flavour never has gets no such hint."""
    python_dir, native_dir = native_fmus
    monkeypatch.setattr(paths, "BUILD_DIR", native_dir.parent)
    err = _run_error(capsys, tmp_path / "python", "python", python_dir, "controller.no_such_gain=1")
    assert "'no_such_gain'" in err and "older than the sources" not in err, err
    err = _run_error(capsys, tmp_path / "native", "native", native_dir, "controller.no_such_gain=1")
    assert "'no_such_gain'" in err, err
    assert err.endswith(f"{native_dir} may be older than the sources: `ipcosim build --native` rebuilds it"), err
    err = _run_error(capsys, tmp_path / "design", "native", native_dir, "controller.Q_cart_position=1")
    assert "design parameter of the python flavour only" in err and "rebuilds it" not in err
    monkeypatch.setattr(paths, "BUILD_DIR", tmp_path / "build")
    stale = _stale_copy(python_dir, tmp_path / "build")
    err = _run_error(capsys, tmp_path / "stale", "python", stale, "controller.no_such_gain=1")
    assert err.endswith(f"{stale} is older than the sources: `ipcosim build` rebuilds it"), err
    assert not any((tmp_path / d).exists() for d in ("python", "native", "design", "stale")), "nothing is written"


def test_a_study_that_falls_back_says_why_from_the_native_build(native_fmus: tuple[Path, Path], tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A study's parameter the native FMUs lack: it runs on the Python flavour, and the line saying so tells
    from the native build which case it is: a design parameter its FMU lists as the Python flavour's only, a
    parameter the Python flavour has that the native FMU was built without (with the command that rebuilds the
    native folder), or a name neither flavour has."""
    import shutil
    import zipfile

    from ipcosim.harness.studies.specs import study_spec

    python_dir, native_dir = native_fmus
    monkeypatch.setattr(paths, "BUILD_DIR", native_dir.parent)    # the fixture's fmus/ and fmus-native/
    _, why = study_spec("single-mass-lqr", "auto", names=["controller.Q_cart_position"])
    assert why.startswith("python FMUs") and f"{native_dir} (a design parameter of the Python flavour" in why, why
    _, why = study_spec("single-mass-lqr", "auto", names=["controller.no_such_gain"])
    assert why.endswith(f"{native_dir}, nor of the Python ones)"), why
    # a native controller built without a gain the Python flavour has: its model description lacks K_cart_position
    old = tmp_path / "build"
    shutil.copytree(python_dir, old / "fmus")
    shutil.copytree(native_dir, old / "fmus-native")
    fmu = old / "fmus-native" / "LQRSingleMass.fmu"
    with zipfile.ZipFile(native_dir / "LQRSingleMass.fmu") as src, zipfile.ZipFile(fmu, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "modelDescription.xml":
                data = data.replace(b'name="K_cart_position"', b'name="K_cart_position_old"')
            dst.writestr(info, data)
    monkeypatch.setattr(paths, "BUILD_DIR", old)
    _, why = study_spec("single-mass-lqr", "auto", names=["controller.K_cart_position"])
    assert why.startswith("python FMUs"), why
    assert why.endswith(f"{old / 'fmus-native'}: they are older than the sources (`ipcosim build --native` rebuilds "
                        "them))"), why


def test_a_native_study_of_a_python_only_parameter_is_refused_in_one_line(native_fmus: tuple[Path, Path],
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """``--fmus native`` with a parameter only the Python flavour has: refused before any run, naming the
    parameter, the native folder and the flavour that runs it; a name neither flavour has is left to the
    study's own check (its closest-name answer)."""
    from ipcosim.errors import UsageError
    from ipcosim.harness.studies.specs import study_spec

    monkeypatch.setattr(paths, "BUILD_DIR", native_fmus[1].parent)
    with pytest.raises(UsageError) as info:
        study_spec("single-mass-lqr", "native", names=["controller.Q_cart_position"])
    msg = str(info.value)
    assert msg.startswith("--fmus native: controller.Q_cart_position is not a parameter of the native FMUs in "
                          f"{native_fmus[1]}") and msg.endswith("; --fmus python runs it"), msg
    spec, why = study_spec("single-mass-lqr", "native", names=["controller.no_such_gain"])
    assert why == "native FMUs" and "controller.no_such_gain" not in spec.parameters


def test_a_native_study_of_a_slip_of_a_python_only_name_suggests_it(native_fmus: tuple[Path, Path],
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A misspelt design weight on ``--fmus native``: the closest name is one only the Python FMUs have, so the
    answer names it and the flavour that runs it, instead of the native names nearest the slip; a slip of a
    native name is still the study's own closest-name answer."""
    from ipcosim.errors import UsageError
    from ipcosim.harness.studies.specs import study_spec

    monkeypatch.setattr(paths, "BUILD_DIR", native_fmus[1].parent)
    with pytest.raises(UsageError) as info:
        study_spec("single-mass-lqr", "native", names=["controller.Q_cart_positon"])
    msg = str(info.value)
    assert msg.startswith("--fmus native: unknown parameter 'controller.Q_cart_positon'; did you mean "
                          "'controller.Q_cart_position'"), msg
    assert "'controller.Q_cart_position'" in msg.split("(", 1)[1] and msg.endswith("--fmus python runs them)"), msg
    spec, why = study_spec("single-mass-lqr", "native", names=["controller.K_cart_positon"])
    assert why == "native FMUs" and "controller.K_cart_position" in spec.parameters
