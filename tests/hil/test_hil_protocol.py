"""Wire protocol framing and the rig server's robustness (servers on 127.0.0.1 only, lockstep)."""
from __future__ import annotations

import random
import socket
import struct
import time

import pytest

from ipcosim.fmus.hil import ErrorCode, HILError, open_card
from ipcosim.fmus.hil.protocol import (
    HEADER_SIZE,
    MAGIC,
    MAX_PAYLOAD,
    PROTOCOL_VERSION,
    REPLY_BIT,
    FrameDecoder,
    Msg,
    Reader,
    encode_frame,
    pack_channels,
    pack_doubles,
    pack_text,
)
from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigServer
from ipcosim.fmus.hil.tcpip import TcpipCard

# --- framing (pure) -----------------------------------------------------------------------------

def test_frame_round_trip_and_header_layout():
    raw = encode_frame(Msg.STEP, 42, b"abc")
    assert raw[:4] == MAGIC and raw[4] == PROTOCOL_VERSION and raw[5] == Msg.STEP
    assert struct.unpack("!I", raw[8:12])[0] == 42 and struct.unpack("!I", raw[12:16])[0] == 3
    assert len(raw) == HEADER_SIZE + 3
    frames = FrameDecoder().feed(raw)
    assert [(f.type, f.seq, f.payload) for f in frames] == [(Msg.STEP, 42, b"abc")]


def test_decoder_reassembles_frames_split_at_every_byte():
    data = b"".join(encode_frame(Msg.TIME, k, bytes([k]) * k) for k in range(1, 6))
    dec = FrameDecoder()
    got = []
    for i in range(len(data)):
        got += dec.feed(data[i:i + 1])
    assert [f.seq for f in got] == [1, 2, 3, 4, 5]
    assert dec.counters == {"garbage": 0, "oversized": 0, "truncated": 0}


def test_decoder_resynchronizes_after_garbage():
    dec = FrameDecoder()
    frames = dec.feed(b"\x00\xffjunkIPR" + encode_frame(Msg.TIME, 7) + b"xx" + encode_frame(Msg.TIME, 8))
    assert [f.seq for f in frames] == [7, 8]
    assert dec.counters["garbage"] == 2


def test_decoder_skips_an_oversized_frame_exactly():
    dec = FrameDecoder()
    big = encode_frame(Msg.WRITE_ANALOG, 1, b"\x00" * (MAX_PAYLOAD + 10))
    frames = dec.feed(big + encode_frame(Msg.TIME, 2))
    assert [f.seq for f in frames] == [2]
    assert dec.counters["oversized"] == 1


def test_decoder_survives_an_implausible_length():
    dec = FrameDecoder()
    bogus = MAGIC + bytes([1, 2]) + b"\x00\x00" + struct.pack("!II", 3, 0x7FFFFFFF)
    frames = dec.feed(bogus + encode_frame(Msg.TIME, 9))
    assert [f.seq for f in frames] == [9]
    assert dec.counters["oversized"] == 1


def test_decoder_never_raises_on_random_bytes():
    rng = random.Random(1)
    dec = FrameDecoder()
    good = 0
    for k in range(300):
        dec.feed(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 80))))
        frames = dec.feed(encode_frame(Msg.TIME, 1000 + k))
        good += sum(1 for f in frames if f.seq >= 1000)
    # random bytes may swallow a following frame only by forming a plausible header
    assert good >= 250


def test_reader_rejects_short_and_trailing_payloads():
    from ipcosim.fmus.hil.protocol import DecodeError
    r = Reader(pack_channels([0, 1]))
    assert r.channels() == [0, 1]
    r.end()
    with pytest.raises(DecodeError):
        Reader(b"\x00\x05\x00").channels()
    r = Reader(pack_channels([0]) + b"x")
    r.channels()
    with pytest.raises(DecodeError):
        r.end()


# --- the server ------------------------------------------------------------------------------------

