"""Card URIs, backend selection, the in-process backend and the Quanser backend's translation layer."""
from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from ipcosim.errors import IpcosimError
from ipcosim.fmus.hil import ErrorCode, HILError, open_card, open_uri, parse_card_uri
from ipcosim.fmus.hil.inproc import VirtualCard, get_rig, register_rig, unregister_rig
from ipcosim.fmus.hil.rig import RigConfig, VirtualRig


@pytest.mark.parametrize("uri, expected", [
    ("q4:0@tcpip://127.0.0.1:18920", ("q4", "0@tcpip://127.0.0.1:18920")),
    ("0@tcpip://localhost:1", ("q4", "0@tcpip://localhost:1")),
    ("q8_usb:0", ("q8_usb", "0")),
    ("0", ("q4", "0")),
    ("q4:0@inproc://bench?plant=double-mass", ("q4", "0@inproc://bench?plant=double-mass")),
])
def test_parse_card_uri(uri, expected):
    assert parse_card_uri(uri) == expected


@pytest.mark.parametrize("uri", ["", "q4:", ":0", "q4:0@tcpip://nohost", "q4:0@tcpip://h:notaport",
                                 "q4:0@carrier-pigeon://x", "q4:0@inproc://x?colour=red",
                                 "q4:0@inproc://x?plant=triple-mass"])
def test_bad_uris_are_clear_errors(uri):
    with pytest.raises(HILError) as e:
        open_uri(uri)
    assert e.value.code == ErrorCode.BAD_URI


def test_hil_error_carries_code_and_message_like_quanser():
    e = HILError(ErrorCode.TIMEOUT, "the rig did not answer")
    assert e.code == e.error_code == 6 and e.get_error_message() == "the rig did not answer"
    assert "TIMEOUT" in str(e) and isinstance(e, IpcosimError) and isinstance(e, RuntimeError)
    assert HILError(-1003, "quanser code").code_name == "-1003"


def test_quanser_backend_absent_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "quanser", None)         # make sure it cannot be imported
    monkeypatch.setitem(sys.modules, "quanser.hardware", None)
    with pytest.raises(HILError) as e:
        open_card("q4", "0")
    assert e.value.code == ErrorCode.BACKEND_MISSING
    assert "quanser.hardware" in e.value.message and "tcpip" in e.value.message


def fake_quanser(monkeypatch, fail_open: bool = False):
    calls = []

    class FakeQError(Exception):
        def __init__(self, code):
            self.error_code = code

        def get_error_message(self):
            return f"quanser says {self.error_code}"

    class FakeHIL:
        def open(self, card_type, card_id):
            if fail_open:
                raise FakeQError(-1001)
            calls.append(("open", card_type, card_id))

        def write_analog(self, ch, n, buf):
            calls.append(("write_analog", ch.dtype.name, list(ch), n, list(buf)))

        def read_encoder(self, ch, n, buf):
            buf[:] = [11, -22][:n]
            calls.append(("read_encoder", ch.dtype.name, list(ch), n, buf.dtype.name))

        def set_encoder_counts(self, ch, n, buf):
            calls.append(("set_encoder_counts", list(ch), n, list(buf)))

        def watchdog_set_analog_expiration_state(self, ch, n, buf):
            calls.append(("expiration", list(ch), n, list(buf)))

        def watchdog_start(self, timeout):
            calls.append(("watchdog_start", timeout))

        def watchdog_reload(self):
            raise FakeQError(-1064)

        def watchdog_is_expired(self):
            return 1

        def watchdog_clear(self):
            calls.append(("clear",))

        def watchdog_stop(self):
            calls.append(("stop",))

        def close(self):
            calls.append(("close",))

    hardware = types.ModuleType("quanser.hardware")
    hardware.HIL, hardware.HILError = FakeHIL, FakeQError
    pkg = types.ModuleType("quanser")
    pkg.hardware = hardware
    monkeypatch.setitem(sys.modules, "quanser", pkg)
    monkeypatch.setitem(sys.modules, "quanser.hardware", hardware)
    return calls


def test_quanser_backend_translates_calls_and_errors(monkeypatch):
    calls = fake_quanser(monkeypatch)
    card = open_card("q4", "0")
    card.write_analog([0], [1.5])
    counts = card.read_encoder([0, 1])
    card.set_encoder_counts([0, 1], [0, 0])
    card.watchdog_set_analog_expiration_state([0], [0.0])
    card.watchdog_start(0.1)
    assert card.watchdog_is_expired() is True
    with pytest.raises(HILError) as e:
        card.watchdog_reload()
    assert e.value.code == -1064 and "quanser says -1064" in e.value.message
    card.close()
    card.close()
    assert counts.dtype == np.int32 and list(counts) == [11, -22]
    assert calls[0] == ("open", "q4", "0")
    assert calls[1] == ("write_analog", "uint32", [0], 1, [1.5])
    assert ("read_encoder", "uint32", [0, 1], 2, "int32") in calls
    assert calls.count(("close",)) == 1
    with pytest.raises(HILError) as e:
        card.write_analog([0], [0.0])
    assert e.value.code == ErrorCode.NOT_OPEN


