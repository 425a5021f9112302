"""The ``ipcosim`` pytest plugin as a user meets it: a user's test file run by pytest (pytester,
in a subprocess so that FMUs load in a fresh interpreter as in a user's CI)."""
from __future__ import annotations

import re

import pytest

pytest_plugins = ["pytester"]

USER_TESTS = '''
import pytest
import ipcosim


def test_lqr_balances(cosim):
    result = cosim.run("single-mass-lqr", stop_time=1.0)
    ipcosim.assert_upright(result)


def test_lqr_settles_fast(cosim):
    result = cosim.run("single-mass-lqr", stop_time=1.0, set={"plant.Mp": "1.1*nominal"})
    ipcosim.assert_settles(result, within_s=0.5)


def test_missing_controller(cosim):
    cosim.run("single-mass-lqr", swap={"controller": "build/NoSuchController.fmu"}, stop_time=1.0)


@pytest.mark.ipcosim_hil
def test_on_the_rig(cosim, ipcosim_rig):
    assert ipcosim_rig.startswith("q4:")
'''


@pytest.mark.integration
@pytest.mark.slow
def test_user_tests_pass_fail_and_skip_with_readable_messages(pytester):
    pytester.makepyfile(test_user=USER_TESTS)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(passed=1, failed=2, skipped=1)
    out = result.stdout.str()
    # the failing assertion: which run, what was expected, what happened, where the files are
    assert re.search(r"CheckFailed: single-mass-lqr \[plant.Mp=0.2\d+\]: the cart did not settle within 0.5 s: "
                     r"it is outside the \+-2 % band \(0.049..0.051 m\) at the end of the run", out), out
    assert re.search(r"ipcosim runs \(results.csv, metrics.json\)", out)
    assert re.search(r"run-01-single-mass-lqr: upright=True, settling_time_s=None", out)
    # the missing FMU: the command line's one line
    assert "SwapFileNotFoundError: --swap controller=build/NoSuchController.fmu: FMU file does not exist" in out
    # the rig test: skipped with the reason
    assert re.search(r"SKIPPED \[1\] test_user.py:\d+: needs a rig: run pytest with --ipcosim-rig URI", out)


def test_hil_test_runs_when_a_rig_is_given(pytester):
    pytester.makepyfile(test_rig='''
import pytest

@pytest.mark.ipcosim_hil
def test_on_the_rig(ipcosim_rig):
    assert ipcosim_rig == "q4:0@tcpip://127.0.0.1:1"
''')
    pytester.runpytest_subprocess("-p", "no:cacheprovider").assert_outcomes(skipped=1)
    pytester.runpytest_subprocess("-p", "no:cacheprovider", "--ipcosim-rig", "q4:0@tcpip://127.0.0.1:1") \
        .assert_outcomes(passed=1)


def test_plugin_is_inert_in_a_session_that_does_not_use_it(pytester):
    pytester.makepyfile(test_plain="import sys\n\n\ndef test_plain():\n"
                                   "    assert 'ipcosim.harness.api.engine' not in sys.modules\n")
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--strict-markers")
    result.assert_outcomes(passed=1)


@pytest.mark.integration
def test_assert_succeeds_is_the_sweeps_criterion_and_says_why_in_millimetres() -> None:
    import ipcosim
    from ipcosim.fmus.metrics import success_status

    done = ipcosim.run("single-mass-lqr", stop_time=6.0)
    # no friction, exact readings: a linear loop, no predicted cycle, the bound is the 1 mm margin alone
    assert done.metadata["amplitude_bound_m"] == pytest.approx(0.001)
    assert done.metrics["amplitude_bound_m"] == done.metadata["amplitude_bound_m"]
    assert done.metrics["amplitude_bound_from"] == "prediction"
    assert success_status(done.metrics, done.metadata["amplitude_bound_m"]) == "ok"
    ipcosim.assert_succeeds(done)
    early = ipcosim.run("single-mass-lqr", stop_time=1.0)  # the final half second is mid-step: far from 50 mm
    with pytest.raises(ipcosim.CheckFailed, match=r"mean error -?\d+(\.\d+)? mm over the final 0.5 s exceeds 1 mm"):
        ipcosim.assert_succeeds(early)
