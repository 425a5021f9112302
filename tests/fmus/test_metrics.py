"""ipcosim.fmus.metrics: the DESIGN.md metric definitions on synthetic signals with known answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.fmus.metrics import METRIC_KEYS, MetricsError, compute_metrics

T = np.linspace(0.0, 10.0, 10001)  # 1 ms grid


def first_order(tau: float, amplitude: float = 0.05) -> np.ndarray:
    return amplitude * (1 - np.exp(-T / tau))


def zeros() -> np.ndarray:
    return np.zeros_like(T)


def test_keys_are_the_design_contract() -> None:
    m = compute_metrics(T, first_order(0.5), np.full_like(T, 0.05), zeros(), zeros())
    assert set(m) == set(METRIC_KEYS)
    assert set(METRIC_KEYS) == {"settling_time_s", "overshoot_m", "steady_state_error_m", "max_abs_angle_rad",
                                "peak_voltage_V", "rms_voltage_V", "upright", "residual_window_s",
                                "cart_mean_error_m", "cart_peak_to_peak_m", "cart_frequency_Hz",
                                "cart_time_in_band", "angle_mean_rad", "angle_peak_to_peak_rad",
                                "angle_frequency_Hz", "limit_cycle"}


def test_first_order_step_settling_time_is_tau_ln_50() -> None:
    tau = 0.5
    m = compute_metrics(T, first_order(tau), np.full_like(T, 0.05), zeros(), zeros())
    # |x - r| = 0.05 e^(-t/tau) <= 2 % of 0.05  <=>  t >= tau ln 50 (first grid point at or after it)
    assert m["settling_time_s"] == pytest.approx(tau * math.log(50), abs=1e-3)
    assert m["overshoot_m"] == 0.0
    assert m["steady_state_error_m"] == pytest.approx(0.05 * np.mean(np.exp(-T[T >= 9.0] / tau)), rel=1e-9)


def test_settling_time_counts_from_the_reference_step() -> None:
    t_step = 2.0
    r = np.where(T >= t_step, 0.05, 0.0)
    x = np.where(T >= t_step, 0.05 * (1 - np.exp(-(T - t_step) / 0.3)), 0.0)
    m = compute_metrics(T, x, r, zeros(), zeros())
    assert m["settling_time_s"] == pytest.approx(0.3 * math.log(50), abs=1e-3)


def test_last_entry_into_the_band_not_the_first() -> None:
    # enters the band at 1 s, leaves it between 3 and 4 s, re-enters at 4 s for good
    x = np.where(T < 1.0, 0.0, 0.05)
    x = np.where((T >= 3.0) & (T < 4.0), 0.06, x)
    m = compute_metrics(T, x, np.full_like(T, 0.05), zeros(), zeros())
    assert m["settling_time_s"] == pytest.approx(4.0, abs=1e-9)
    assert m["overshoot_m"] == pytest.approx(0.01)


def test_not_settled_at_the_end_gives_none() -> None:
    x = first_order(0.5)
    x[-50:] = 0.0
    m = compute_metrics(T, x, np.full_like(T, 0.05), zeros(), zeros())
    assert m["settling_time_s"] is None


def test_underdamped_overshoot_and_negative_step() -> None:
    wn, zeta = 4.0, 0.3
    wd = wn * math.sqrt(1 - zeta ** 2)
    resp = 1 - np.exp(-zeta * wn * T) * (np.cos(wd * T) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * T))
    expected_os = math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2))
    for amp in (0.05, -0.05):
        m = compute_metrics(T, amp * resp, np.full_like(T, amp), zeros(), zeros())
        assert m["overshoot_m"] == pytest.approx(abs(amp) * expected_os, rel=1e-3)


def test_angle_and_voltage_metrics() -> None:
    angle = 0.2 * np.sin(2 * np.pi * T)
    volts = 3.0 * np.sin(2 * np.pi * T)
    m = compute_metrics(T, first_order(0.5), np.full_like(T, 0.05), angle, volts)
    assert m["max_abs_angle_rad"] == pytest.approx(0.2, rel=1e-6)
    assert m["peak_voltage_V"] == pytest.approx(3.0, rel=1e-6)
    assert m["rms_voltage_V"] == pytest.approx(3.0 / math.sqrt(2), rel=1e-3)
    assert m["upright"] is True
    m = compute_metrics(T, first_order(0.5), np.full_like(T, 0.05), angle * 2, volts)
    assert m["upright"] is False


def test_upright_limit_is_strict_at_0_35_rad() -> None:
    angle = zeros()
    angle[5000] = -0.35
    assert compute_metrics(T, first_order(0.5), np.full_like(T, 0.05), angle, zeros())["upright"] is False
    angle[5000] = -0.3499
    assert compute_metrics(T, first_order(0.5), np.full_like(T, 0.05), angle, zeros())["upright"] is True


def test_diverged_run_still_gives_metrics() -> None:
    x = first_order(0.5)
    angle = zeros()
    x[6000:] = np.nan
    angle[6000:] = np.nan
    m = compute_metrics(T, x, np.full_like(T, 0.05), angle, zeros())
    assert m["upright"] is False
    assert m["settling_time_s"] is None and m["steady_state_error_m"] is None
    assert m["max_abs_angle_rad"] is None
    assert m["peak_voltage_V"] == 0.0


@pytest.mark.parametrize("bad", [
    dict(time=[0.0]), dict(time=[0.0, 0.0, 1.0]), dict(position=[0.0, 1.0]), dict(angle=np.zeros((3, 1))),
])
def test_malformed_signals_are_rejected(bad: dict) -> None:
    args = dict(time=[0.0, 0.5, 1.0], position=[0.0, 0.0, 0.0], reference=[0.05] * 3, angle=[0.0] * 3,
                voltage=[0.0] * 3)
    args.update(bad)
    with pytest.raises(MetricsError):
        compute_metrics(**args)


# ---------------------------------------------------------------- the residual oscillation (docs/metrics.md)

def test_a_friction_cycle_is_a_limit_cycle_with_its_amplitude_and_frequency() -> None:
    # the cart hunts +-0.8 mm at 0.6 Hz about 0.3 mm beyond the reference, the pendulum +-3 mrad at 0.6 Hz:
    # over the final 5 s (10 s run) the peak-to-peak amplitudes are 1.6 mm and 6 mrad, the frequency 0.6 Hz
    x = first_order(0.3) + 0.0003 + 0.0008 * np.sin(2 * np.pi * 0.6 * T)  # starts at 0.3 mm: step 49.7 mm
    th = 0.003 * np.cos(2 * np.pi * 0.6 * T)
    m = compute_metrics(T, x, np.full_like(T, 0.05), th, zeros())
    assert m["residual_window_s"] == 5.0
    assert m["cart_peak_to_peak_m"] == pytest.approx(0.0016, rel=0.02)
    assert m["angle_peak_to_peak_rad"] == pytest.approx(0.006, rel=0.02)
    assert m["cart_frequency_Hz"] == pytest.approx(0.6, abs=0.03)
    assert m["angle_frequency_Hz"] == pytest.approx(0.6, abs=0.03)
    assert m["cart_mean_error_m"] == pytest.approx(0.0003, abs=0.0001)  # 3 periods in the window: mean of sin ~0
    # the band is +-2 % of 49.7 mm: the cart is outside it where 0.3 mm + 0.8 mm sin > band, i.e. sin > s, for a
    # fraction (pi - 2 asin(s)) / (2 pi) of each period (3 whole periods in the window)
    s = (0.02 * 0.0497 - 0.0003) / 0.0008
    assert m["cart_time_in_band"] == pytest.approx(1 - (math.pi - 2 * math.asin(s)) / (2 * math.pi), abs=0.005)
    assert m["limit_cycle"] is True
    # it leaves the band every period; ending inside, its "settling time" is the last period's entry, which is
    # why the cycle is reported as one
    assert m["settling_time_s"] > T[-1] - 1 / 0.6


def test_a_loop_at_rest_is_not_a_limit_cycle() -> None:
    # a first-order approach, then a one-count dither: 1 count peak to peak is below the 4 counts a cycle needs
    x = first_order(0.3) + 2.275e-5 * (np.sin(2 * np.pi * 3 * T) > 0)
    m = compute_metrics(T, x, np.full_like(T, 0.05), zeros(), zeros())
    assert m["limit_cycle"] is False
    assert m["cart_time_in_band"] == 1.0
    assert m["settling_time_s"] is not None


def test_a_slow_drift_is_not_an_oscillation() -> None:
    # a cart creeping 2 mm over the 5 s window toward the reference swings 2 mm peak to peak, but its
    # spectrum peaks below two periods per window: no cycle
    x = 0.045 + 0.0004 * T
    m = compute_metrics(T, x, np.full_like(T, 0.05), zeros(), zeros())
    assert m["cart_peak_to_peak_m"] == pytest.approx(0.002, rel=1e-3)
    assert m["cart_frequency_Hz"] * m["residual_window_s"] < 2.0
    assert m["limit_cycle"] is False


def test_a_decaying_oscillation_is_not_a_limit_cycle() -> None:
    # 2 mm at 1 Hz decaying with tau = 1 s: the second half of the window swings e^-2.5 as far as the first
    x = 0.05 + 0.002 * np.exp(-(T - 5.0)) * np.sin(2 * np.pi * T)
    m = compute_metrics(T, x, np.full_like(T, 0.05), zeros(), zeros())
    assert m["cart_peak_to_peak_m"] > 4 * 2.275e-5
    assert m["limit_cycle"] is False


def test_the_passive_cart_is_measured_with_a_double_mass_plant() -> None:
    from ipcosim.fmus.metrics import PASSIVE_RESIDUAL_KEYS, task_metrics

    names = ("time", "plant.active_cart_position", "plant.passive_cart_position", "plant.pendulum_angle",
             "setpoint.reference", "controller.voltage")
    rows = np.zeros(T.size, dtype=[(k, "f8") for k in names])
    rows["time"], rows["setpoint.reference"] = T, 0.05
    rows["plant.active_cart_position"] = 0.05
    rows["plant.passive_cart_position"] = 0.05 + 0.001 * np.sin(2 * np.pi * 0.5 * T)
    m = task_metrics(rows)
    assert set(PASSIVE_RESIDUAL_KEYS) <= set(m)
    assert m["passive_cart_peak_to_peak_m"] == pytest.approx(0.002, rel=0.02)
    assert m["passive_cart_frequency_Hz"] == pytest.approx(0.5, abs=0.03)
    assert m["cart_peak_to_peak_m"] == 0.0 and m["limit_cycle"] is True  # the passive cart alone hunts


# ---------------------------------------------------------------- the success criterion (docs/metrics.md, "Success")

def test_the_amplitude_bound_is_the_band_plus_the_cycle_the_spring_and_friction_force() -> None:
    from ipcosim.fmus.metrics import amplitude_bound

    # 2 mm (the +-1 mm band's width) + 2 b2 / K: 2 x 0.1047 N / 142.185 N/m = 1.4727 mm
    assert amplitude_bound(0.1047, 142.185) == pytest.approx(0.002 + 2 * 0.1047 / 142.185, rel=1e-12)
    assert amplitude_bound(0.1047, 142.185) == pytest.approx(3.4727e-3, abs=1e-7)
    assert amplitude_bound() == amplitude_bound(0.0, 142.185) == amplitude_bound(0.1047, 0.0) == 0.002


@pytest.mark.parametrize("metrics,bound,status", [
    ({"upright": False, "cart_mean_error_m": 0.0, "cart_peak_to_peak_m": 0.0}, None, "fell"),
    ({"upright": True, "cart_mean_error_m": -0.0011, "cart_peak_to_peak_m": 0.0}, None, "unsettled"),
    ({"upright": True, "cart_mean_error_m": 0.0009, "cart_peak_to_peak_m": 0.0021}, None, "hunting"),
    ({"upright": True, "cart_mean_error_m": 0.0009, "cart_peak_to_peak_m": 0.0021}, 0.0035, "ok"),
    ({"upright": True, "cart_mean_error_m": None, "cart_peak_to_peak_m": None}, None, "unsettled"),
])
def test_success_status_applies_each_condition_in_turn(metrics, bound, status) -> None:
    from ipcosim.fmus.metrics import success_status

    assert success_status(metrics, bound) == status


def test_a_sweep_judges_a_run_by_its_own_spring_and_friction() -> None:
    from ipcosim.harness.studies.runners import classify_task

    m = {"upright": True, "cart_mean_error_m": 2e-4, "cart_peak_to_peak_m": 3.0e-3, "settling_time_s": None}
    assert classify_task(m, {"plant.b2": 0.1047, "plant.K": 142.185}) == "ok"      # bound 3.47 mm
    assert classify_task(m, {"plant.b2": 0.1047, "plant.K": 300.0}) == "hunting"   # bound 2.70 mm
    assert classify_task(m, {}) == "hunting"                                       # bound 2 mm
