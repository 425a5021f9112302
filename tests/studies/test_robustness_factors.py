"""The robustness study by factor: what each factor draws, that a deterministic bench is one run, and
which factor is named as breaking a loop first."""
from __future__ import annotations

import pytest

from ipcosim.fmus.instruments import realism
from ipcosim.harness.studies.robustness import (
    EXTRA_DELAY,
    FACTORS,
    decisive_factor,
    factor_cases,
    factor_cell,
    factor_runs,
    summarize,
)


def test_each_factor_draws_its_own_parameters_and_the_lab_bench_its_friction() -> None:
    vary, fixed = factor_runs("double-mass", ("masses",))
    assert vary == [f"plant.{n}=uniform(0.8,1.2)*nominal" for n in ("Ma", "Mc", "Mp")] and fixed == {}
    assert factor_runs("double-mass", ("motor Kt, Ra",))[0][0] == "plant.Kt=uniform(0.9,1.1)*nominal"
    assert factor_runs("single-mass", ("spring",)) == ([], {})
    vary, fixed = factor_runs("double-mass", ("lab bench", "delay"))
    inst, _ = realism("lab", "double-mass")
    assert fixed["plant.input_delay"] == pytest.approx(inst.input_delay + EXTRA_DELAY)
    assert fixed["plant.voltage_resolution"] == inst.voltage_resolution and fixed["plant.voltage_limit"] == 10.0
    assert sorted(v.partition("=")[0] for v in vary) == ["plant.b1", "plant.b2"]
    with pytest.raises(ValueError, match="unknown robustness factor 'mass'"):
        factor_runs("double-mass", ("mass",))


def test_a_deterministic_factor_is_one_run_and_a_drawn_one_as_many_as_asked() -> None:
    class Spec:
        parameters = {"plant.Ma": 0.5, "plant.Mc": 1.0, "plant.Mp": 0.1, "plant.input_delay": 0.0}

    assert len(factor_cases(Spec(), "double-mass", ("delay",), 200)) == 1
    cases = factor_cases(Spec(), "double-mass", ("masses",), 50, seed=3)
    assert len(cases) == 50 and len({c.params["plant.Mp"] for c in cases}) == 50
    assert all(0.08 <= c.params["plant.Mp"] <= 0.12 for c in cases)


def _summary(ok: int, n: int) -> dict:
    return summarize([{"status": "ok"}] * ok + [{"status": "fell"}] * (n - ok), ())


def test_the_factor_that_breaks_a_loop_first_is_the_worst_alone_below_95_percent() -> None:
    rows = {f: _summary(200, 200) for f in FACTORS}
    rows["all together"] = _summary(10, 200)
    assert decisive_factor(rows) == "none alone"
    rows["spring"], rows["lab bench"] = _summary(150, 200), _summary(20, 200)
    assert decisive_factor(rows) == "lab bench"
    assert factor_cell(_summary(150, 200)) == "75.0 % (68.6-80.5)"
    assert factor_cell(_summary(1, 1)) == "ok (1 run)" and factor_cell(_summary(0, 1)) == "fell (1 run)"


def test_a_sweep_on_the_lab_bench_sets_its_values_and_set_wins_over_them() -> None:
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.studies.robustness import sweep_study

    lab = realism_values("lab", "double-mass")
    inst, plant = realism("lab", "double-mass")
    assert lab["plant.input_delay"] == inst.input_delay and lab["plant.b2"] == plant["b2"]
    study = sweep_study("double-mass-lqg", ["plant.K=uniform(0.8,1.2)*nominal"], samples=2, realism="lab",
                        set={"plant.b2": 0.0}, fmus="python")
    given = study.metadata["set"]
    assert given["plant.b1"] == plant["b1"] and given["plant.b2"] == 0.0
    assert study.spec.set["plant.voltage_resolution"] == inst.voltage_resolution


def test_a_lab_sweep_of_a_scenario_whose_kind_its_name_does_not_say_is_refused_by_name() -> None:
    from ipcosim.errors import UsageError
    from ipcosim.harness.studies.robustness import sweep_study

    with pytest.raises(UsageError, match="--realism lab: cannot tell the plant kind of scenario 'my-loop'"):
        sweep_study("my-loop", ["plant.K=uniform(0.8,1.2)*nominal"], realism="lab")
