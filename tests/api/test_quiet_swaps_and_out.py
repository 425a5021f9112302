"""A swapped-in FMU's missing parameters are one warning line (an error with --strict), and a run's
output folder never mixes two runs' files."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from ipcosim.harness.cli import main
from ipcosim.harness.support.paths import BUILD_FMU_DIR, SCENARIO_DIR

pytestmark = pytest.mark.integration
PID = BUILD_FMU_DIR / "PIDSingleMass.fmu"


def _run(tmp_path: Path, *extra: str) -> list[str]:
    return ["run", "single-mass-lqr", "--swap", f"controller={PID}", "--stop-time", "0.05", "--quiet", *extra]


def _set_but_missing(ssv: Path, fmu: Path) -> list[str]:
    """The parameters a scenario's set gives the controller that ``fmu`` has no variable for."""
    import xml.etree.ElementTree as ET

    from fmpy import read_model_description
    have = {v.name for v in read_model_description(str(fmu)).modelVariables}
    names = [e.get("name") for e in ET.parse(ssv).iter() if e.tag.endswith("}Parameter")]
    return [n for n in names if n not in have]


def test_missing_parameters_of_a_swap_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_run(tmp_path, "--out", str(tmp_path / "a"))) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    missing = _set_but_missing(SCENARIO_DIR / "single-mass-lqr" / "thesis.ssv", PID)
    assert f"sets {len(missing)} parameter(s) the FMU does not have: " in err[0] and "ignored" in err[0]
    assert all(name in err[0] for name in missing) and "Q_cart_position" in missing
    assert main(_run(tmp_path, "--out", str(tmp_path / "b"), "--strict")) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ipcosim run: error:") and "the FMU does not have" in err[0]
    assert not (tmp_path / "b" / "results.csv").exists()


def test_a_previous_runs_files_are_replaced_not_mixed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "plot.png").write_bytes(b"a stale double-mass figure")
    (out / "metrics.json").write_text('{"stale": true}')
    (out / "notes.txt").write_text("mine")
    assert main(["run", "single-mass-lqr", "--stop-time", "0.05", "--quiet", "--out", str(out)]) == 0
    assert not (out / "plot.png").exists(), "no stale figure beside fresh results"
    assert "stale" not in json.loads((out / "metrics.json").read_text())
    assert (out / "notes.txt").read_text() == "mine"


def test_a_sweeps_results_are_never_replaced(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "results.csv").write_text("index,seed,status\n0,1,ok\n")
    assert main(["run", "single-mass-lqr", "--stop-time", "0.05", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "its results.csv is not a run's (first column 'index'" in err[0]
    assert (out / "results.csv").read_text() == "index,seed,status\n0,1,ok\n"
