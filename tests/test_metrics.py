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
                                "peak_voltage_V", "rms_voltage_V", "upright"}


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
