"""The clocked controller FMUs (FMI 3.0 input clock = the law's sample period) against the
standard's schema and against the unclocked variant, run by the master."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ipcosim
from ipcosim.harness.master.clocks import clocking
from ipcosim.harness.native.clocked import build_clocked, clocked_names

#: The scenario that runs each law (its controller component is ``controller``).
SCENARIOS = {"PID": "pid", "CascadePID": "cascade-pid", "LQR": "lqr", "HSMC": "hsmc",
             "AdaptiveHSMC": "adaptive-hsmc", "LQG": "lqg", "SwingUp": "swing-up"}


@pytest.fixture(scope="module")
def clocked_fmus(native_fmus: tuple[Path, Path]) -> Path:
    out = native_fmus[1].parent / "fmus-clocked"
    build_clocked(native_fmus[0], out)
    return out


def _scenario(model: str) -> str:
    plant = "single-mass" if model.endswith("SingleMass") else "double-mass"
    return f"{plant}-{SCENARIOS[model.removesuffix('SingleMass').removesuffix('DoubleMass')]}"


def test_clocked_fmus_validate_and_declare_their_clock(clocked_fmus: Path) -> None:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    fmus = sorted(clocked_fmus.glob("*Clocked.fmu"))
    assert len(fmus) == len(clocked_names())
    for fmu in fmus:
        assert validate_fmu(str(fmu)) == [], fmu.name
        md = read_model_description(str(fmu), validate=True)
        assert md.coSimulation.hasEventMode
        (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
        period = next(v for v in md.modelVariables if v.name == "sample_period")
        assert clock.causality == "input" and clock.intervalVariability == "constant"
        ours = clocking(fmu, "3.0", fmu.name)  # the attributes as written (fmpy does not read them all)
        (tick,) = ours.clocks
        assert float(tick.interval) == float(period.start) and tick.shift == 0
        for v in md.modelVariables:
            if v.causality in ("input", "output"):
                assert ours.clocked[v.valueReference] == (tick.vr,), (fmu.name, v.name)


@pytest.mark.parametrize("model", clocked_names())
def test_clocked_trajectory_equals_the_unclocked_one(model: str, native_fmus: tuple[Path, Path],
                                                     native_fmus3: Path, clocked_fmus: Path) -> None:
    scenario = _scenario(model)
    plain = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                        swap={"controller": str(native_fmus3 / f"{model}.fmu")})
    clocked = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.5,
                          swap={"controller": str(clocked_fmus / f"{model}Clocked.fmu")})
    assert plain.error is None and clocked.error is None, (plain.error, clocked.error)
    assert list(plain.data.dtype.names) == list(clocked.data.dtype.names)
    for name in plain.data.dtype.names:  # bit for bit
        assert np.array_equal(plain.data[name], clocked.data[name], equal_nan=True), (model, name)
    assert np.ptp(clocked.data["controller.voltage"]) > 0  # the law acted


def test_a_host_without_event_mode_is_told_to_take_the_unclocked_variant(clocked_fmus: Path) -> None:
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    fmu = clocked_fmus / "LQRSingleMassClocked.fmu"
    md = read_model_description(str(fmu))
    messages = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception):  # noqa: B017 -- fmpy raises a bare Exception on a NULL instance
        slave.instantiate(eventModeUsed=False, logMessage=lambda env, status, cat, msg: messages.append(msg))
    assert any(b"take the unclocked variant" in m for m in messages)


def test_a_step_that_misses_the_clock_is_refused_naming_it(native_fmus: tuple[Path, Path], clocked_fmus: Path) -> None:
    from ipcosim.harness.master.algorithm import StepSizeError
    from ipcosim.harness.master.clocks import ClockError

    with pytest.raises((StepSizeError, ClockError), match="0.0003 s.*choose --step"):
        ipcosim.run("single-mass-lqr", fmus="native", fmu_dirs=[native_fmus[1]], stop_time=0.1, step=0.0003,
                    swap={"controller": str(clocked_fmus / "LQRSingleMassClocked.fmu")})
