"""The HIL adapter FMUs driven through fmpy against virtual rigs (lockstep; servers on 127.0.0.1 only).

What is checked: exactly the plant's connectors; an open-loop voltage sequence through the
adapter reproduces the plant FMU's trajectory within one encoder count (both plants, in
process and over TCP); start/stop safety (zeroed encoders, 0 V, watchdog); every fault ends
the step with a clear message and leaves the motor at 0 V; validate_fmu and VDMCheck2.
"""
from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmi_helpers import assert_vdmcheck_clean, instantiate, open_tcpip_cards, private_resource
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from ipcosim.fmus.hil.inproc import register_rig, unregister_rig
from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigServer

ROOT = Path(__file__).resolve().parents[2]
CART_RES, PEND_RES = 2.275e-5, 1.534e-3        # thesis-data.md, encoders
LSB = 20.0 / 4096                              # 12-bit DAC over +-10 V
OK, DISCARD, FATAL = 0, 2, 4
MEASURED = {"single-mass": ("cart_position", "pendulum_angle"),
            "double-mass": ("active_cart_position", "passive_cart_position", "pendulum_angle")}
RESOLUTION = {"cart_position": CART_RES, "active_cart_position": CART_RES, "passive_cart_position": CART_RES,
              "pendulum_angle": PEND_RES}

pytestmark = pytest.mark.integration


@pytest.fixture(scope="session")
def hil_fmus(project_fmus: dict[str, Path]) -> dict[str, Path]:
    """The HIL adapter FMUs of this run's build."""
    return {"single-mass": project_fmus["fmus/fmu_ip02_hil_single_mass.py"],
            "double-mass": project_fmus["fmus/fmu_ip02_hil_double_mass.py"]}


@pytest.fixture(scope="session")
def unzipped(tmp_path_factory: pytest.TempPathFactory):
    dirs: dict[Path, Path] = {}

    def get(fmu: Path) -> Path:
        if fmu not in dirs:
            dirs[fmu] = tmp_path_factory.mktemp(fmu.stem)
        return dirs[fmu]
    return get


def start_adapter(fmu: Path, unzip_dir: Path, uri: str, **params):
    f = instantiate(fmu, unzip_dir)
    s = f.slave
    s.setString([f.vr["card_uri"]], [uri])
    for name, value in params.items():
        s.setReal([f.vr[name]], [float(value)])
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    return f


def init_status(f) -> int:
    from fmpy.fmi2 import fmi2OK  # noqa: F401 -- fmpy raises on errors; catch and return the status
    try:
        f.slave.exitInitializationMode()
        return OK
    except Exception as exc:  # noqa: BLE001 -- fmpy's FMICallException carries the status
        return getattr(exc, "status", FATAL)


def do_step(f, t: float, h: float) -> int:
    try:
        f.slave.doStep(t, h)
        return OK
    except Exception as exc:  # noqa: BLE001
        return getattr(exc, "status", FATAL)


def free(f) -> None:
    try:
        f.slave.terminate()
    except Exception:  # noqa: BLE001
        pass
    f.slave.freeInstance()


