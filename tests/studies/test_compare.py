"""The comparison report: claims judged from measured numbers, Markdown and self-contained
HTML rendering, figures; the robustness defaults. Rendered from hand-made result rows (no FMUs);
the end-to-end run on real FMUs is in test_studies_integration.py."""
from __future__ import annotations

import base64
import math
import re

import numpy as np
import pytest

from evidence.claims import CLAIMS, on_comparison
from ipcosim.harness.api.grammar import parse_all
from ipcosim.harness.studies import report
from ipcosim.harness.studies.robustness import DEFAULT_UNCERTAINTY, default_vary, summarize


def row(status="ok", **metrics):
    base = {"status": status, "settling_time_s": 2.0, "overshoot_m": 0.001, "steady_state_error_m": 1e-4,
            "max_abs_angle_rad": 0.05, "peak_voltage_V": 5.0, "rms_voltage_V": 1.0, "upright": status != "fell",
            "angle_reversals": 4, "cost": 0.02, "fall_time_s": None}
    base.update(metrics)
    return base


def thesis_like():
    """Results shaped as the thesis describes them: every claim should come out confirmed."""
    return {
        "single-mass-pid": row("fell", upright=False, settling_time_s=None, cost=math.inf, fall_time_s=0.4),
        "single-mass-lqr": row("ok", angle_reversals=12, cost=0.03),
        "single-mass-hsmc": row("ok", angle_reversals=3, settling_time_s=2.5, steady_state_error_m=2e-4, cost=0.02),
        "single-mass-adaptive-hsmc": row("ok", settling_time_s=1.5),
        "double-mass-pid": row("fell", upright=False, settling_time_s=None, cost=math.inf),
        "double-mass-lqr": row("fell", upright=False, settling_time_s=None, cost=math.inf, fall_time_s=3.0),
        "double-mass-hsmc": row("unsettled", settling_time_s=None, steady_state_error_m=0.0056, cost=0.05),
        "double-mass-adaptive-hsmc": row("ok", settling_time_s=3.0, steady_state_error_m=0.0002),
    }


def verdicts(results):
    return {source: v for _, source, _, v in on_comparison(results)}


def test_every_claim_confirmed_on_thesis_like_results():
    out = on_comparison(thesis_like())
    assert len(out) == len(CLAIMS) >= 10
    assert [v.verdict for *_, v in out] == ["confirmed"] * len(out), [(s, v) for _, s, _, v in out]


@pytest.mark.parametrize("scenario, change, source", [
    ("single-mass-pid", {"status": "ok", "upright": True}, "3.2.1"),
    ("single-mass-lqr", {"angle_reversals": 2}, "3.2.2, Fig. 3.9 (simulation)"),
    ("single-mass-hsmc", {"steady_state_error_m": 0.002}, "ch. 5, Fig. 3.11"),
    ("single-mass-adaptive-hsmc", {"settling_time_s": None}, "3.2.4, Fig. 3.12"),
    ("single-mass-hsmc", {"angle_reversals": 20}, "3.3, Fig. 3.19 (experiment)"),
    ("double-mass-hsmc", {"cost": math.inf}, "ch. 5"),
    ("double-mass-pid", {"status": "ok", "upright": True}, "4.2.1, Fig. 4.7"),
    ("double-mass-lqr", {"status": "ok", "upright": True}, "4.2.2, Fig. 4.9"),
    ("double-mass-hsmc", {"steady_state_error_m": 1e-5}, "4.2.3, Fig. 4.11 (simulation)"),
    ("double-mass-adaptive-hsmc", {"steady_state_error_m": 0.01}, "4.2.4, Fig. 4.12"),
])
def test_each_claim_is_refuted_when_the_numbers_say_otherwise(scenario, change, source):
    results = thesis_like()
    results[scenario] = {**results[scenario], **change}
    assert verdicts(results)[source].verdict == "not confirmed"


def test_missing_or_failed_scenarios_are_not_measured():
    results = thesis_like()
    del results["single-mass-pid"]
    results["double-mass-lqr"] = {"status": "error", "error": "FMU crashed at t = 1 s"}
    v = verdicts(results)
    assert v["3.2.1"] == report.Verdict("not measured", "single-mass-pid: not run")
    assert v["4.2.2, Fig. 4.9"].verdict == "not measured"
    assert "FMU crashed at t = 1 s" in v["4.2.2, Fig. 4.9"].measured