def test_quanser_open_failure_keeps_the_quanser_code(monkeypatch):
    fake_quanser(monkeypatch, fail_open=True)
    with pytest.raises(HILError) as e:
        open_card("q8_usb", "3")
    assert e.value.code == -1001 and "q8_usb" in e.value.message


def test_inproc_card_drives_a_registered_rig_and_is_exclusive():
    rig = register_rig("test-api", VirtualRig(RigConfig(plant="double-mass")))
    try:
        card = open_card("q4", "0@inproc://test-api")
        assert card.info.plant == "double-mass" and card.rig is rig
        with pytest.raises(HILError) as e:
            open_card("q4", "0@inproc://test-api")
        assert e.value.code == ErrorCode.BUSY
        card.write_analog([0], [2.0])
        assert rig.motor_voltage() == pytest.approx(2.0, abs=0.003)
        card.close()
        assert rig.motor_voltage() == 0.0          # closing leaves the outputs at 0 V
        with pytest.raises(HILError) as e:
            card.read_encoder([0])
        assert e.value.code == ErrorCode.NOT_OPEN
        open_card("q4", "0@inproc://test-api").close()
    finally:
        unregister_rig("test-api")


def test_a_deferred_inproc_step_returns_at_once_and_the_next_waits_for_its_sample_instant():
    """As over TCP: with ``defer_wait`` a wall-clock step returns its sample instant's reading at once and the
    next step starts no earlier than that instant; without it, a step returns at its instant."""
    import time

    rig = register_rig("test-defer", VirtualRig(RigConfig(clock="wallclock", pendulum_limit=None, cart_limit=None)))
    try:
        card = open_card("q4", "0@inproc://test-defer")
        card.watchdog_start(1.0)
        card.defer_wait = True
        until = card.time() + 0.2
        began = time.monotonic()
        first = card.step([0], [0.5], [0, 1], until)
        assert time.monotonic() - began < 0.15 and first.time < until and rig._t_ns >= round(until * 1e9)
        card.step([0], [0.5], [0, 1], until + 0.001)
        assert card.last_wait_ns > 0.1e9 and rig.now_ns() >= round(until * 1e9)
        card.defer_wait = False
        until3 = card.time() + 0.05
        third = card.step([0], [0.5], [0, 1], until3)
        assert third.time >= until3
        card.close()
    finally:
        unregister_rig("test-defer")


def test_inproc_creates_a_rig_from_the_query():
    try:
        card = open_uri("q4:0@inproc://test-query?plant=double-mass")
        assert isinstance(card, VirtualCard) and get_rig("test-query").kind == "double-mass"
        card.close()
    finally:
        unregister_rig("test-query")


def test_swap_alias_picks_the_adapter_by_plant_kind(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from ipcosim.fmus.kinds import plant_kind
    from ipcosim.harness.hil.swap import HilSwapError, card_clock, find_adapter, resolve_hil
    from ipcosim.harness.scenario.locations import fmu_search_path

    assert plant_kind("x", "IP02SingleMass", set()) == "single-mass"
    assert plant_kind("x", "IP02DoubleMass", set()) == "double-mass"
    assert plant_kind("double-mass-lqr", None, set()) == "double-mass"
    assert plant_kind("ssp/single-mass-pid", None, set()) == "single-mass"
    assert plant_kind("mine", None, {"voltage", "passive_cart_position"}) == "double-mass"
    assert plant_kind("mine", None, {"voltage", "cart_position"}) == "single-mass"
    assert plant_kind("mine", parameters={"Mp", "K"}) == "double-mass"
    assert plant_kind("mine", parameters={"Mp"}) == "single-mass"
    assert plant_kind("mine", "Other", {"voltage"}) is None
    unknown = SimpleNamespace(scenario=SimpleNamespace(name="mine"), component="plant",
                              model=SimpleNamespace(name="Other", path=None), fmu_dirs=())
    with pytest.raises(HilSwapError, match="cannot tell the plant kind of scenario 'mine'"):
        resolve_hil(unknown)
    (tmp_path / "IP02HILSingleMass.fmu").write_bytes(b"")
    assert find_adapter("IP02HILSingleMass", [tmp_path]) == (tmp_path / "IP02HILSingleMass.fmu").resolve()
    monkeypatch.setenv("IPCOSIM_FMU_PATH", str(tmp_path))
    assert find_adapter("IP02HILSingleMass", fmu_search_path()) == (tmp_path / "IP02HILSingleMass.fmu").resolve()
    with pytest.raises(HilSwapError, match="ipcosim build"):
        find_adapter("IP02HILNoSuchPlant", [tmp_path])
    assert card_clock("q4:0") == "wallclock"                              # a real card runs in real time
    assert card_clock("q4:0@inproc://nowhere?clock=lockstep") == "lockstep"
    assert card_clock("q4:0@tcpip://127.0.0.1:1") == "wallclock"          # unreachable: assume real time