def voltage_sequence(n: int) -> list[float]:
    """An open-loop test input: steps and a sine, rounded to DAC codes (so plant FMU and rig see the same volts)."""
    out = []
    for k in range(n):
        t = k * 1e-3
        v = 1.5 * math.sin(2 * math.pi * 1.3 * t) + (0.8 if (k // 150) % 2 else -0.8)
        out.append(round(v / LSB) * LSB)
    return out


@pytest.fixture
def inproc_rig():
    made = []

    def make(name: str, **config):
        rig = register_rig(name, VirtualRig(RigConfig(**config)))
        made.append(name)
        return rig
    yield make
    for name in made:
        unregister_rig(name)


# --- interface ------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["single-mass", "double-mass"])
def test_adapter_has_exactly_the_plants_connectors(kind, hil_fmus, plant_fmus):
    hil = read_model_description(str(hil_fmus[kind]))
    plant = read_model_description(str(plant_fmus[kind]))
    hil_io = {(v.name, v.causality, v.type, v.unit) for v in hil.modelVariables if v.causality in ("input", "output")
              and v.type == "Real"}
    plant_in = {(v.name, v.causality, v.type, v.unit) for v in plant.modelVariables if v.causality == "input"}
    plant_measured = {(v.name, v.causality, v.type, v.unit) for v in plant.modelVariables
                      if v.name in MEASURED[kind]}
    assert hil_io == plant_in | plant_measured
    status = {v.name: v.type for v in hil.modelVariables if v.causality == "output" and v.type != "Real"}
    assert status == {"watchdog_expired": "Boolean", "limit_tripped": "Boolean", "overruns": "Integer",
                      "last_error": "String"}
    params = {v.name for v in hil.modelVariables if v.causality == "parameter"}
    assert {"card_uri", "analog_channel", "cart_encoder_channel", "pendulum_encoder_channel", "cart_calibration",
            "pendulum_calibration", "watchdog_timeout"} <= params


@pytest.mark.parametrize("kind", ["single-mass", "double-mass"])
def test_adapter_passes_validate_fmu(kind, hil_fmus):
    assert validate_fmu(str(hil_fmus[kind])) == []
    names = zipfile.ZipFile(hil_fmus[kind]).namelist()
    assert private_resource(names, "fmus/hil/api.py")
    assert not any("/harness/" in n for n in names), names  # nothing of the master side
    assert all(n.endswith(".pyc") for n in names if "__pycache__" in n)  # only the build's checked bytecode
    for module in ("server", "server_requests", "server_log", "service"):  # the rig side, in the same room:
        assert not private_resource(names, f"fmus/hil/{module}.py")       # not imported
    for module in ("rig", "rig_config", "rig_clock", "rig_physics"):     # the in-process card's rig
        assert private_resource(names, f"fmus/hil/{module}.py")
    assert not private_resource(names, "harness/cli/__init__.py")


@pytest.mark.parametrize("kind", ["single-mass", "double-mass"])
@pytest.mark.slow
def test_adapter_passes_vdmcheck(kind, hil_fmus):
    assert_vdmcheck_clean(hil_fmus[kind])


# --- lockstep equivalence -------------------------------------------------------------------------

def run_open_loop(kind, hil, plant_fmu, unzip, uri, n):
    plant = instantiate(plant_fmu, unzip(plant_fmu))
    plant.slave.setupExperiment(startTime=0.0)
    plant.slave.enterInitializationMode()
    plant.slave.exitInitializationMode()
    hil_out, plant_out = [], []
    names = MEASURED[kind]
    for k, v in enumerate(voltage_sequence(n)):
        for f in (hil, plant):
            f.set(voltage=v)
        assert do_step(hil, k * 1e-3, 1e-3) == OK, hil.text()
        plant.slave.doStep(k * 1e-3, 1e-3)
        hil_out.append(hil.get(*names))
        plant_out.append(plant.get(*names))
    free(plant)
    return np.array(hil_out), np.array(plant_out)


@pytest.mark.parametrize("kind", ["single-mass", "double-mass"])
def test_open_loop_through_the_adapter_matches_the_plant_fmu_within_one_count(kind, hil_fmus, plant_fmus, unzipped,
                                                                               inproc_rig):
    rig = inproc_rig(f"openloop-{kind}", plant=kind, pendulum_limit=None, cart_limit=None)
    hil = start_adapter(hil_fmus[kind], unzipped(hil_fmus[kind]), f"q4:0@inproc://openloop-{kind}")
    assert init_status(hil) == OK, hil.text()
    assert hil.get(*MEASURED[kind]) == [0.0] * len(MEASURED[kind])
    n = 1500
    got, want = run_open_loop(kind, hil, plant_fmus[kind], unzipped, None, n)
    res = np.array([RESOLUTION[name] for name in MEASURED[kind]])
    err = np.abs(got - want) / res
    assert err.max() < 1.0, f"max error {err.max():.3f} counts"
    assert np.ptp(want[:, 0]) > 200 * CART_RES                  # the cart really moved
    assert rig.time() == pytest.approx(n * 1e-3, abs=1e-12)     # doStep(t, h) advanced the rig by exactly h
    free(hil)
    assert rig.motor_voltage() == 0.0


def test_open_loop_over_tcp_matches_too(hil_fmus, plant_fmus, unzipped):
    kind = "single-mass"
    with RigServer(VirtualRig(RigConfig(pendulum_limit=None, cart_limit=None)), "127.0.0.1", 0) as srv:
        hil = start_adapter(hil_fmus[kind], unzipped(hil_fmus[kind]), f"q4:{srv.uri}")
        assert init_status(hil) == OK, hil.text()
        got, want = run_open_loop(kind, hil, plant_fmus[kind], unzipped, srv.uri, 600)
        assert (np.abs(got - want) / np.array([CART_RES, PEND_RES])).max() < 1.0
        free(hil)
        assert srv.rig.motor_voltage() == 0.0


# --- safety on start and stop -----------------------------------------------------------------------

def test_start_zeroes_encoders_and_the_first_step_arms_the_watchdog(hil_fmus, unzipped, inproc_rig):
    rig = inproc_rig("start", pendulum_limit=None)
    rig.plant.set_state([0.05, 0, 0.1, 0, 0])         # wherever the rig happens to be
    rig.write_analog([0], [3.0])
    hil = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0@inproc://start",
                        watchdog_timeout=0.25)
    assert init_status(hil) == OK, hil.text()
    assert list(rig.read_encoder([0, 1])) == [0, 0]
    assert rig.motor_voltage() == 0.0
    assert not rig.watchdog.running                          # not armed before stepping begins
    hil.set(voltage=2.0)
    assert do_step(hil, 0.0, 1e-3) == OK
    assert rig.watchdog.running and rig.watchdog.timeout_ns == 250_000_000
    assert rig.motor_voltage() == pytest.approx(2.0, abs=LSB)
    assert rig.watchdog.last_reload_ns == 0                  # reloaded at the start of the step
    hil.slave.terminate()
    assert rig.motor_voltage() == 0.0 and not rig.watchdog.running
    hil.slave.freeInstance()


def test_voltage_is_clipped_to_the_voltage_limit(hil_fmus, unzipped, inproc_rig):
    rig = inproc_rig("clip", pendulum_limit=None)
    hil = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0@inproc://clip",
                        voltage_limit=6.0)
    assert init_status(hil) == OK
    hil.set(voltage=50.0)
    do_step(hil, 0.0, 1e-3)
    assert rig.motor_voltage() == pytest.approx(6.0, abs=LSB)
    free(hil)


