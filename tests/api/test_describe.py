"""`ipcosim describe` and the closest-name answers a user gets for an unknown name."""
from __future__ import annotations

import json

import pytest

from ipcosim.errors import closest
from ipcosim.harness.api.describe import describe, describe_text
from ipcosim.harness.cli import main


def _variables(info: dict, component: str) -> dict[str, dict]:
    comp = next(c for c in info["components"] if c["name"] == component)
    return {v["name"]: v for v in comp["variables"]}


def test_describe_lists_components_variables_units_and_bound_starts() -> None:
    info = describe("single-mass-lqr")
    assert [c["name"] for c in info["components"]] == ["setpoint", "controller", "plant"]
    plant = _variables(info, "plant")
    assert plant["Mp"]["unit"] == "kg" and plant["Mp"]["causality"] == "parameter" and "python" in plant["Mp"]["set"]
    assert plant["Mp"]["description"]
    assert plant["voltage"]["set"] == [], "an input fed by a connection cannot be --set"
    assert plant["cart_position"]["set"] == [] and plant["cart_position"]["unit"] == "m"
    assert info["parameter_sets"]["bound"] == ["thesis"]


def test_describe_start_values_follow_the_parameter_set() -> None:
    thesis = _variables(describe("single-mass-hsmc", parameter_set="thesis"), "controller")
    tuned = _variables(describe("single-mass-hsmc", parameter_set="tuned"), "controller")
    assert tuned["c1"]["start"] == pytest.approx(5.63) and tuned["KI"]["start"] == pytest.approx(1540.0)
    assert thesis["c1"]["start"] == pytest.approx(43.99107779453682)


def test_describe_command_text_and_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["describe", "single-mass-lqr", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert _variables(info, "controller")["sample_period"]["unit"] == "s"
    text = describe_text(info)
    assert "component plant: IP02SingleMass" in text
    line = next(row for row in text.splitlines() if row.split()[:1] == ["Mp"])
    assert line.split()[1:4] == ["parameter", "Real", "kg"]


@pytest.mark.parametrize("argv,expected", [
    (["describe", "single-mass-lqrr"], "unknown scenario 'single-mass-lqrr'; did you mean 'single-mass-lqr'"),
    (["run", "single-mass-lqr", "--set", "plant.Mpp=0.2"], "has no variable 'Mpp'; did you mean 'Mp'?"),
    (["run", "single-mass-lqr", "--set", "plantt.Mp=0.2"], "no component 'plantt'; did you mean 'plant'?"),
    (["run", "single-mass-lqr", "--parameter-set", "thesiss"], "no parameter set 'thesiss'; did you mean 'thesis'?"),
    (["linearize", "single-mass", "--preset", "thesis-ch33", "--json"], "did you mean 'thesis-ch3'"),
    (["linearize", "single-mas", "--json"], "invalid choice 'single-mas'; did you mean 'single-mass'?"),
])
def test_unknown_names_answer_with_the_closest(argv: list[str], expected: str, tmp_path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    if argv[0] == "run":
        argv = [*argv, "--out", str(tmp_path / "out"), "--stop-time", "0.01"]
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        status = exc.code
    err = capsys.readouterr().err
    assert status != 0 and expected in err, err
    assert not (tmp_path / "out").exists(), "a bad name fails before anything is written"


def test_closest_without_a_near_name_lists_few_and_counts_many() -> None:
    assert closest("zzz", ["a", "b"]) == "known: a, b"
    assert closest("zzz", [f"n{i}" for i in range(40)]) == "none close among 40 names"
    assert closest("mp", ["Mp", "Lp"]) == "did you mean 'Mp'?"
