"""Disk margin at the plant input and the margins of every sensor (loop at a time) of ``ipcosim analyze``: the disk
margin against its definition computed here, the sensor gain ranges against the values an independent
analysis found and against the nonlinear loop just inside and just outside each range."""
from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from ipcosim.controllers.catalog import make_law
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.params import preset
from ipcosim.fmus.physics import MEASURED
from ipcosim.harness.analysis.analyze import (
    closed_loop_poles,
    disk_margin,
    frequency_grid,
    is_stable,
    loop_response,
    scenario_loop,
    sensor_margins,
)


@pytest.fixture(scope="module")
def double_mass():
    """The thesis double-mass LQR's loop and its margins, and the double-mass LQG's (both shipped sets), as
    ``analyze_loop`` reports them."""
    out = {}
    for law, scenario, pset in (("lqr", "double-mass-lqr", "thesis"), ("lqg", "double-mass-lqg", "tuned")):
        loop = scenario_loop(scenario, pset)[0]
        w = frequency_grid(loop.T)
        out[law] = (loop, {"disk_margin": disk_margin(loop, w, loop_response(loop, w)),
                           "sensor_margins": sensor_margins(loop, MEASURED["double-mass"], w)})
    return out


def _loop_gain(loop, w: float) -> complex:
    """``L(e^{jwT}) = -C(z) P(z)`` from the sampled plant's and the controller's matrices."""
    z = cmath.exp(1j * w * loop.T)
    pd, c = loop.plant, loop.controller
    Ap, Bp, Cp, Dp = (np.asarray(m) for m in (pd.A, pd.B, pd.C, pd.D))
    P = Cp @ np.linalg.solve(z * np.eye(len(Ap)) - Ap, Bp) + Dp                 # outputs x 1
    C = c.C @ np.linalg.solve(z * np.eye(len(c.A)) - c.A, c.B) + c.D            # 1 x outputs
    return complex(-(C @ P)[0, 0])


def _balanced_disk_margin(loop) -> tuple[float, float]:
    """``alpha = 1 / max_w |(S - T)/2|`` with ``S - T = (1 - L)/(1 + L)`` (the balanced disk, Seiler et al. 2020),
    on a dense grid finished by a bounded scalar search; returns alpha and its frequency."""
    nyquist = math.pi / loop.T
    w = np.logspace(-3, math.log10(nyquist), 4000)

    def dev(v: float) -> float:
        L = _loop_gain(loop, v)
        return abs((1 - L) / (1 + L)) / 2
    values = np.array([dev(v) for v in w])
    i = int(np.argmax(values))
    best = minimize_scalar(lambda v: -dev(v), bounds=(w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]),
                           method="bounded", options={"xatol": 1e-9})
    return 1.0 / max(-best.fun, values[i]), float(best.x)


@pytest.mark.parametrize("law", ["lqr", "lqg"])
def test_disk_margin_is_its_definition(double_mass, law) -> None:
    loop, r = double_mass[law]
    alpha, w = _balanced_disk_margin(loop)
    dm = r["disk_margin"]
    assert dm["alpha"] == pytest.approx(alpha, rel=5e-4)
    assert dm["frequency_rad_s"] == pytest.approx(w, rel=1e-2)
    # the balanced disk's real gains and phase: (1 +- alpha/2)/(1 -+ alpha/2) and 2 atan(alpha/2)
    assert dm["gain_upper"] == pytest.approx((1 + alpha / 2) / (1 - alpha / 2), rel=1e-3)
    assert dm["gain_lower"] == pytest.approx((1 - alpha / 2) / (1 + alpha / 2), rel=1e-3)
    assert dm["phase_deg"] == pytest.approx(math.degrees(2 * math.atan(alpha / 2)), rel=1e-3)
    # a disk margin's gains are simultaneous with any phase: the real gains of its range keep the loop stable
    assert is_stable(closed_loop_poles(loop, dm["gain_upper"] * 0.999))
    assert is_stable(closed_loop_poles(loop, dm["gain_lower"] * 1.001))