# --- faults ---------------------------------------------------------------------------------------

def test_limit_trip_ends_the_step_naming_the_limit_and_the_amplifier_stays_off(hil_fmus, unzipped, inproc_rig):
    kind = "single-mass"
    rig = inproc_rig("limit", initial_state={"pendulum_angle": 0.3})
    hil = start_adapter(hil_fmus[kind], unzipped(hil_fmus[kind]), "q4:0@inproc://limit")
    assert init_status(hil) == OK
    status = OK
    for k in range(3000):
        hil.set(voltage=0.0)
        status = do_step(hil, k * 1e-3, 1e-3)
        if status != OK:
            break
    assert status == DISCARD
    assert "pendulum limit tripped" in hil.text() and "20 deg" in hil.text()
    assert hil.slave.getBoolean([hil.vr["limit_tripped"]]) == [True]
    assert b"pendulum limit" in hil.slave.getString([hil.vr["last_error"]])[0]
    free(hil)
    assert rig.status().limit_tripped and rig.motor_voltage() == 0.0
    again = start_adapter(hil_fmus[kind], unzipped(hil_fmus[kind]), "q4:0@inproc://limit")
    assert init_status(again) == FATAL                 # the amplifier stays off until the operator resets
    assert "reset the rig" in again.text()
    again.slave.freeInstance()
    rig.reset()
    third = start_adapter(hil_fmus[kind], unzipped(hil_fmus[kind]), "q4:0@inproc://limit")
    assert init_status(third) == OK
    free(third)


def test_rig_that_stops_answering_is_reported_and_the_motor_goes_to_zero(hil_fmus, unzipped):
    srv = RigServer(VirtualRig(RigConfig(clock="wallclock")), "127.0.0.1", 0, stall_after_steps=40).start()
    try:
        hil = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), f"q4:{srv.uri}",
                            watchdog_timeout=1.0)
        assert init_status(hil) == OK
        status = OK
        for k in range(100):
            hil.set(voltage=1.0)
            status = do_step(hil, k * 1e-3, 1e-3)
            if status != OK:
                break
        assert status == DISCARD and k == 40
        assert "did not answer STEP" in hil.text() and "within 1 s" in hil.text()
        assert hil.slave.getString([hil.vr["last_error"]])[0]
        free(hil)
        for _ in range(300):                        # bounded: the adapter closed its connection
            if srv.rig.motor_voltage() == 0.0:
                break
            import time
            time.sleep(0.01)
        assert srv.rig.motor_voltage() == 0.0
    finally:
        srv.close()


