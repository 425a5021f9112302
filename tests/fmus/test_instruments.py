"""Bench instruments of the plant model (encoders, seeded noise, end stops), pure and through the FMU."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fmi_helpers import instantiate
from fmpy.fmi1 import FMICallException

from ipcosim.fmus.instruments import (
    CART_M_PER_COUNT,
    DAC_V_PER_CODE,
    END_STOP_M,
    LAB_SAMPLE_PERIOD,
    InstrumentError,
    Instruments,
    Readout,
    quantize,
    realism,
)
from ipcosim.fmus.params import preset
from ipcosim.fmus.plant import InstrumentedPlant, Plant

H = 1e-3


@pytest.mark.parametrize("x", [0.0, 1.1e-5, 1.2e-5, -3.4e-5, 0.05, -0.2871234])
def test_quantization_is_the_nearest_whole_count(x: float) -> None:
    y = quantize(x, CART_M_PER_COUNT)
    counts = y / CART_M_PER_COUNT
    assert counts == pytest.approx(round(counts), abs=1e-9)
    assert abs(y - x) <= CART_M_PER_COUNT / 2 + 1e-15
    assert quantize(x, 0.0) == x


def test_quantization_step_is_one_count() -> None:
    edge = 0.5 * CART_M_PER_COUNT
    assert quantize(edge + 1e-12, CART_M_PER_COUNT) - quantize(edge - 1e-12, CART_M_PER_COUNT) == \
        pytest.approx(CART_M_PER_COUNT, rel=1e-9)


def test_noise_is_seeded_and_has_its_standard_deviation() -> None:
    def draws(seed: int) -> np.ndarray:
        r = Readout(Instruments(noise_counts=2.0, noise_seed=seed), [0.0])
        return np.array([r.read([0.0])[0] for _ in range(4000)])

    a, b, c = draws(1), draws(1), draws(2)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.std(a) == pytest.approx(2.0, rel=0.05)


def test_bad_option_names_it() -> None:
    with pytest.raises(InstrumentError, match="end_stop = -1"):
        Instruments(end_stop=-1.0)


def test_ideal_instrumented_plant_is_the_plant() -> None:
    p = preset("thesis-ch3")
    a, b = Plant(p, [0, 0, 0.01, 0, 0]), InstrumentedPlant(p, [0, 0, 0.01, 0, 0])
    for k in range(500):
        a.do_step(k * H, H, 2.0)
        b.do_step(k * H, H, 2.0)
    assert a.state == b.state and b.readings == a.measured()


@pytest.mark.parametrize("kind,preset_name", [("single-mass", "thesis-ch3"), ("double-mass", "thesis-ch4")])
def test_end_stops_hold_every_cart_on_the_track(kind: str, preset_name: str) -> None:
    inst, overrides = realism("lab", kind)
    plant = InstrumentedPlant(preset(preset_name, **overrides), instruments=inst)
    for k in range(3000):  # 10 V for 3 s would carry the cart well past the end of the track
        plant.do_step(k * H, H, 10.0)
    v = plant.values()
    carts = [n for n in v if n.endswith("cart_position")]
    assert plant.end_stop_hits > 0
    for n in carts:
        assert abs(v[n]) <= END_STOP_M + 1e-12
    assert max(v[n] for n in carts) == pytest.approx(END_STOP_M)
    assert v[carts[0].replace("position", "velocity")] == pytest.approx(0.0, abs=1e-9)


def test_ideal_and_lab_presets() -> None:
    ideal, ov = realism("ideal", "double-mass")
    assert ideal.ideal and ov["b1"] == ov["b2"] == 0.0
    lab, ov = realism("lab", "double-mass")
    assert not lab.ideal and lab.end_stop == END_STOP_M and ov["b2"] == preset("thesis-ch4-friction").b2
    with pytest.raises(InstrumentError, match="unknown realism preset 'x'"):
        realism("x", "single-mass")


@pytest.mark.integration
def test_plant_fmu_outputs_encoder_readings(plant_fmus: dict[str, Path], tmp_path: Path) -> None:
    f = instantiate(plant_fmus["single-mass"], tmp_path)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    f.set(cart_resolution=CART_M_PER_COUNT, pendulum_resolution=2 * math.pi / 4096, end_stop=0.05,
          initial_pendulum_angle=0.0123)
    f.slave.exitInitializationMode()
    for k in range(600):
        f.set(voltage=10.0)
        f.slave.doStep(k * H, H)
        x, th, v = f.get("cart_position", "pendulum_angle", "cart_velocity")
        assert (x / CART_M_PER_COUNT) == pytest.approx(round(x / CART_M_PER_COUNT), abs=1e-6)
        assert (th / (2 * math.pi / 4096)) == pytest.approx(round(th / (2 * math.pi / 4096)), abs=1e-6)
    assert x == pytest.approx(0.05, abs=CART_M_PER_COUNT) and v == 0.0
    f.slave.freeInstance()


@pytest.mark.integration
def test_plant_fmu_rejects_a_negative_option(plant_fmus: dict[str, Path], tmp_path: Path) -> None:
    f = instantiate(plant_fmus["double-mass"], tmp_path)
    f.slave.setupExperiment(startTime=0.0)
    f.slave.enterInitializationMode()
    f.set(noise_counts=-1.0)
    with pytest.raises(FMICallException):
        f.slave.exitInitializationMode()
    assert any("parameter noise_counts = -1.0" in m[2] for m in f.messages)
    f.slave.freeInstance()


def test_tap_changes_the_momenta_by_the_impulses() -> None:
    """M dv = (P_F, P_tau): the generalized momenta jump by exactly the impulses."""
    from ipcosim.fmus.instruments import tap_velocity_change

    m = (1.3, -0.02, 0.0087)
    dv, dw = tap_velocity_change(m, 0.3, 0.01)
    assert m[0] * dv + m[1] * dw == pytest.approx(0.3, rel=1e-12)
    assert m[1] * dv + m[2] * dw == pytest.approx(0.01, rel=1e-12)


def test_torque_tap_on_the_upright_pendulum_of_the_plant() -> None:
    p = preset("thesis-ch3")
    plant = InstrumentedPlant(p, instruments=Instruments(tap_time=0.005, tap_torque_impulse=0.005))
    for k in range(5):
        plant.do_step(k * H, H, 0.0)
    assert plant.state == [0.0] * 5 and not plant.tapped
    plant.do_step(5 * H, H, 0.0)
    assert plant.tapped and plant.values()["pendulum_velocity"] > 0.5


def test_input_delay_holds_the_voltage_back_whole_steps() -> None:
    plant = InstrumentedPlant(preset("thesis-ch3"), instruments=Instruments(input_delay=0.003))
    applied = []
    for k in range(6):
        plant.do_step(k * H, H, float(k + 1))
        applied.append(plant.voltage)
    assert applied == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]


def test_one_sample_computation_delay() -> None:
    """The lab bench's delay: the voltage of one step acts during the next (zero before the first)."""
    inst, _ = realism("lab", "single-mass")
    assert inst.input_delay == LAB_SAMPLE_PERIOD == H
    plant = InstrumentedPlant(preset("thesis-ch3"), instruments=Instruments(input_delay=H))
    applied = []
    for k in range(4):
        plant.do_step(k * H, H, float(k + 1))
        applied.append(plant.voltage)
    assert applied == [0.0, 1.0, 2.0, 3.0]


