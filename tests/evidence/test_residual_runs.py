"""The per-run diagnosis of the residual-cycle prediction, on rows whose answer is known by construction."""
from __future__ import annotations

import numpy as np
import pytest

from evidence.residual_runs import diagnosis, main, window_spread


def _rows(n: int = 300, seed: int = 3) -> list[dict]:
    """Runs whose simulated peak-to-peak is 1.25 times the predicted one plus 0.5 mm per 10 N/m of spring
    below 150 N/m: a prediction blind to the spring, and low."""
    rng = np.random.default_rng(seed)
    K = rng.uniform(114, 171, n)
    pred = rng.uniform(2.5e-3, 4.5e-3, n)
    sim = 1.25 * pred + 0.5e-4 * np.maximum(150.0 - K, 0.0)
    return [{"upright": True, "plant.K": float(k), "plant.Mp": 0.127, "predicted_cart_peak_to_peak_m": float(p),
             "cart_peak_to_peak_m": float(s), "cart_frequency_Hz": 0.5 + 0.002 * float(k)}
            for k, p, s in zip(K, pred, sim)] + [{"upright": False, "predicted_cart_peak_to_peak_m": None}]


def test_the_error_and_its_spread_are_the_constructed_ones() -> None:
    d = diagnosis(_rows())
    assert d["runs"] == 301 and d["predicted"] == 300                 # the fallen run is left out
    assert d["ratio"]["p10"] >= 1.25 - 1e-12                           # never below the constructed factor
    shortfall = [0.25 * r["predicted_cart_peak_to_peak_m"] + 0.5e-4 * max(150.0 - r["plant.K"], 0.0)
                 for r in _rows()[:-1]]
    assert d["shortfall_mm"]["median"] == pytest.approx(np.median(shortfall) * 1e3)
    assert d["shortfall_mm"]["within_margin"] == pytest.approx(np.mean(np.array(shortfall) <= 1e-3))


def test_the_softest_springs_are_missed_most_and_the_constant_factor_is_not_drawn() -> None:
    d = diagnosis(_rows())
    thirds = [t["median_error"] for t in d["spring_thirds"]]
    assert thirds[0] < thirds[1] < thirds[2] == pytest.approx(-0.2)    # 1/1.25 - 1: no spring term above 150 N/m
    assert set(d["factors"]) == {"plant.K"}                             # Mp is the same in every run
    assert d["factors"]["plant.K"]["simulated"] < 0 and d["frequency_Hz"]["simulated_with_K"] == pytest.approx(1.0)


def test_window_spread_of_two_incommensurate_sinusoids_reaches_their_sum() -> None:
    """A 1 mm and a 0.5 mm amplitude at 0.55 and 1.55 Hz: every 5 s window lies between the larger swing's
    peak-to-peak and the sum of both; over a long run some window comes near the sum (3 mm)."""
    t = np.arange(0.0, 200.0, 1e-3)
    x = 1e-3 * np.sin(2 * np.pi * 0.55 * t) + 0.5e-3 * np.sin(2 * np.pi * 1.55 * t + 1.0)
    pp = window_spread(t, x, 5.0)
    assert len(pp) == int((200.0 - 1e-3 - 15.0) / 0.5) + 1
    assert np.all(pp <= 3e-3 + 1e-12) and pp.min() >= 2e-3 and pp.max() > 2.95e-3


def test_bad_seeds_are_one_clear_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--seeds", "zero"]) == 2
    assert capsys.readouterr().err.strip() == "--seeds 'zero': give integers separated by commas"


def test_less_the_windup_takes_each_runs_own_2_b2_over_K_off() -> None:
    rows = [{**r, "plant.b2": 0.1} for r in _rows()[:-1]]
    full, less = diagnosis(rows), diagnosis(rows, less_windup=True)
    sim = np.array([r["cart_peak_to_peak_m"] for r in rows])
    pred = np.array([r["predicted_cart_peak_to_peak_m"] - 0.2 / r["plant.K"] for r in rows])
    assert less["ratio"]["median"] == pytest.approx(np.median(sim / pred))
    assert less["ratio"]["median"] > full["ratio"]["median"]
