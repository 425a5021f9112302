"""The fitted passive-cart Coulomb friction reproduces the thesis's 5.575 mm (and is needed for it)."""
from __future__ import annotations

import pytest

from evidence.friction import THESIS_DOUBLE_MASS_HSMC_ERROR, hsmc_error
from ipcosim.fmus.params import PRESETS, preset


def test_fitted_friction_reproduces_the_thesis_error() -> None:
    b2 = preset("thesis-ch4-friction").b2
    assert b2 > 0 and "FITTED" in PRESETS["thesis-ch4-friction"][2]
    assert hsmc_error(b2) == pytest.approx(THESIS_DOUBLE_MASS_HSMC_ERROR, abs=0.1e-3)


def test_without_coulomb_friction_the_error_vanishes() -> None:
    """The 5.6 mm is friction's: on the frictionless plant the same law ends within 0.01 mm."""
    assert hsmc_error(0.0) < 1e-5