def test_dac_quantizes_the_voltage_to_whole_codes() -> None:
    """The Q4's 12-bit DAC over +-10 V: 4.883 mV codes; a command is the nearest code, so a command below half
    a code gives 0 V, and one of 0.6 codes one code."""
    inst, _ = realism("lab", "single-mass")
    assert inst.voltage_resolution == DAC_V_PER_CODE == pytest.approx(20 / 4096)
    plant = InstrumentedPlant(preset("thesis-ch3"), instruments=Instruments(voltage_resolution=DAC_V_PER_CODE))
    for k, (command, code) in enumerate([(0.4 * DAC_V_PER_CODE, 0), (0.6 * DAC_V_PER_CODE, 1), (1.0, 205),
                                         (-2.5 * DAC_V_PER_CODE + 1e-9, -2)]):
        plant.do_step(k * H, H, command)
        assert plant.voltage == code * DAC_V_PER_CODE, (command, plant.voltage)


def test_tap_metrics() -> None:
    from ipcosim.fmus.metrics import tap_metrics

    t = np.arange(0, 5, 1e-3)
    th = np.where(t < 1.0, 0.0, 0.05 * np.exp(-(t - 1.0) / 0.2) * np.cos(10 * (t - 1.0)))
    m = tap_metrics(t, th)
    assert m["peak_angle_after_tap_rad"] == pytest.approx(0.05)
    # the envelope 0.05 e^(-s/0.2) reaches 0.01 at s = 0.2 ln 5 = 0.32 s; the cosine re-enters a little earlier
    assert 0.2 < m["recovery_time_s"] <= 0.2 * math.log(5) + 1e-3
    assert tap_metrics(t, np.zeros_like(t)) == {"peak_angle_after_tap_rad": None, "recovery_time_s": None}
