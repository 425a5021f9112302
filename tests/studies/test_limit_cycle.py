"""The describing function's Coulomb friction limit cycles (``ipcosim.harness.analysis.limit_cycle``), checked
against the force the plant's own equations give and against the nonlinear loop's hunting."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.controllers.catalog import make_law
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.linearize import force_columns
from ipcosim.fmus.params import DEFAULT_PRESET, preset
from ipcosim.harness.analysis.analyze import scenario_loop
from ipcosim.harness.analysis.limit_cycle import predict
from ipcosim.harness.analysis.scenario_analysis import analyze


def test_force_columns_are_the_carts_accelerations_per_newton() -> None:
    """Single mass at upright: 1 N on the cart accelerates it by m22 / det and the pendulum by ml / det
    (the mass matrix of ``ipcosim.fmus.physics``); the double mass's motor-cart force reaches only that cart."""
    p = preset(DEFAULT_PRESET["single-mass"])
    ml, m22 = 0.5 * p.Mp * p.Lp, p.Mp * p.Lp ** 2 / 3.0
    det = (p.Meq + p.Mp) * m22 - ml * ml
    [(name, col)] = force_columns(p)
    assert name == "b"
    assert col == pytest.approx([0.0, m22 / det, 0.0, ml / det, 0.0], rel=1e-12)
    (n1, active), (n2, passive) = force_columns(preset(DEFAULT_PRESET["double-mass"]))
    assert (n1, n2) == ("b1", "b2")
    assert [i for i, v in enumerate(active) if v] == [1] and active[1] == pytest.approx(1 / 1.094, rel=1e-3)
    assert [i for i, v in enumerate(passive) if v] == [3, 5]


def _amplitude_and_frequency(t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    x = x - x.mean()
    ups = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    return (x.max() - x.min()) / 2, 1.0 / float(np.mean(np.diff(t[ups])))


def test_the_prediction_matches_the_hunting_of_the_nonlinear_loop() -> None:
    """The double-mass LQG without its compensation on a plant with the lab bench's stick-slip friction on both
    carts (exact readings): the passive cart's friction predicts the cycle the simulation settles into, its
    frequency and the passive cart's amplitude within 10 %; the motor cart's own friction adds its smaller
    cycle, so the motor cart swings between the passive cart's prediction and the sum of both."""
    law = make_law("double-mass", "LQG", "tuned")
    plant = preset(DEFAULT_PRESET["double-mass"], b1=0.1047, b2=0.1047)
    run = run_loop(law, plant, stop_time=30.0)
    loop, _ = scenario_loop("double-mass-lqg", "tuned")
    cycles = {c["parameter"]: c for c in predict(loop, {"b1": 0.1047, "b2": 0.1047})}
    b1, b2 = cycles["b1"], cycles["b2"]
    tail = run.time >= 15.0
    amplitude, frequency = _amplitude_and_frequency(run.time[tail], run.signal("passive_cart_position")[tail])
    assert amplitude == pytest.approx(b2["amplitudes"]["passive_cart_position"], rel=0.1)
    assert frequency == pytest.approx(b2["frequency_Hz"], rel=0.1)
    motor, frequency = _amplitude_and_frequency(run.time[tail], run.signal("active_cart_position")[tail])
    assert frequency == pytest.approx(b2["frequency_Hz"], rel=0.1)
    one, both = (b2["amplitudes"]["active_cart_position"],
                 b2["amplitudes"]["active_cart_position"] + b1["amplitudes"]["active_cart_position"])
    assert one < motor < 1.05 * both, (one, motor, both)
    assert one > 5e-3   # hunting far outside the +-1 mm band


def test_analyze_reports_the_cycles_with_the_forces_it_used() -> None:
    """``analyze``'s ``friction_limit_cycles``: the lab bench's forces for a plant without friction, the plant's
    own where set (the amplitude scales with the force), none predicted for an unstable loop."""
    r = analyze("single-mass-lqg", parameter_set="tuned")["friction_limit_cycles"]
    assert r["coulomb_forces_N"] == {"b": 0.1047} and r["forces_from"].startswith("the lab bench")
    [cycle] = r["cycles"]
    doubled = analyze("single-mass-lqg", parameter_set="tuned", set={"plant.b": 0.2094})["friction_limit_cycles"]
    assert doubled["forces_from"] == "the plant's parameters"
    assert doubled["cycles"][0]["amplitudes"]["cart_position"] == pytest.approx(
        2 * cycle["amplitudes"]["cart_position"], rel=1e-9)
    assert math.isclose(doubled["cycles"][0]["frequency_Hz"], cycle["frequency_Hz"], rel_tol=1e-9)
    unstable = analyze("double-mass-lqg", parameter_set="lab")
    assert not unstable["closed_loop_stable"] and unstable["friction_limit_cycles"]["cycles"] is None
