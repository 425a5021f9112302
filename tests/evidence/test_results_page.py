"""docs/results.md is what its generator writes: its generated block is the rendering of the committed data
(docs/results.json: tests/project/test_docblocks.py), and the parts of that data that are cheap to recompute are
recomputed here (the margins, the verdicts from their measurements, the success rates and Wilson intervals from
the counts, the factor that breaks each loop first)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from evidence.claims import CLAIMS, verdict
from evidence.results_page import breakaway_note, margin_rows, remeasure
from ipcosim.harness.studies.robustness import FACTORS, decisive_factor, wilson_interval

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "results.md"
DATA = ROOT / "docs" / "results.json"


@pytest.fixture(scope="module")
def data() -> dict:
    return json.loads(DATA.read_text())


@pytest.mark.slow
def test_the_margins_are_those_the_analysis_gives_now(data: dict) -> None:
    now = margin_rows()
    assert [(r["scenario"], r["set"]) for r in now] == [(r["scenario"], r["set"]) for r in data["margins"]]
    for a, b in zip(now, data["margins"]):
        for key, value in a.items():
            if isinstance(value, float):
                assert b[key] == pytest.approx(value, rel=1e-6), (a["scenario"], a["set"], key)
            else:
                assert b[key] == value, (a["scenario"], a["set"], key)


def test_the_lab_lqg_is_unstable_in_the_linearization_by_its_breakaway_term_alone(data: dict) -> None:
    """What breakaway_note() says of the double-mass LQG's lab row, measured."""
    from ipcosim.controllers.laws.lqg import LAB_LQG
    from ipcosim.harness.analysis.analyze import analyze_loop, scenario_loop

    gain = LAB_LQG["double-mass"]["friction_breakaway_gain"]
    assert gain > 0 and f"({gain:g})" in breakaway_note()
    rows = {r["set"]: r for r in data["margins"] if r["scenario"] == "double-mass-lqg"}
    assert not rows["lab"]["stable"] and rows["tuned"]["stable"]
    loop = scenario_loop("double-mass-lqg", parameter_set="lab", set={"controller.friction_breakaway_gain": 0.0})[0]
    r = analyze_loop(loop, pid_search=False)
    assert r["closed_loop_stable"]
    assert r["phase_margin_deg"] == pytest.approx(rows["tuned"]["phase_margin_deg"], rel=1e-6)
    assert r["delay_margin_s"] == pytest.approx(rows["tuned"]["delay_margin_s"], rel=1e-6)


def test_the_soft_lab_lqg_is_the_lab_set_with_a_larger_voltage_weight_and_a_delay_margin_beyond_the_bench(
        data: dict) -> None:
    """The double mass's lab-soft set changes only the regulator's voltage weight of the lab set, upward (a softer
    loop); like the lab set it has no linear margins with its breakaway term, and without it the loop tolerates
    far more delay than the lab bench's 2 ms (its computation sample and the rig's 1 ms)."""
    from ipcosim.controllers.catalog import set_values
    from ipcosim.harness.analysis.analyze import analyze_loop, scenario_loop

    lab, soft = set_values("double-mass", "LQG", "lab"), set_values("double-mass", "LQG", "lab-soft")
    assert {k for k in lab.keys() | soft.keys() if lab.get(k) != soft.get(k)} == {"R"} and soft["R"] > lab["R"]
    rows = {r["set"]: r for r in data["margins"] if r["scenario"] == "double-mass-lqg"}
    assert not rows["lab-soft"]["stable"]
    loop = scenario_loop("double-mass-lqg", parameter_set="lab-soft",
                         set={"controller.friction_breakaway_gain": 0.0})[0]
    r = analyze_loop(loop, pid_search=False)
    assert r["closed_loop_stable"] and r["delay_margin_s"] > 5 * 2e-3


def test_each_verdict_follows_from_its_measurements(data: dict) -> None:
    """Never 'confirmed' by a fitted lab value; below the sensor's resolution, indistinguishable."""
    fitted = {c.text: c.fitted for c in CLAIMS}
    assert [r["claim"] for r in data["claims"]] == [c.text for c in CLAIMS]
    for r in data["claims"]:
        assert r["verdict"] == verdict(r["ideal"]["holds"], r["lab"]["holds"], fitted[r["claim"]])
        if fitted[r["claim"]]:
            assert not r["verdict"].startswith("confirmed")


