"""The residual cycle of friction and counts together (``ipcosim.harness.analysis.residual_cycle``), checked against
the first harmonic of the nonlinearities themselves, the Nyquist-crossing prediction of friction alone, the sensor
gain margins of the linear loop, and the bound a run records before it runs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.controllers.laws.lqg import coulomb_estimate
from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT, quantize
from ipcosim.harness.analysis import describing as df
from ipcosim.harness.analysis import residual_cycle as rc
from ipcosim.harness.analysis.analyze import break_point_margins, frequency_grid, scenario_loop, sensor_loop
from ipcosim.harness.analysis.limit_cycle import plant_of, predict


def _first_harmonic_gain(f, amplitude: float, n: int = 200_000) -> float:
    """b1 / A of ``f(A sin t)`` over one period: the describing function by its definition."""
    t = (np.arange(n) + 0.5) * 2 * math.pi / n
    y = np.array([f(amplitude * math.sin(v)) for v in t])
    return float(2.0 * np.mean(y * np.sin(t)) / amplitude)


@pytest.mark.parametrize("counts", [0.4, 0.6, 2 ** -0.5, 1.2, 1.5, 2.49, 3.7, 12.3])
def test_the_quantizers_describing_function_is_the_first_harmonic_of_the_encoders_reading(counts) -> None:
    q = PENDULUM_RAD_PER_COUNT
    exact = _first_harmonic_gain(lambda x: quantize(x, q), counts * q, 40_000)
    assert df.quantizer_gain(counts * q, q) == pytest.approx(exact, abs=2e-3)


def test_the_quantizers_gain_dips_below_one_under_each_threshold_and_tends_to_one() -> None:
    q = 1.0
    assert df.quantizer_gain(1.5, q) == pytest.approx(4 / (1.5 * math.pi) * math.sqrt(1 - 1 / 9), rel=1e-12)
    assert df.quantizer_gain(1.5, q) < df.quantizer_gain(2.5, q) < df.quantizer_gain(3.5, q) < 1.0
    assert df.quantizer_gain(500.5, q) == pytest.approx(1.0, abs=5e-5)     # the dips shrink as ~0.4 / n^1.5
    assert df.quantizer_gain(df.LINEAR_QUANTIZER_COUNTS - 0.5, q) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("ratio", [0.5, 1.3, 1.9, 2.5, 8.0])
def test_the_compensations_describing_function_is_the_first_harmonic_of_the_laws_estimate(ratio) -> None:
    b, v0 = 0.1047, 2e-3
    exact = _first_harmonic_gain(lambda v: coulomb_estimate(v, b, v0), ratio * v0, 20_000)
    assert df.compensation_gain(ratio * v0, b, v0) == pytest.approx(exact, abs=1e-3 * b / v0)


@pytest.mark.parametrize("ratio", [0.3, 0.99, 1.01, 1.7, 6.0, 40.0])
def test_the_dithered_relay_is_the_first_harmonic_of_the_friction_averaged_over_a_triangular_dither(ratio) -> None:
    """A triangle wave of half-width d spends equal time at every velocity in [-d, d]: the friction the slow
    swing feels is ``b sign(v + d')`` averaged over d' uniform there, taken here by its definition."""
    b, d = 0.1047, 2.5e-4
    shifts = (np.arange(400) + 0.5) / 400 * 2 * d - d
    averaged = lambda v: b * float(np.mean(np.sign(v + shifts)))   # noqa: E731
    exact = _first_harmonic_gain(averaged, ratio * d, 20_000)
    assert df.dithered_relay_gain(ratio * d, b, d) == pytest.approx(exact, rel=5e-3)
    assert df.dithered_relay_gain(ratio * d, b, 0.0) == df.relay_gain(ratio * d, b)


@pytest.mark.parametrize("ratio", [0.8, 1.5, 3.0])
def test_the_dithered_compensation_is_the_mean_of_the_laws_estimate_at_the_two_dithered_velocities(ratio) -> None:
    b, v0, d = 0.1047, 5e-4, 2.6e-4
    exact = _first_harmonic_gain(lambda v: 0.5 * (coulomb_estimate(v + d, b, v0) + coulomb_estimate(v - d, b, v0)),
                                 ratio * v0, 20_000)
    assert df.compensation_gain(ratio * v0, b, v0, d) == pytest.approx(exact, abs=2e-3 * b / v0)


def test_the_dithers_velocity_swing_is_the_triangle_of_a_mass_pushed_each_way_for_one_sample() -> None:
    """A free mass m pushed by +-F, the sign alternating every sample T: its velocity ramps by F T / m each
    sample, a triangle of half-width F T / (2 m); with viscous damping c (``v' = (F - c v) / m``), the steady
    alternation of the ZOH-sampled system stepped until it settles."""
    m, F, T = 0.94, 0.7, 1e-3
    Ad = np.array([[1.0, T], [0.0, 1.0]])
    Bd = np.array([[F * T ** 2 / (2 * m)], [F * T / m]])
    assert df.dither_velocity(Ad, Bd, 1, 1.0) == pytest.approx(F * T / (2 * m), rel=1e-12)
    c = 7.0
    e = math.exp(-c * T / m)
    Ad, Bd = np.array([[e]]), np.array([[F / c * (1 - e)]])
    v = 0.0
    for k in range(20_000):
        v = e * v + Bd[0, 0] * 0.4 * (-1) ** k
    assert df.dither_velocity(Ad, Bd, 0, 0.4) == pytest.approx(abs(v), rel=1e-9)


def test_friction_alone_is_the_nyquist_crossing_of_the_relay() -> None:
    """Without encoders and delay the harmonic balance of the single mass's one relay is the crossing of its
    velocity response with the negative real axis (``limit_cycle.predict``, found on a frequency grid)."""
    loop, _ = scenario_loop("single-mass-lqr", "thesis")
    [crossing] = predict(loop, {"b": 0.1047})
    p = rc.predict_residual(loop, plant_of(loop), {"b": 0.1047}, {}, delay=0)
    assert p["found"]
    assert p["frequency_Hz"] == pytest.approx(crossing["frequency_Hz"], rel=2e-3)
    for signal, amplitude in crossing["amplitudes"].items():
        assert p["signals"][signal]["amplitude"] == pytest.approx(amplitude, rel=5e-3), signal


def test_one_encoder_alone_balances_where_its_gain_is_the_loops_lower_gain_limit_on_that_signal() -> None:
    """The pendulum's counts alone: the quantizer's gain at the predicted amplitude is the factor on the pendulum
    reading at which the linear loop loses stability (the sensor's lower gain limit), at that crossing's frequency."""
    loop, _ = scenario_loop("single-mass-lqg", "tuned")
    j = 1   # the pendulum angle, second measured signal
    margins = break_point_margins(sensor_loop(loop, j), frequency_grid(loop.T, 4000))
    p = rc.predict_residual(loop, plant_of(loop), {}, {"pendulum_angle": PENDULUM_RAD_PER_COUNT}, delay=0)
    assert p["found"]
    a = p["signals"]["pendulum_angle"]["amplitude"]
    assert df.quantizer_gain(a, PENDULUM_RAD_PER_COUNT) == pytest.approx(margins["gain_lower"], rel=2e-3)
    assert 2 * math.pi * p["frequency_Hz"] == pytest.approx(margins["gain_lower_frequency_rad_s"], rel=1e-2)


def test_a_linear_loop_has_no_cycle_and_an_unstable_one_cannot_be_treated() -> None:
    loop, _ = scenario_loop("single-mass-lqr", "thesis")
    none = rc.predict_lab_cycle(loop, plant_of(loop), {"b": 0.0}, {}, 0)
    assert none["found"] and none["motor_cart_peak_to_peak_m"] == 0.0
    pid, _ = scenario_loop("single-mass-pid", "thesis")
    p = rc.predict_lab_cycle(pid, plant_of(pid), {"b": 0.1047}, {"cart_position": CART_M_PER_COUNT}, 1)
    assert not p["found"] and "not stable" in p["reason"]


def test_distinct_cycles_add_and_the_bound_is_the_prediction_plus_the_margin() -> None:
    from ipcosim.fmus.metrics import AMPLITUDE_MARGIN_M
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = select_parameter_set(load_scenario("single-mass-lqr"), "thesis")
    lab = realism_values("lab", "single-mass")
    p = rc.scenario_prediction(sc, lab)
    fr, qu = p["friction"], p["counts"]
    assert max(fr["frequency_Hz"], qu["frequency_Hz"]) > rc.DISTINCT_FREQUENCY_RATIO * min(
        fr["frequency_Hz"], qu["frequency_Hz"])
    assert p["motor_cart_peak_to_peak_m"] == pytest.approx(
        fr["motor_cart_peak_to_peak_m"] + qu["motor_cart_peak_to_peak_m"], rel=1e-12)
    bound = rc.run_bound(sc, lab)
    assert bound["amplitude_bound_from"] == "prediction"
    assert bound["amplitude_bound_m"] == pytest.approx(p["motor_cart_peak_to_peak_m"] + AMPLITUDE_MARGIN_M, rel=1e-12)


def test_a_run_the_prediction_cannot_treat_falls_back_on_the_friction_bound_and_says_why() -> None:
    from ipcosim.fmus.metrics import amplitude_bound
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = select_parameter_set(load_scenario("double-mass-adaptive-hsmc"), "thesis")
    values = {**realism_values("lab", "double-mass"), "plant.K": 120.0, "plant.b2": 0.12}
    bound = rc.run_bound(sc, values)
    assert bound["amplitude_bound_from"].startswith("friction bound: ")
    assert "not stable" in bound["amplitude_bound_from"]
    assert bound["amplitude_bound_m"] == pytest.approx(amplitude_bound(0.12, 120.0), rel=1e-12)
    assert bound["predicted_cart_peak_to_peak_m"] is None


def test_a_finer_pendulum_encoder_shrinks_the_predicted_cycle() -> None:
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = select_parameter_set(load_scenario("double-mass-lqg"), "lab")
    lab = realism_values("lab", "double-mass")
    coarse = rc.scenario_prediction(sc, lab)["counts"]
    fine = rc.scenario_prediction(sc, {**lab, "plant.pendulum_resolution": 2 * math.pi / 8192})["counts"]
    assert fine["signals"]["pendulum_angle"]["amplitude"] < coarse["signals"]["pendulum_angle"]["amplitude"]
    assert fine["motor_cart_peak_to_peak_m"] < coarse["motor_cart_peak_to_peak_m"]


def test_the_double_mass_cycle_adds_the_spring_windup_of_its_own_plant_to_the_motor_cart_only() -> None:
    """The passive cart rests at the turns while the motor cart winds the spring through 2 b2 of force: 2 b2 / K of
    travel on top of the sliding cycle, with the run's own spring and friction; the other signals are the sliding
    cycle's. The single mass has no spring: nothing is added."""
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = select_parameter_set(load_scenario("double-mass-lqg"), "lab")
    values = {**realism_values("lab", "double-mass"), "plant.K": 120.0, "plant.b2": 0.12}
    p = rc.scenario_prediction(sc, values)
    fr, qu = p["friction"], p["counts"]
    assert p["spring_windup_m"] == pytest.approx(2 * 0.12 / 120.0, rel=1e-12)
    assert p["motor_cart_peak_to_peak_m"] == pytest.approx(
        fr["motor_cart_peak_to_peak_m"] + qu["motor_cart_peak_to_peak_m"] + 2e-3, rel=1e-12)
    assert p["signals"]["passive_cart_position"]["peak_to_peak"] == pytest.approx(
        fr["signals"]["passive_cart_position"]["peak_to_peak"] + qu["signals"]["passive_cart_position"]["peak_to_peak"])
    single = rc.scenario_prediction(select_parameter_set(load_scenario("single-mass-lqr"), "thesis"),
                                    realism_values("lab", "single-mass"))
    assert single["spring_windup_m"] == 0.0
