"""Linear loop analysis: the laws' linear models, margins against a hand-checked loop, the
position-only limit against the pendulum equation, and ``ipcosim analyze``."""
from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest

from ipcosim.controllers.catalog import PARAMETER_SETS, make_law
from ipcosim.fmus.params import preset
from ipcosim.harness.analysis.analyze import (
    analyze_loop,
    closed_loop_poles,
    is_stable,
    loop_from,
    position_only_limit,
    scenario_loop,
)
from ipcosim.harness.analysis.linear_law import LinearizationError, LinearLaw, linear_law
from ipcosim.harness.cli import main as cli_main

# the swing-up is nonlinear and the excitation a time signal: neither has a linear model
CASES = [(law, kind, s) for law, per in PARAMETER_SETS.items() if law not in ("SwingUp", "Excitation")
         for kind, sets in per.items() for s in sets]


@pytest.mark.parametrize("law_name,kind,pset", CASES)
def test_linear_law_reproduces_the_law(law_name: str, kind: str, pset: str) -> None:
    """Driven by the same small random measurements, the linear model and the law give the same voltages
    (the LQG without its dither, an input at half the sample rate that the linear model leaves out)."""
    law = make_law(kind, law_name, pset, voltage_limit=1e9, **({"dither_amplitude": 0.0} if law_name == "LQG" else {}))
    if law_name == "AdaptiveHSMC":
        law.ticks = 400_000  # t = 400 s: the schedules have reached their final values
    lin = linear_law(law)
    rng = np.random.default_rng(7)
    ys = rng.normal(size=(400, len(law.measured))) * 1e-10  # tanh(g S) linear to ~1e-9
    ys[0] = 0.0  # both start at rest
    u_law = np.array([law.step(y, 0.0) for y in ys])
    u_lin = lin.simulate(ys)
    assert np.max(np.abs(u_law - u_lin)) <= 1e-7 * np.max(np.abs(u_law))


def test_unknown_law_is_refused() -> None:
    with pytest.raises(LinearizationError, match="object"):
        linear_law(object())  # type: ignore[arg-type]


def _proportional_loop(K: float, T: float):
    """Integrator plant 1/s under u = -K y, sampled: L(z) = K T / (z - 1)."""
    law = LinearLaw(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[-K]]), T, ("y",), ())
    return loop_from(control.ss([[0.0]], [[1.0]], [[1.0]], [[0.0]]), law)


@pytest.mark.parametrize("K,T", [(50.0, 0.01), (300.0, 0.001)])
def test_margins_of_a_hand_checked_loop(K: float, T: float) -> None:
    """L = K T/(z - 1): pole 1 - K T; stable for 0 < K T < 2, so GM = 2/(K T); |L| = 1 at
    2 sin(w T/2) = K T, where the phase is -(pi/2 + w T/2); max |S| = 2/(2 - K T) at z = -1."""
    r = analyze_loop(_proportional_loop(K, T))
    wc = 2 / T * math.asin(K * T / 2)
    pm = math.pi / 2 - wc * T / 2
    assert r["closed_loop_stable"]
    assert r["closed_loop_poles"][0]["z_re"] == pytest.approx(1 - K * T, abs=1e-12)
    assert r["gain_margin"]["upper"] == pytest.approx(2 / (K * T), rel=1e-9)
    assert r["gain_margin"]["checked"]
    assert r["phase_margin_deg"] == pytest.approx(math.degrees(pm), rel=1e-6)
    assert r["delay_margin_s"] == pytest.approx(pm / wc, rel=1e-6)
    assert r["peak_sensitivity"] == pytest.approx(2 / (2 - K * T), rel=1e-6)
    assert r["position_only_limit"]["sensitivity_peak_lower_bound"] == 1.0  # no RHP zero


def _pendulum_zero(name: str) -> float:
    """Positive root of (Mp Lp^2/3) s^2 + Bp s - Mp g Lp/2: where the pendulum equation blocks the cart."""
    p = preset(name)
    J, c = p.Mp * p.Lp ** 2 / 3, p.Mp * p.g * p.Lp / 2
    return (-p.Bp + math.sqrt(p.Bp ** 2 + 4 * J * c)) / (2 * J)