def test_robustness_rates_and_intervals_follow_from_the_counts(data: dict) -> None:
    rob = data["robustness"]
    assert rob["samples"] >= 200
    for row in rob["rows"]:
        assert set(row["factors"]) <= {*FACTORS, "all together"} and "all together" in row["factors"]
        for factor, s in row["factors"].items():
            ok = s["counts"].get("ok", 0)
            assert sum(s["counts"].values()) == s["runs"] and s["success_rate"] == ok / s["runs"]
            assert s["runs"] == (1 if factor == "delay" else rob["samples"]), (row["scenario"], factor)
            assert s["success_ci95"] == pytest.approx(list(wilson_interval(ok, s["runs"])))
        breaks = decisive_factor(row["factors"])
        assert breaks == "none alone" or row["factors"][breaks]["success_rate"] < 0.95


def test_remeasuring_an_unknown_row_names_it_and_the_closest_before_running_anything(data: dict) -> None:
    with pytest.raises(ValueError, match=r"--rows single-mass-lqq: not a row .*single-mass-lqg"):
        remeasure(data, ["single-mass-lqq"])


def test_the_success_table_rates_follow_from_the_counts_and_the_target_law_has_two_seeds(data: dict) -> None:
    from evidence.results_page import ROBUST_LAB_SETS, ROBUST_SCENARIOS, VERDICT_SEEDS

    rows = data["verdict"]
    assert {r["scenario"] for r in rows} == {name for name, _ in ROBUST_SCENARIOS}
    for lab in ROBUST_LAB_SETS["double-mass-lqg"]:
        seeds = sorted(r["seed"] for r in rows if r["scenario"] == "double-mass-lqg" and r["set"] == lab
                       and not r.get("bench_change"))
        assert seeds == list(VERDICT_SEEDS["double-mass-lqg"]), lab
    for r in rows:
        ok = r["counts"].get("ok", 0)
        assert r["runs"] >= 200 and sum(r["counts"].values()) == r["runs"] and r["success_rate"] == ok / r["runs"]
        assert r["success_ci95"] == pytest.approx(list(wilson_interval(ok, r["runs"])))
        # a success is upright with the mean error in 1 mm: neither fraction can be below the success rate
        assert r["success_rate"] <= r["mean_error_ok"] <= r["upright"]
        assert r["upright"] == pytest.approx(1 - r["counts"].get("fell", 0) / r["runs"])
        amp = r["distributions"]["cart_peak_to_peak_m"]
        assert amp["median"] <= amp["p90"]
        if "old_success_rate" in r:   # measured with each run's bound: the friction bound's figures beside
            old = round(r["old_success_rate"] * r["runs"])
            assert r["old_success_ci95"] == pytest.approx(list(wilson_interval(old, r["runs"])))
            assert r["old_success_rate"] <= r["mean_error_ok"]
            assert 0 <= r["fallback_runs"] <= r["runs"]


def test_each_comparison_verdict_is_the_success_criterion_of_its_measurements(data: dict) -> None:
    from evidence.comparison import BENCHES, LAWS
    from ipcosim.fmus.metrics import AMPLITUDE_MARGIN_M, amplitude_bound, success_status

    rows = data["comparison"]
    assert [(r["scenario"], r["bench"]) for r in rows] == [
        (f"{kind}-{law}", bench) for kind, laws in LAWS.items() for law, _, _ in laws for bench in BENCHES]
    for r in rows:
        s, where = r["step"], (r["scenario"], r["bench"])
        assert s["status"] == success_status(s, s["amplitude_bound_m"]), where
        # the friction bound beside it: 2 b2 / K beyond 2 mm where the lab bench's friction acts on a passive cart
        forced = r["kind"] == "double-mass" and r["bench"] == "lab"
        assert s["old_amplitude_bound_m"] == pytest.approx(amplitude_bound(0.1047, 142.185) if forced else 0.002)
        assert s["old_status"] == success_status(s, s["old_amplitude_bound_m"]), where
        if s["amplitude_bound_from"] == "prediction":   # the predicted cycle plus the margin; none on the ideal plant
            assert s["amplitude_bound_m"] == pytest.approx(s["predicted_cart_peak_to_peak_m"] + AMPLITUDE_MARGIN_M)
            assert (s["predicted_cart_peak_to_peak_m"] == 0.0) == (r["bench"] == "ideal"), where
        else:
            assert s["amplitude_bound_m"] == s["old_amplitude_bound_m"], where
        for what in ("push", "tap"):
            assert r[what]["upright"] in (True, False)


def test_each_prediction_row_is_a_lab_run_that_stayed_upright_and_its_target_verdict_follows(data: dict) -> None:
    from evidence.residual_check import TOLERANCE, error, why

    upright = [(r["scenario"], r["set"]) for r in data["comparison"]
               if r["bench"] == "lab" and r["step"]["upright"] is True]
    assert [(r["scenario"], r["set"]) for r in data["prediction"]] == upright
    for r in data["prediction"]:
        e = error(r)
        assert (e is not None and abs(e) <= TOLERANCE) == why(r).startswith("within"), r["scenario"]