def test_watchdog_expiry_between_steps_is_reported(hil_fmus, unzipped, inproc_rig):
    class Clock:
        ns = 0

        def __call__(self):
            self.ns += 20_000                      # time passes as it is read (20 us per reading)
            return self.ns

    clock = Clock()
    rig = register_rig("wd", VirtualRig(RigConfig(clock="wallclock"), clock_ns=clock))
    try:
        hil = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0@inproc://wd",
                            watchdog_timeout=0.05)
        assert init_status(hil) == OK
        for k in range(5):
            hil.set(voltage=1.0)
            assert do_step(hil, k * 1e-3, 1e-3) == OK
        clock.ns += 200_000_000                    # the master stalls for 0.2 s
        assert rig.status().watchdog_expired and rig.motor_voltage() == 0.0
        assert do_step(hil, 5e-3, 1e-3) == DISCARD
        assert "watchdog expired" in hil.text()
        assert hil.slave.getBoolean([hil.vr["watchdog_expired"]]) == [True]
        free(hil)
    finally:
        unregister_rig("wd")


def test_second_adapter_is_refused_while_the_first_controls_the_rig(hil_fmus, unzipped):
    with RigServer(VirtualRig(RigConfig()), "127.0.0.1", 0) as srv:
        first = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), f"q4:{srv.uri}")
        assert init_status(first) == OK
        first.set(voltage=0.5)
        assert do_step(first, 0.0, 1e-3) == OK      # stepping begins: the first adapter controls the rig
        second = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), f"q4:{srv.uri}")
        assert init_status(second) == FATAL
        assert "rig busy" in second.text()
        second.slave.freeInstance()
        assert do_step(first, 1e-3, 1e-3) == OK      # the first session is unaffected
        free(first)


def test_garbage_on_the_adapters_connection_is_dropped_and_the_session_goes_on(hil_fmus, unzipped):
    from ipcosim.fmus.hil.protocol import Msg, encode_frame

    with RigServer(VirtualRig(RigConfig(pendulum_limit=None)), "127.0.0.1", 0) as srv:
        hil = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), f"q4:{srv.uri}")
        assert init_status(hil) == OK
        hil.set(voltage=0.625)
        assert do_step(hil, 0.0, 1e-3) == OK          # the connection of the stepping session
        card = next(c for c in open_tcpip_cards() if c.card_id == srv.uri)
        for k in range(1, 200):
            if k == 50:
                card._sock.send(b"\x13\x37 not a frame")
                card._sock.send(encode_frame(Msg.WRITE_ANALOG, 1, b"\x00\x01"))   # old seq and bad payload
                card._sock.send(encode_frame(Msg.WRITE_ANALOG, card._seq + 10_000, b"\x00"))  # bad payload
            hil.set(voltage=0.625)
            assert do_step(hil, k * 1e-3, 1e-3) == OK, hil.text()
        assert srv.counters["malformed"] == 2 and srv.counters["out_of_order"] == 1
        assert srv.rig.time() == pytest.approx(0.2, abs=1e-9)
        free(hil)


def test_wrong_plant_kind_and_missing_quanser_package_are_clear_errors(hil_fmus, unzipped, inproc_rig,
                                                                       monkeypatch):
    import sys
    inproc_rig("kind", plant="double-mass")
    f = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0@inproc://kind")
    assert init_status(f) == FATAL and "double-mass rig" in f.text()
    f.slave.freeInstance()
    monkeypatch.setitem(sys.modules, "quanser", None)
    f = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0")
    assert init_status(f) == FATAL and "quanser.hardware" in f.text() and "not installed" in f.text()
    f.slave.freeInstance()
    f = start_adapter(hil_fmus["single-mass"], unzipped(hil_fmus["single-mass"]), "q4:0@tcpip://127.0.0.1:1")
    assert init_status(f) == FATAL and "cannot connect" in f.text()
    f.slave.freeInstance()