@pytest.fixture
def server():
    srv = RigServer(VirtualRig(RigConfig()), "127.0.0.1", 0).start()
    yield srv
    srv.close()


class Raw:
    """A hand-driven protocol client."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.dec = FrameDecoder()

    def send(self, raw: bytes) -> None:
        self.sock.sendall(raw)

    def request(self, msg: int, seq: int, payload: bytes = b"", version: int = PROTOCOL_VERSION):
        self.send(encode_frame(msg, seq, payload, version))
        return self.reply()

    def reply(self):
        while True:
            data = self.sock.recv(65536)
            if not data:
                return None
            frames = self.dec.feed(data)
            if frames:
                f = frames[0]
                code, flags, t_ns = struct.unpack_from("!iIq", f.payload)
                return f, code, f.payload[16:]

    def hello(self, seq: int = 1, role: int = 1):
        return self.request(Msg.HELLO, seq, struct.pack("!B", role) + pack_text("raw test client"))

    def close(self) -> None:
        self.sock.close()


def test_card_over_tcp_reads_what_the_rig_holds(server):
    card = open_card("q4", server.uri)
    assert card.info.plant == "single-mass" and card.info.clock == "lockstep" and card.info.protocol_version == 1
    server.rig.plant.set_state([0.1, 0, 0.2, 0, 0])
    assert list(card.read_encoder([0, 1])) == [round(0.1 / 2.275e-5), round(0.2 / 1.534e-3)]   # nearest count
    card.set_encoder_counts([0, 1], [0, 0])
    assert list(card.read_encoder([0, 1])) == [0, 0]
    card.watchdog_start(0.1)
    assert card.watchdog_reload() is True and card.watchdog_is_expired() is False
    t0 = card.time()
    res = card.step([0], [1.0], [0, 1], t0 + 0.001)
    assert res.reloaded and res.time == pytest.approx(t0 + 0.001)
    with pytest.raises(HILError) as e:
        card.write_analog([9], [0.0])
    assert e.value.code == ErrorCode.BAD_CHANNEL            # the rig's error travels with its code
    card.close()


def test_second_controlling_client_is_refused(server):
    first = open_card("q4", server.uri)
    with pytest.raises(HILError) as e:
        open_card("q4", server.uri)
    assert e.value.code == ErrorCode.BUSY and "busy" in e.value.message
    raw = Raw(server.port)
    f, code, body = raw.hello()
    assert code == ErrorCode.BUSY
    assert raw.sock.recv(10) == b""                           # and the connection is closed
    raw.close()
    assert server.counters["refused"] == 2
    first.read_encoder([0])                                   # the first session is unaffected
    first.close()
    second = open_card("q4", server.uri)                      # free again once the first left
    second.close()


def test_monitor_session_may_watch_but_not_drive(server):
    ctl = open_card("q4", server.uri)
    mon = TcpipCard("q4", server.uri, "127.0.0.1", server.port, role="monitor")
    assert mon.status().amplifier_enabled
    with pytest.raises(HILError) as e:
        mon.write_analog([0], [1.0])
    assert e.value.code == ErrorCode.NOT_CONTROLLER
    with pytest.raises(HILError) as e:
        mon.reset()
    assert e.value.code == ErrorCode.BUSY
    ctl.close()
    mon.reset()                                               # nobody controls the rig: allowed
    mon.close()


def test_wrong_protocol_version_gets_a_clear_refusal(server):
    raw = Raw(server.port)
    f, code, body = raw.request(Msg.HELLO, 1, struct.pack("!B", 1) + pack_text("old client"), version=99)
    assert code == ErrorCode.VERSION
    assert b"version 99" in body
    raw.close()


def test_malformed_oversized_and_out_of_order_messages_are_dropped_and_counted(server):
    raw = Raw(server.port)
    f, code, _ = raw.hello(seq=1)
    assert code == 0
    raw.send(b"\x00\x01garbage bytes\xff")                                        # not a frame
    raw.send(encode_frame(Msg.WRITE_ANALOG, 2, b"\x00\x01\x00"))                  # payload too short
    raw.send(encode_frame(Msg.WRITE_ANALOG, 3, b"\x00" * (MAX_PAYLOAD + 1)))      # oversized
    raw.send(encode_frame(0x7E, 4))                                               # unknown type
    raw.send(encode_frame(Msg.TIME, 5, version=2))                                # other version
    f, code, _ = raw.request(Msg.TIME, 10)                                        # a good one
    assert f.seq == 10 and f.type == Msg.TIME | REPLY_BIT and code == 0
    raw.send(encode_frame(Msg.WRITE_ANALOG, 9, pack_channels([0]) + pack_doubles([5.0])))   # out of order
    raw.send(encode_frame(Msg.WRITE_ANALOG, 10, pack_channels([0]) + pack_doubles([5.0])))  # replayed
    f, code, _ = raw.request(Msg.WRITE_ANALOG, 11, pack_channels([0]) + pack_doubles([1.0]))
    assert f.seq == 11 and code == 0                                               # the session goes on
    assert server.rig.motor_voltage() == pytest.approx(1.0, abs=0.003)             # 5 V never applied
    c = server.counters
    assert c["malformed"] == 4 and c["oversized"] == 1 and c["out_of_order"] == 2
    raw.close()


def test_losing_the_controller_forces_zero_volts(server):
    card = open_card("q4", server.uri)
    card.write_analog([0], [4.0])
    assert server.rig.motor_voltage() == pytest.approx(4.0, abs=0.003)
    card._sock.close()                    # the client vanishes without BYE
    card._sock = None
    for _ in range(200):                  # bounded wait for the server thread to notice
        if server.rig.motor_voltage() == 0.0:
            break
        time.sleep(0.01)
    assert server.rig.motor_voltage() == 0.0
    assert any(e.topic == "session" and "ended" in e.message for e in server.rig.events)


def test_a_stalled_rig_times_out_with_a_clear_error():
    srv = RigServer(VirtualRig(RigConfig()), "127.0.0.1", 0, stall_after_steps=3).start()
    try:
        card = open_card("q4", srv.uri, timeout=0.2)
        for k in range(3):
            card.step([0], [0.0], [0, 1], (k + 1) * 1e-3)
        with pytest.raises(HILError) as e:
            card.step([0], [0.0], [0, 1], 4e-3)
        assert e.value.code == ErrorCode.TIMEOUT and "did not answer STEP" in e.value.message
    finally:
        srv.close()


def test_server_binds_loopback_by_default():
    srv = RigServer(VirtualRig(RigConfig()), port=0)
    assert srv.host == "127.0.0.1"


def test_a_deferred_step_returns_at_once_and_the_next_waits_for_its_sample_instant():
    """``defer_wait``: STEP returns the sample instant's reading as soon as the rig answers, and the next STEP
    is not sent before that instant (the rig's own clock says so: no request of the second step arrives
    before the first one's ``until``); without it, STEP returns at its sample instant (Card.step)."""
    srv = RigServer(VirtualRig(RigConfig(clock="wallclock", pendulum_limit=None, cart_limit=None)),
                    "127.0.0.1", 0).start()
    try:
        card = open_card("q4", srv.uri)
        card.watchdog_start(1.0)
        until = card.time() + 0.2
        card.defer_wait = True
        began = time.monotonic()
        first = card.step([0], [0.5], [0, 1], until)
        assert time.monotonic() - began < 0.15 and first.time < until          # answered before its instant
        second = card.step([0], [0.5], [0, 1], until + 0.001)
        assert second.time >= until and srv.rig.now_ns() >= round(until * 1e9)  # sent after the first's instant
        assert card.last_wait_ns > 0.1e9 and first.late == second.late == 0
        card.defer_wait = False
        until3 = card.time() + 0.05
        third = card.step([0], [0.5], [0, 1], until3)
        assert third.time >= until3 and card.last_wait_ns > 0.02e9              # waited for its own instant
        card.close()
    finally:
        srv.close()