def series(amplitude, seed):
    t = np.linspace(0, 5, 501)
    x = 0.05 * (1 - np.exp(-2 * t)) * (1 + amplitude * np.sin(5 * t + seed))
    return {"time": t.tolist(), "position": x.tolist(), "reference": np.full_like(t, 0.05).tolist(),
            "angle": (0.05 * np.exp(-t) * np.sin(8 * t)).tolist(), "voltage": (3 * np.exp(-t)).tolist()}


def test_render_markdown_html_and_figures(tmp_path):
    results = thesis_like()
    for i, name in enumerate(results):
        results[name]["series"] = series(0.1 * (i % 3), i)
    results["single-mass-cascade-pid"] = {"status": "error", "error": "could not load Setpoint.fmu"}
    rob = {"single-mass-lqr": summarize([{"status": "ok"}] * 3 + [{"status": "fell"}], [])}
    files = report.render(results, tmp_path, robustness=rob, robustness_note="+-20 % note",
                          meta={"stop time": "5 s", "packages": {"numpy": "2"}}, claims=on_comparison(results))
    md = files["markdown"].read_text()
    # the table: one line per scenario, in plant x controller order, with the robustness column
    lines = [line for line in md.splitlines() if line.startswith("| single mass") or line.startswith("| double mass")]
    assert len(lines) == 9
    assert lines[0].startswith("| single mass | PID | - | fell |")
    assert lines[1].startswith("| single mass | CascadePID | - | error |")
    lqr = next(line for line in lines if "| LQR |" in line and line.startswith("| single"))
    assert "| 75 % (4 runs, CI" in lqr and "| 12 |" in lqr
    assert "10 confirmed, 0 not confirmed, 0 not measured" in md
    assert "could not load Setpoint.fmu" in md
    assert "![single-mass](figures/single-mass.png)" in md
    # self-contained HTML: every image inline, no external references
    page = files["html"].read_text()
    images = re.findall(r'src="([^"]+)"', page)
    assert len(images) == 2 and all(s.startswith("data:image/png;base64,") for s in images)
    png = base64.b64decode(images[0].split(",", 1)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert "href=" not in page and "<script" not in page
    assert page.count('class="confirmed"') == 10
    assert (tmp_path / "figures" / "double-mass.png").stat().st_size > 5000
    # without claims (the package's own ``ipcosim compare``) the report has no claims section
    bare = report.render(results, tmp_path / "bare")["markdown"].read_text()
    assert "claims, measured" not in bare and "| single mass | PID |" in bare


def test_default_uncertainty_names_only_physical_parameters():
    single = {"plant.Mc": 0.96, "plant.Mp": 0.23, "plant.Beq": 11.55, "plant.Bp": 0.0024, "plant.Ra": 2.6}
    exprs = default_vary("single-mass", single)
    assert exprs == [f"{n}=uniform(0.8,1.2)*nominal" for n in DEFAULT_UNCERTAINTY["single-mass"]]
    varies = parse_all(exprs, single)
    assert {v.name for v in varies} == {"plant.Mc", "plant.Mp", "plant.Beq", "plant.Bp"}
    assert "plant.K" in DEFAULT_UNCERTAINTY["double-mass"]
    # a scenario lacking one of them simply does not vary it
    assert default_vary("double-mass", {"plant.K": 142.0}) == ["plant.K=uniform(0.8,1.2)*nominal"]


def test_a_comparison_is_refused_before_any_run_without_scenarios_or_samples(tmp_path):
    from ipcosim.errors import UsageError
    from ipcosim.harness.studies.compare import comparison

    with pytest.raises(UsageError, match="no scenarios found"):
        comparison([], tmp_path / "a")
    with pytest.raises(UsageError, match="--samples 0"):
        comparison(["single-mass-lqr"], tmp_path / "b", samples=0)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_scenario_that_does_not_load_is_an_error_row_and_the_only_one_fails_the_comparison(tmp_path):
    from ipcosim.harness.studies.compare import comparison

    lines: list[str] = []
    study = comparison(["no-such-scenario"], tmp_path, log=lines.append)
    assert not study.specs and study.results["no-such-scenario"]["status"] == "error"
    assert "unknown scenario 'no-such-scenario'" in lines[0]
    assert study.counts() == (0, 1)
    assert study.failure().startswith("every scenario failed to run; no-such-scenario: unknown scenario")