def test_the_thesis_double_mass_lqr_margins(double_mass) -> None:
    """The values an independent analysis found: +-10.7 deg of disk margin, a gain on the active-cart reading of
    0.970 to 1.178 and on the passive-cart reading of 0.862 to 1.031; the LQG's passive cart 0.874 to 1.197."""
    r = double_mass["lqr"][1]
    assert round(r["disk_margin"]["phase_deg"], 1) == 10.7
    sensors = r["sensor_margins"]
    assert (round(sensors["active_cart_position"]["gain_lower"], 3),
            round(sensors["active_cart_position"]["gain_upper"], 3)) == (0.970, 1.178)
    assert (round(sensors["passive_cart_position"]["gain_lower"], 3),
            round(sensors["passive_cart_position"]["gain_upper"], 3)) == (0.862, 1.031)
    passive = double_mass["lqg"][1]["sensor_margins"]["passive_cart_position"]
    assert (round(passive["gain_lower"], 3), round(passive["gain_upper"], 3)) == (0.874, 1.197)
    assert all(m["gain_checked"] and m["delay_margin_s"] > 0 for m in sensors.values())


class _ScaledReading:
    """The law reading its ``j``-th measurement multiplied by ``k`` (a sensor's gain error)."""

    def __init__(self, law, j: int, k: float) -> None:
        self.law, self.j, self.k, self.sample_period = law, j, k, law.sample_period

    def reset(self) -> None:
        self.law.reset()

    def step(self, y, reference):
        y = list(y)
        y[self.j] *= self.k
        return self.law.step(y, reference)


def _growth(j: int, k: float) -> float:
    """How much the nonlinear loop's motion grows from [2, 6] s to [8, 12] s, the law reading sensor j times k,
    the pendulum started 0.02 rad off upright (frictionless plant, exact readings)."""
    law = _ScaledReading(make_law("double-mass", "LQR", "thesis"), j, k)
    run = run_loop(law, preset("thesis-ch4"), stop_time=12.0, reference=0.0, x0=[0, 0, 0, 0, 0.02, 0, 0])
    size = np.abs(np.column_stack([run.signal("active_cart_position") / 0.01, run.signal("pendulum_angle") / 0.01]))
    t = run.time
    return float(size[t >= 8].max() / size[(t >= 2) & (t <= 6)].max())


@pytest.mark.parametrize("sensor, j, end", [("active_cart_position", 0, "gain_lower"),
                                            ("active_cart_position", 0, "gain_upper"),
                                            ("passive_cart_position", 1, "gain_lower"),
                                            ("passive_cart_position", 1, "gain_upper")])
def test_sensor_gain_limits_hold_in_the_nonlinear_loop(double_mass, sensor, j, end) -> None:
    """2 % inside a sensor's gain limit the nonlinear loop's motion dies out, 2 % outside it grows."""
    limit = double_mass["lqr"][1]["sensor_margins"][sensor][end]
    inside, outside = (limit * 1.02, limit * 0.98) if end == "gain_lower" else (limit * 0.98, limit * 1.02)
    assert _growth(j, inside) < 0.9
    assert _growth(j, outside) > 1.1


def test_without_matplotlib_analyze_keeps_its_margins(tmp_path, monkeypatch, capsys) -> None:
    """No plotting library: the figures are skipped with one line, every number (the margins too) is reported."""
    import importlib.util

    from ipcosim.harness.cli import main as cli_main

    real = importlib.util.find_spec
    from ipcosim.harness.support import extras

    monkeypatch.setattr(extras, "_said", set())  # each skip is said once a process: once in this test
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a))
    assert cli_main(["analyze", "single-mass-lqr", "--out", str(tmp_path)]) == 0
    text, err = capsys.readouterr()
    assert sum("skipped: matplotlib is not installed" in line for line in err.splitlines()) == 1
    assert "disk margin (balanced)" in text and "cart_position: gain x" in text
    assert (tmp_path / "analysis.json").is_file() and not (tmp_path / "margins.png").exists()
