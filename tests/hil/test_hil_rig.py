"""The virtual rig's card and lab model, in lockstep (deterministic) and with a fake wall clock."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.fmus.hil import ErrorCode, HILError, count_difference
from ipcosim.fmus.hil.api import INT32_MAX
from ipcosim.fmus.hil.rig import (
    CART_M_PER_COUNT,
    DAC_LSB,
    END_STOP_M,
    PENDULUM_RAD_PER_COUNT,
    RigConfig,
    VirtualRig,
    dac_quantize,
)
from ipcosim.fmus.params import preset
from ipcosim.fmus.plant import Plant

# Thesis facts (thesis-data.md, section 1 table and section 3)
THESIS_CART_RES = 2.275e-5
THESIS_PEND_RES = 1.534e-3
LSB = 20.0 / 4096


def nearest(q: float) -> int:
    """The default encoder model: count edges half a count either side of the zero."""
    return math.floor(q + 0.5)


def rig(**kw) -> VirtualRig:
    return VirtualRig(RigConfig(**kw))


def test_card_constants_are_the_thesis_numbers():
    assert CART_M_PER_COUNT == THESIS_CART_RES
    assert PENDULUM_RAD_PER_COUNT == THESIS_PEND_RES
    assert DAC_LSB == LSB
    # 4096 counts per revolution of the pendulum encoder
    assert abs(4096 * THESIS_PEND_RES - 2 * math.pi) < 2 * math.pi * 1e-3


@pytest.mark.parametrize("volts", [0.0, 1.0, -1.0, 3.3333, 7.77, -9.99])
def test_dac_is_12_bit_over_10_volts(volts):
    q = dac_quantize(volts)
    assert abs(q - volts) <= LSB / 2 + 1e-12
    assert abs(q / LSB - round(q / LSB)) < 1e-9          # an integer code


def test_dac_saturates_at_the_range():
    assert dac_quantize(25.0) == pytest.approx(2047 * LSB)
    assert dac_quantize(-25.0) == pytest.approx(-10.0)


def test_encoders_count_positions_counter_clockwise_positive():
    r = rig()
    r.plant.set_state([0.1, 0, 0.2, 0, 0])
    counts = r.read_encoder([0, 1, 2, 3])
    assert counts.dtype == np.int32
    assert counts[0] == nearest(0.1 / THESIS_CART_RES)
    assert counts[1] == nearest(0.2 / THESIS_PEND_RES) > 0       # counter-clockwise = positive
    assert counts[2] == 0 and counts[3] == 0                         # not connected on the single mass
    r.plant.set_state([-0.1, 0, -0.2, 0, 0])
    counts = r.read_encoder([0, 1])
    assert counts[0] == nearest(-0.1 / THESIS_CART_RES) < 0
    assert counts[1] == nearest(-0.2 / THESIS_PEND_RES) < 0


def test_reading_is_within_half_a_count_and_the_edge_phase_is_configurable():
    r = rig()
    edge = rig(encoder_phase=0.0)
    for x in np.linspace(-0.3, 0.3, 37):
        for rr in (r, edge):
            rr.plant.set_state([x, 0, 0, 0, 0])
        measured = int(r.read_encoder([0])[0]) * THESIS_CART_RES
        assert abs(x - measured) <= THESIS_CART_RES / 2 + 1e-15
        measured = int(edge.read_encoder([0])[0]) * THESIS_CART_RES     # an edge at the zero:
        assert 0 <= x - measured < THESIS_CART_RES                       # up to one count below


def test_double_mass_third_encoder_is_the_passive_cart():
    r = rig(plant="double-mass")
    r.plant.set_state([0.05, 0, -0.02, 0, 0.1, 0, 0])
    c = r.read_encoder([0, 1, 2])
    assert c[0] == nearest(0.05 / THESIS_CART_RES)
    assert c[1] == nearest(0.1 / THESIS_PEND_RES)
    assert c[2] == nearest(-0.02 / THESIS_CART_RES)


def test_counters_are_32_bit_and_wrap():
    r = rig()
    r.set_encoder_counts([0], [INT32_MAX - 1])
    before = int(r.read_encoder([0])[0])
    r.plant.set_state([5.5 * THESIS_CART_RES, 0, 0, 0, 0])   # 5 counts further
    after = int(r.read_encoder([0])[0])
    assert after < 0 < before                                 # wrapped around
    assert count_difference(after, before) == 5


def test_set_encoder_counts_zeroes_at_the_current_position():
    r = rig()
    r.plant.set_state([0.0123, 0, 0.05, 0, 0])
    r.set_encoder_counts([0, 1], [0, 0])
    assert list(r.read_encoder([0, 1])) == [0, 0]
    r.plant.set_state([0.0123 + 100 * THESIS_CART_RES, 0, 0.05, 0, 0])
    assert int(r.read_encoder([0])[0]) in (99, 100)


def test_lockstep_rig_steps_the_plant_physics_exactly():
    """One source of truth: the rig's motion is ipcosim.fmus.plant.Plant, step for step."""
    r = rig()
    plant = Plant(preset("thesis-ch3"))
    volts = [k * LSB for k in (128, 128, -256, 0, 512, 64)]   # DAC-exact values
    for k in range(300):
        v = volts[(k // 50) % len(volts)]
        r.write_analog([0], [v])
        r.advance(1e-3)
        plant.do_step(k * 1e-3, 1e-3, v)
    assert np.array_equal(r.plant.x, plant.x)
    assert r.time() == pytest.approx(0.3, abs=1e-12)


def test_lockstep_is_deterministic_and_ticks_are_integer_nanoseconds():
    a, b = rig(), rig()
    for r in (a, b):
        for k in range(1, 1001):
            r.step([0], [1.0 if k < 500 else -1.0], [0, 1], k * 1_000_000)
    assert np.array_equal(a.plant.x, b.plant.x)
    assert a._t_ns == 1_000_000_000          # no accumulated float error after 1000 steps


def test_step_into_the_past_is_refused_in_lockstep():
    r = rig()
    r.advance(0.01)
    with pytest.raises(HILError) as e:
        r.step([0], [0.0], [0], 5_000_000)
    assert e.value.code == ErrorCode.CLOCK


def test_bad_channels_and_values_are_clear_errors():
    r = rig()
    with pytest.raises(HILError) as e:
        r.write_analog([4], [0.0])
    assert e.value.code == ErrorCode.BAD_CHANNEL and "channel 4" in e.value.message
    with pytest.raises(HILError) as e:
        r.write_analog([0], [float("nan")])
    assert e.value.code == ErrorCode.INVALID_ARGUMENT
    with pytest.raises(HILError) as e:
        r.read_encoder([7])
    assert e.value.code == ErrorCode.BAD_CHANNEL
    with pytest.raises(HILError) as e:
        r.watchdog_start(0.0)
    assert e.value.code == ErrorCode.INVALID_ARGUMENT


def test_watchdog_expiry_forces_the_expiration_state_and_latches():
    r = rig()
    r.watchdog_set_analog_expiration_state([0], [1.0])
    r.watchdog_start(0.05)
    r.write_analog([0], [5.0])
    r.advance(0.04)
    assert r.watchdog_reload() is True
    reload_ns = r.watchdog.last_reload_ns
    r.advance(0.2)
    assert r.watchdog_is_expired()
    assert r.watchdog.expired_at_ns - reload_ns <= 50_000_000 + r.tick_ns      # within the timeout (+ one tick)
    assert r.motor_voltage() == pytest.approx(dac_quantize(1.0))         # the expiration state, not 5 V
    with pytest.raises(HILError) as e:
        r.write_analog([0], [3.0])
    assert e.value.code == ErrorCode.WATCHDOG_EXPIRED
    assert r.watchdog_reload() is False
    r.watchdog_stop()
    assert r.watchdog_is_expired()                                        # stop does not clear
    r.watchdog_clear()
    r.write_analog([0], [2.0])
    assert r.motor_voltage() == pytest.approx(dac_quantize(2.0))


def test_watchdog_default_expiration_state_is_zero_volts():
    r = rig()
    r.watchdog_start(0.01)
    r.write_analog([0], [4.0])
    r.advance(0.05)
    assert r.watchdog_is_expired() and r.motor_voltage() == 0.0


def test_pendulum_limit_latches_the_amplifier_off_until_reset():
    r = rig(initial_state={"pendulum_angle": 0.3})       # 17 deg, inside the 20 deg limit
    r.new_session("test")
    assert r.status().amplifier_enabled
    for _ in range(2000):
        r.write_analog([0], [0.0])
        r.advance(1e-3)
        if not r.amplifier_enabled:
            break
    st = r.status()
    assert st.limit_tripped and not st.amplifier_enabled
    assert "pendulum" in st.limit_message and "20 deg" in st.limit_message
    angle = r.true_state()["pendulum_angle"]
    assert abs(angle) > math.radians(20) - THESIS_PEND_RES
    r.write_analog([0], [5.0])
    assert r.motor_voltage() == 0.0                       # the card accepts the write; the amplifier is off
    r.new_session("next")                                 # a new session does not clear the latch
    assert r.status().limit_tripped and r.motor_voltage() == 0.0
    r.reset()
    r.write_analog([0], [5.0])
    assert r.status().amplifier_enabled and r.motor_voltage() == pytest.approx(dac_quantize(5.0))
    assert r.true_state()["pendulum_angle"] == pytest.approx(0.3)      # re-homed


def test_cart_limit_trips_at_0_30_m():
    r = rig(pendulum_limit=None)
    for _ in range(5000):
        r.write_analog([0], [6.0])
        r.advance(1e-3)
        if not r.amplifier_enabled:
            break
    st = r.status()
    assert st.limit_tripped and "cart_position" in st.limit_message and "0.3" in st.limit_message
    assert r.true_state()["cart_position"] == pytest.approx(0.30, abs=0.005)


def test_hard_end_stop_at_0_407_m():
    r = rig(cart_limit=None, pendulum_limit=None)
    positions = []
    for _ in range(4000):
        r.write_analog([0], [8.0])
        r.advance(1e-3)
        positions.append(r.true_state()["cart_position"])
    assert max(positions) == pytest.approx(END_STOP_M)
    assert max(positions) <= 0.407
    assert r.true_state()["cart_velocity"] == 0.0
    assert r.status().counters.get("end_stop:cart_position", 0) > 0


def test_transport_latency_delays_commands_and_readings():
    lat = 0.005
    delayed, direct = rig(latency=lat), rig()
    for r in (delayed, direct):
        r.write_analog([0], [3.0])
    delayed.advance(lat)
    assert delayed.true_state()["cart_position"] == 0.0          # the command has not arrived yet
    direct_counts = []
    delayed_counts = []
    for _ in range(100):
        direct.advance(1e-3)
        direct_counts.append(int(direct.read_encoder([0])[0]))
    # the delayed rig: command arrives 5 ms late, readings show the encoders 5 ms ago
    for _ in range(100):
        delayed.advance(1e-3)
        delayed_counts.append(int(delayed.read_encoder([0])[0]))
    # delayed reading at (lat + (k+1) ms) shows the encoders at (k+1) ms after the command's arrival
    # = direct reading at (k+1) ms, minus the lat already spent -> shift of lat/1ms samples
    shift = int(round(lat / 1e-3))
    assert delayed_counts[shift:] == direct_counts[:len(direct_counts) - shift]


def test_encoder_noise_is_seeded_gaussian_counts():
    a, b, clean = rig(noise_counts=2.0, seed=7), rig(noise_counts=2.0, seed=7), rig()
    for r in (a, b, clean):
        r.plant.set_state([0.05, 0, 0.1, 0, 0])
    ra = np.array([a.read_encoder([0])[0] for _ in range(3000)], dtype=float)
    rb = np.array([b.read_encoder([0])[0] for _ in range(3000)], dtype=float)
    exact = float(clean.read_encoder([0])[0])
    assert np.array_equal(ra, rb)
    assert 1.6 < np.std(ra - exact) < 2.4
    assert abs(np.mean(ra - exact)) < 0.2


class FakeClock:
    def __init__(self) -> None:
        self.ns = 1_000_000_000

    def __call__(self) -> int:
        return self.ns


def fine(plant: Plant, t0: float, t1: float, volts: float, h: float = 1e-5) -> None:
    """``plant`` from ``t0`` to ``t1`` in steps of about ``h`` (an independent, finer integration)."""
    n = max(1, round((t1 - t0) / h))
    for k in range(n):
        plant.do_step(t0 + k * (t1 - t0) / n, (t1 - t0) / n, volts)


def test_wallclock_computes_the_physics_exactly_to_the_request_without_ticking():
    clock = FakeClock()
    r = VirtualRig(RigConfig(clock="wallclock", tick=5e-4), clock_ns=clock)
    r.start_clock()
    r.write_analog([0], [2.0])
    clock.ns += 10_300_000                       # 10.3 ms of real time: not on any 0.5 ms grid
    assert r._t_ns == 0                          # nothing was computed while nobody asked
    assert r.time() == pytest.approx(0.0103)
    assert r._t_ns == 10_300_000                 # the physics is at the request, not at the last tick
    plant = Plant(preset("thesis-ch3"))
    fine(plant, 0.0, 0.0103, dac_quantize(2.0))
    assert np.allclose(r.plant.x, plant.x, rtol=0, atol=1e-6)     # the integrator's own accuracy
    tick_grid = Plant(preset("thesis-ch3"))
    fine(tick_grid, 0.0, 0.0100, dac_quantize(2.0))
    assert not np.allclose(r.plant.x, tick_grid.x, rtol=0, atol=1e-6)   # a grid would lag by 0.3 ms


def test_wallclock_watchdog_expires_at_its_deadline_without_any_request():
    clock = FakeClock()
    r = VirtualRig(RigConfig(clock="wallclock", tick=5e-4), clock_ns=clock)
    r.start_clock()
    clock.ns += 370_000                          # armed 0.37 ms in: the deadline is off every tick grid
    r.watchdog_start(0.05)
    r.write_analog([0], [6.0])
    clock.ns += 200_000_000                      # the client went silent for 0.2 s
    st = r.status()
    assert st.watchdog_expired and st.motor_voltage == 0.0
    assert r.watchdog.expired_at_ns == 50_370_000      # at the deadline itself


def test_watchdog_expiry_inside_a_long_interval_switches_the_motor_off_at_its_deadline():
    r = rig(cart_limit=None, pendulum_limit=None)
    r.watchdog_start(0.0503)                     # lockstep ticks are 1 ms: the deadline lies between two
    r.write_analog([0], [5.0])
    r.advance(0.2)
    assert r.watchdog.expired_at_ns == 50_300_000
    exact = Plant(preset("thesis-ch3"))
    fine(exact, 0.0, 0.0503, dac_quantize(5.0))
    fine(exact, 0.0503, 0.2, 0.0)
    late = Plant(preset("thesis-ch3"))          # what latching at the next tick (51 ms) would give
    fine(late, 0.0, 0.051, dac_quantize(5.0))
    fine(late, 0.051, 0.2, 0.0)
    off_exact, off_late = np.max(np.abs(r.plant.x - exact.x)), np.max(np.abs(r.plant.x - late.x))
    assert off_exact < 1e-5 and off_late > 100 * off_exact    # 1 ms steps against 10 us ones


def first_trip(x0: dict, limit: float, t_end: float, h: float = 1e-5) -> float:
    """When the pendulum's encoder reading first exceeds ``limit`` with the motor at 0 V, by fine steps."""
    p = Plant(preset("thesis-ch3"))
    p.set_state([x0.get(n, 0.0) for n in p.state_names])
    k = 0
    while k * h < t_end:
        p.do_step(k * h, h, 0.0)
        k += 1
        if abs(nearest(p.values()["pendulum_angle"] / PENDULUM_RAD_PER_COUNT) * PENDULUM_RAD_PER_COUNT) > limit:
            return k * h
    raise AssertionError("no trip")


@pytest.mark.parametrize("clock", ["lockstep", "wallclock"])
def test_a_limit_crossing_inside_a_long_interval_is_latched_at_the_instant_it_happens(clock):
    x0 = {"pendulum_angle": 0.2}
    fake = FakeClock()
    r = VirtualRig(RigConfig(clock=clock, initial_state=x0, cart_limit=None), clock_ns=fake)
    r.start_clock()
    if clock == "lockstep":
        r.advance(1.0)                           # one request across the whole fall
    else:
        fake.ns += 1_000_000_000
        r.status()
    trip = [e for e in r.events if e.topic == "limit"]
    assert len(trip) == 1
    expected = first_trip(x0, math.radians(20), 1.0)
    assert abs(trip[0].time - expected) <= 1e-5 + 1e-12      # to the 10 us the rig locates to
    # after the trip the motor was off: the written voltage never reached the plant
    assert r.motor_voltage() == 0.0


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match="clock"):
        RigConfig(clock="sundial").checked()
    with pytest.raises(ValueError, match="plant"):
        RigConfig(plant="triple-mass").checked()
    with pytest.raises(ValueError, match="latency"):
        RigConfig(latency=-1).checked()
    with pytest.raises(ValueError, match="no state"):
        VirtualRig(RigConfig(initial_state={"angle": 0.1}))


def test_limits_are_disarmed_after_a_session_ends_and_rearmed_by_the_next():
    r = rig(initial_state={"pendulum_angle": 0.3})
    r.new_session("a")
    r.end_session("done")
    r.advance(2.0)                                         # the pendulum falls with the motor at 0 V
    assert abs(r.true_state()["pendulum_angle"]) > math.radians(20)
    assert not r.status().limit_tripped                    # not the next experiment's fault
    r.new_session("b")                                     # re-homed and armed again
    for _ in range(2000):
        r.advance(1e-3)
        if r.status().limit_tripped:
            break
    assert r.status().limit_tripped
