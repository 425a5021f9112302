"""The FMUs enforce the FMI 2.0 co-simulation call order (``ipcosim.fmus.fmi``, "FMI 2.0 call
order"), driven through fmpy's low-level API: a refused fmi2DoStep is logged with status
fmi2Error naming the call and the state, returns fmi2Discard and changes nothing; a refused set
call is fmi2Fatal with such a message (pythonfmu 0.7.0 offers no fmi2Error return)."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from fmi_helpers import instantiate
from fmpy.fmi1 import FMICallException

from ipcosim.fmus.pybuild import build_all

pytestmark = pytest.mark.integration
DATA = Path(__file__).resolve().parents[1] / "data"
FMI_DISCARD, FMI_ERROR, FMI_FATAL = 2, 3, 4
H = 0.1


@pytest.fixture(scope="module")
def fault_fmu(tmp_path_factory) -> Path:
    (result,) = build_all(tmp_path_factory.mktemp("call-order-fmu"), scripts=[DATA / "fmu_corpus_fault.py"])
    return result.fmu


@pytest.fixture(scope="module")
def unzip(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("call-order-unzipped")


def _instance(fmu: Path, unzip: Path, phase: str):
    """An instance brought to ``phase``: instantiated, initialization, stepping (one step done) or terminated."""
    f = instantiate(fmu, unzip)
    f.slave.setupExperiment(startTime=0.0)
    if phase == "instantiated":
        return f
    f.slave.enterInitializationMode()
    f.set(u=2.0)
    if phase == "initialization":
        return f
    f.slave.exitInitializationMode()
    f.slave.doStep(0.0, H)
    if phase == "terminated":
        f.slave.terminate()
    return f


def _refused_step(f, t: float, h: float) -> str:
    before = f.get("y")
    with pytest.raises(FMICallException) as info:
        f.slave.doStep(t, h)
    assert info.value.status == FMI_DISCARD
    errors = [m[2] for m in f.messages if m[0] == FMI_ERROR]
    assert len(errors) == 1, f.messages
    call = f"fmi2DoStep(currentCommunicationPoint = {t!r}, communicationStepSize = {h!r})"
    assert errors[0].startswith(f"{call} in state")
    assert f.get("y") == before  # nothing changed
    return errors[0]


STEP_CASES = {
    # case: (phase, t, h, expected in the message)
    "before-initialization": ("instantiated", 0.0, H, "in state instantiated: allowed only after "
                              "fmi2ExitInitializationMode and before fmi2Terminate"),
    "in-initialization-mode": ("initialization", 0.0, H, "in state initialization: allowed only after"),
    "after-terminate": ("terminated", H, H, "in state terminated: allowed only after"),
    "going-back": ("stepping", 0.05, H, "does not continue the last step, which ended at t = 0.1"),
    "repeating-a-done-step": ("stepping", 0.0, H, "does not continue the last step, which ended at t = 0.1"),
    "skipping-ahead": ("stepping", 0.3, H, "does not continue the last step, which ended at t = 0.1"),
    "negative-step": ("stepping", H, -H, "the step size must be a positive finite number"),
    "zero-step": ("stepping", H, 0.0, "the step size must be a positive finite number"),
    "nan-step": ("stepping", H, math.nan, "the step size must be a positive finite number"),
    "infinite-step": ("stepping", H, math.inf, "the step size must be a positive finite number"),
    "nan-communication-point": ("stepping", math.nan, H, "does not continue the last step"),
}


@pytest.mark.parametrize("case", sorted(STEP_CASES))
def test_out_of_order_step_is_refused_and_logged(case, fault_fmu, unzip):
    phase, t, h, expected = STEP_CASES[case]
    f = _instance(fault_fmu, unzip, phase)
    assert expected in _refused_step(f, t, h)
    if phase == "stepping":  # the instance stays usable: the right next step works
        f.set(u=3.0)
        f.slave.doStep(H, H)
        assert f.get("y") == [3.0]
    f.slave.freeInstance()


def test_a_discarded_step_may_be_retried_from_the_same_point(fault_fmu, unzip):
    f = _instance(fault_fmu, unzip, "instantiated")
    f.slave.enterInitializationMode()
    f.slave.setInteger([f.vr["fault"]], [3])
    f.set(fail_time=0.05)
    f.slave.exitInitializationMode()
    with pytest.raises(FMICallException):
        f.slave.doStep(0.0, H)  # the FMU's own discard (StepFailure)
    with pytest.raises(FMICallException):
        f.slave.doStep(0.0, H)  # retried from the same point: refused by the model again, not by the call order
    assert all("does not continue" not in m[2] for m in f.messages)
    f.slave.freeInstance()


def test_fixed_parameter_after_initialization_is_refused(fault_fmu, unzip):
    f = _instance(fault_fmu, unzip, "stepping")
    with pytest.raises(FMICallException) as info:
        f.set(fail_time=5.0)
    assert info.value.status == FMI_FATAL
    assert any(m[2].endswith("fmi2SetReal in state stepping: parameter fail_time is fixed: it cannot be set to 5.0 "
                             "after initialization") for m in f.messages), f.messages
    f.slave.freeInstance()


def test_set_after_terminate_is_refused(fault_fmu, unzip):
    f = _instance(fault_fmu, unzip, "terminated")
    with pytest.raises(FMICallException) as info:
        f.set(u=1.0)
    assert info.value.status == FMI_FATAL
    assert any(m[2].endswith("fmi2SetReal in state terminated: no value can be set after fmi2Terminate")
               for m in f.messages), f.messages
    f.slave.freeInstance()


def test_entering_initialization_twice_is_refused(fault_fmu, unzip):
    f = _instance(fault_fmu, unzip, "initialization")
    with pytest.raises(FMICallException) as info:
        f.slave.enterInitializationMode()
    assert info.value.status == FMI_FATAL
    assert any("fmi2EnterInitializationMode in state initialization: allowed only once" in m[2] for m in f.messages)
    f.slave.freeInstance()


def test_reset_returns_to_the_instantiated_state(fault_fmu, unzip):
    f = _instance(fault_fmu, unzip, "stepping")
    f.slave.reset()
    assert "in state instantiated" in _refused_step(f, H, H)
    f.messages.clear()
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    f.set(u=4.0)
    f.slave.exitInitializationMode()
    f.slave.doStep(0.0, H)
    f.slave.doStep(H, H)
    assert f.get("y") == [4.0]
    f.slave.freeInstance()
