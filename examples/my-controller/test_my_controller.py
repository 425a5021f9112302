"""My controller, kept honest in CI: it balances both plants and settles, it survives +-20 %
pendulum mass, and its trajectory stays on the recorded baseline.

Uses only ipcosim's public API and its pytest plugin (fixture ``cosim``, marker ``ipcosim_hil``).
"""
from __future__ import annotations

from pathlib import Path

import pytest

import ipcosim

HERE = Path(__file__).resolve().parent
SCRIPTS = {"single-mass": "my_controller_single_mass.py", "double-mass": "my_controller_double_mass.py"}
BASELINE = HERE / "baselines" / "single-mass.csv"

# The scenarios' thesis parameter sets configure their own controllers; mine ignores those values.
pytestmark = pytest.mark.filterwarnings("ignore:.*the FMU does not have:UserWarning")


@pytest.fixture(scope="session")
def my_fmus() -> dict[str, Path]:
    """My two FMUs, designed and built once (rebuilt only when a source or the design changed)."""
    from design import write_gains

    gains = write_gains()
    return {plant: ipcosim.build_fmu(HERE / script, files=[gains[plant], HERE / "my_law.py"])
            for plant, script in SCRIPTS.items()}


@pytest.mark.parametrize("plant", SCRIPTS)
def test_balances_and_settles(cosim, my_fmus, plant):
    result = cosim.run(f"{plant}-lqr", swap={"controller": my_fmus[plant]}, stop_time=4.0)
    ipcosim.assert_upright(result)
    ipcosim.assert_settles(result, within_s=2.0)
    ipcosim.assert_steady_state(result, error_m=0.5e-3)


@pytest.mark.parametrize("case", ipcosim.cases(plants=SCRIPTS, vary={"plant.Mp": "[0.8, 1.2]*nominal"}))
def test_survives_pendulum_mass_spread(cosim, my_fmus, case):
    result = cosim.run(case.scenario("lqr"), swap={"controller": my_fmus[case.plant]}, set=case.set, stop_time=4.0)
    ipcosim.assert_upright(result)
    ipcosim.assert_settles(result, within_s=2.5)


def test_stays_on_baseline(cosim, my_fmus):
    """The baseline was recorded with
    ``ipcosim run single-mass-lqr --swap controller=build/MyControllerSingleMass.fmu --stop-time 3
    --record plant.cart_position,plant.pendulum_angle,controller.voltage --out out/single-mass
    --save-baseline out/single-mass-baseline.csv`` and copied to ``baselines/single-mass.csv`` (README)."""
    result = cosim.run("single-mass-lqr", swap={"controller": my_fmus["single-mass"]}, stop_time=3.0)
    ipcosim.assert_close_to(result, BASELINE, tol={"plant.cart_position": 0.5e-3, "plant.pendulum_angle": 2e-3,
                                                   "controller.voltage": 0.2})


@pytest.mark.ipcosim_hil
def test_balances_the_rig(cosim, my_fmus, ipcosim_rig):
    """On a rig (``pytest --ipcosim-rig q4:0@tcpip://HOST:PORT``); skipped without one."""
    result = cosim.run("single-mass-lqr", swap={"controller": my_fmus["single-mass"], "plant": "hil"},
                       set={"plant.card_uri": ipcosim_rig}, stop_time=4.0)
    ipcosim.assert_upright(result)
