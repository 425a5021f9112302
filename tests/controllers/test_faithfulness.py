"""The thesis's single-mass HSMC constants are a force model (driven through the motor), and the
single-mass adaptive HSMC uses every schedule of the thesis's App. A.6 listing."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ipcosim.controllers.catalog import make_law, set_values
from ipcosim.controllers.laws.hsmc import HSMC
from ipcosim.fmus.params import preset


def _drive(law, ys):
    return np.array([law.step(y, 0.0) for y in ys])


def test_single_mass_thesis_hsmc_output_is_a_force_applied_through_the_motor() -> None:
    law = make_law("single-mass", "HSMC", "thesis", voltage_limit=1e9)
    raw = HSMC("single-mass", law.gains, law.models, law.sample_period, 1e9)  # same law, output in newtons
    p = preset("thesis-ch3")
    Kf, Ke = p.force_per_amp / p.Ra, p.emf_per_velocity
    assert Kf == pytest.approx(1.7258, rel=1e-4) and Ke == pytest.approx(4.4871, rel=1e-4)
    ys = np.cumsum(np.random.default_rng(3).normal(size=(300, 2)) * 1e-4, axis=0)
    volts, forces = [], []
    for y in ys:
        volts.append(law.step(y, 0.02))
        forces.append(raw.step(y, 0.02) / Kf + Ke * law._d[1].value)  # _d[1]: the cart's velocity estimate
    assert np.allclose(volts, forces, rtol=1e-9, atol=1e-12)


def test_tuned_and_double_mass_hsmc_stay_voltage_models() -> None:
    assert make_law("single-mass", "HSMC", "tuned").force_gain == 1.0
    law = make_law("double-mass", "HSMC", "thesis")
    assert (law.force_gain, law.emf_gain) == (1.0, 0.0)


def test_single_mass_adaptive_thesis_set_carries_the_first_layer_schedules() -> None:
    v = set_values("single-mass", "AdaptiveHSMC", "thesis")
    assert (v["k1"], v["k1_delta"], v["k1_rate"]) == (0.0, 14.0, 0.1)          # deltaKP = 14, KP1 = 0.1
    assert (v["KI1"], v["KI1_delta"], v["KI1_rate"]) == (320.0, -320.0, 4.0)   # KI = 320, deltaKI = 1, KI1 = 4
    law = make_law("single-mass", "AdaptiveHSMC", "thesis", voltage_limit=1e9)
    plain = make_law("single-mass", "AdaptiveHSMC", "thesis", voltage_limit=1e9)
    plain.schedules = replace(plain.schedules, k1=None, KI1=None)
    ys = np.cumsum(np.random.default_rng(5).normal(size=(200, 2)) * 1e-4, axis=0)
    u, u_plain = _drive(law, ys), _drive(plain, ys)
    assert not np.allclose(u, u_plain)
    assert law.integral1 != 0.0 and plain.integral1 == 0.0


def test_first_layer_schedules_default_to_off() -> None:
    law = make_law("double-mass", "AdaptiveHSMC", "thesis")
    assert law.schedules.k1 is None and law.schedules.KI1 is None