@pytest.mark.parametrize("name,zero,pole", [("thesis-ch3", 6.471, 6.604), ("thesis-appendix-a", 4.752, 4.831)])
def test_position_only_limit(name: str, zero: float, pole: float) -> None:
    """The RHP zero of voltage -> cart position is the pendulum's; the bound is |(z + p)/(z - p)|."""
    law = make_law("single-mass", "PID")
    loop = scenario_loop("single-mass-pid", set={"plant.Lp": preset(name).Lp})[0]
    lim = position_only_limit(loop)
    (z,), (p,) = lim["rhp_zeros_rad_s"], lim["rhp_poles_rad_s"]
    assert z == pytest.approx(_pendulum_zero(name), rel=1e-6)
    assert (z, p) == (pytest.approx(zero, abs=1e-3), pytest.approx(pole, abs=1e-3))
    assert lim["sensitivity_peak_lower_bound"] == pytest.approx((z + p) / (p - z), rel=1e-9)
    assert lim["sampled_sensitivity_peak_lower_bound"] == pytest.approx(lim["sensitivity_peak_lower_bound"], rel=1e-2)
    assert not lim["strongly_stabilizable"] and lim["controller_uses_this_output_only"]
    assert law.measured == ("cart_position", "pendulum_angle")


@pytest.mark.slow
def test_thesis_pid_loop_is_unstable_and_no_pid_stabilizes() -> None:
    r = analyze_loop(scenario_loop("single-mass-pid")[0])
    assert not r["closed_loop_stable"] and r["gain_margin"] is None and r["peak_sensitivity"] is None
    assert r["pid_gain_search"]["stabilizing"] == 0
    assert r["pid_gain_search"]["smallest_spectral_radius"] > 1.0
    bound = r["position_only_limit"]["sensitivity_peak_lower_bound"]
    assert 95 < bound < 100 and f"{bound:.4g}" in r["statement"]


def _with_delay(loop, n: int) -> np.ndarray:
    """Closed-loop poles with n samples of delay at the plant input."""
    delay = control.ss(np.eye(n, k=-1), np.eye(n, 1), np.eye(1, n, n - 1), [[0.0]], loop.T)
    return np.linalg.eigvals(np.asarray(control.feedback(control.series(delay, loop.L), 1, sign=-1).A))


def test_delay_margin_of_the_thesis_lqr_in_samples() -> None:
    """A delay just under the delay margin keeps the sampled loop stable, one just over it does not."""
    loop = scenario_loop("single-mass-lqr")[0]
    r = analyze_loop(loop)
    n = r["delay_margin_samples"]
    assert r["closed_loop_stable"] and 5 < n < 40
    assert is_stable(_with_delay(loop, math.floor(n)))
    assert not is_stable(_with_delay(loop, math.ceil(n) + 1))
    assert r["gain_margin"]["checked"]
    assert not r["position_only_limit"]["controller_uses_this_output_only"]
    assert np.allclose(sorted(abs(closed_loop_poles(loop))), sorted(p["z_abs"] for p in r["closed_loop_poles"]))


@pytest.mark.slow
def test_cli_json_and_figures(tmp_path, capsys) -> None:
    assert cli_main(["analyze", "double-mass-lqr", "--json", "--out", str(tmp_path)]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["law"] == "LQR" and r["kind"] == "double-mass" and r["closed_loop_stable"]
    for name in ("bode.png", "nyquist.png", "margins.png", "analysis.json"):
        assert (tmp_path / name).stat().st_size > 1000
    assert set(r["sensor_margins"]) == {"active_cart_position", "passive_cart_position", "pendulum_angle"}
    assert 0 < r["disk_margin"]["gain_lower"] < 1 < r["disk_margin"]["gain_upper"]
    assert json.loads((tmp_path / "analysis.json").read_text())["delay_margin_s"] == r["delay_margin_s"]


@pytest.mark.parametrize("argv,needle,status", [
    (["analyze", "no-such-scenario"], "unknown scenario 'no-such-scenario'", 2),  # usage: a name that is not there
    (["analyze", "single-mass-lqr", "--set", "plant.Mp=-1"], "parameter Mp = -1.0 kg must be > 0", 1),  # the model's
    (["analyze", "single-mass-lqr", "--set", "setpoint.amplitude=1"], "--set setpoint.amplitude", 2),
])
def test_cli_errors_are_one_line(argv, needle, status, capsys, tmp_path) -> None:
    assert cli_main(argv + ["--out", str(tmp_path)]) == status
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1