def test_adapter_presents_the_rigs_token_from_its_parameter_or_the_environment(hil_fmus, unzipped, monkeypatch):
    monkeypatch.delenv("IPCOSIM_RIG_TOKEN", raising=False)
    fmu = hil_fmus["single-mass"]
    with RigServer(VirtualRig(RigConfig()), "127.0.0.1", 0, token="lab-token") as srv:
        f = start_adapter(fmu, unzipped(fmu), f"q4:{srv.uri}")
        assert init_status(f) == FATAL and "access token" in f.text()
        f.slave.freeInstance()
        f = start_adapter(fmu, unzipped(fmu), f"q4:{srv.uri}")
        f.slave.setString([f.vr["card_token"]], ["lab-token"])
        assert init_status(f) == OK, f.text()
        assert do_step(f, 0.0, 1e-3) == OK
        free(f)
        monkeypatch.setenv("IPCOSIM_RIG_TOKEN", "lab-token")
        f = start_adapter(fmu, unzipped(fmu), f"q4:{srv.uri}")
        assert init_status(f) == OK, f.text()
        assert do_step(f, 0.0, 1e-3) == OK
        free(f)


def test_initialization_longer_than_the_watchdog_and_the_lease_does_not_stop_the_first_step(hil_fmus, unzipped):
    fmu = hil_fmus["single-mass"]
    with RigServer(VirtualRig(RigConfig(clock="wallclock")), "127.0.0.1", 0, idle_timeout=0.3) as srv:
        f = start_adapter(fmu, unzipped(fmu), f"q4:{srv.uri}", watchdog_timeout=0.1)
        assert init_status(f) == OK
        import time
        time.sleep(1.0)                         # the other components initialize slowly
        assert not srv.rig.status().watchdog_expired
        for k in range(20):
            f.set(voltage=0.5)
            assert do_step(f, k * 1e-3, 1e-3) == OK, f.text()
        assert srv.rig.watchdog.running and not srv.rig.status().watchdog_expired
        free(f)


class _ClockCard:
    """A card that only tells its time [s] and its clock (for the adapter's sample instants)."""

    def __init__(self, now_s: float, clock: str, tick: float = 5e-4) -> None:
        import types

        self.now_s, self.info = now_s, types.SimpleNamespace(clock=clock, tick=tick)

    def time(self) -> float:
        return self.now_s


def test_a_real_time_cards_sample_instants_follow_the_earliest_paced_schedule():
    """The start-up step puts the sample instants on the card's tick grid (a lockstep card keeps them); on a
    real-time card the next step, the first a host paces, puts them ANCHOR_LEAD of a period before its start
    on the card's clock (the host's time since it began taken off); a later step that begins earlier than
    that schedule by less than half a period moves them with it, one that begins later or about a period
    early (a host that does not pace) leaves them."""
    import time

    from ipcosim.fmus.hil.adapter import ANCHOR_LEAD, HilFmu

    lead = round(1e6 * ANCHOR_LEAD)                           # [ns] of a 1 ms period
    fmu = HilFmu.__new__(HilFmu)
    for clock in ("wallclock", "lockstep"):
        fmu._base_ns, fmu._paced_base = None, False
        card = _ClockCard(12.3456789, clock)
        fmu._base_ns = fmu._sample_base(card, 0.0, 1e-3, time.monotonic_ns())
        assert fmu._base_ns == 12_345_500_000                                  # the tick grid (0.5 ms)
        card.now_s = 12.35
        began = time.monotonic_ns() - 3_000_000                 # the second step, at t = 1 ms, began 3 ms ago
        base = fmu._sample_base(card, 1e-3, 1e-3, began)
        elapsed = time.monotonic_ns() - began
        if clock == "lockstep":
            assert base is None
            continue
        assert 12_350_000_000 - elapsed - 1_000_000 - lead <= base <= 12_350_000_000 - 3_000_000 - 1_000_000 - lead
        fmu._base_ns = base

        def at(t: float, ahead_ns: int, card: _ClockCard = card, base: int = base) -> int | None:
            """A step at time ``t`` that begins ``ahead_ns`` before the schedule in use (negative: after)."""
            card.now_s = (base + round(t * 1e9) + lead - ahead_ns) / 1e9
            return fmu._sample_base(card, t, 1e-3, time.monotonic_ns())

        assert at(0.002, -200_000) is None                     # later than the schedule: kept
        assert at(0.003, 900_000) is None                      # about a period early: not a pacing host, kept
        moved = at(0.004, 200_000)                             # 0.2 ms early: the host's schedule, followed
        assert moved is not None and 199_000 <= base - moved <= 201_000
