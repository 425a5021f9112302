"""The rig server against faulty and hostile clients: leases, bounded connections, read and write
timeouts, validated numbers, access tokens, escaped and rate-limited logs, a seeded fuzz test, and
SIGTERM/SIGINT in every state. Servers on 127.0.0.1, any free port; every wait bounded."""
from __future__ import annotations

import math
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from fmi_helpers import wait_for

from ipcosim.fmus.hil import ErrorCode, HILError
from ipcosim.fmus.hil.protocol import HEADER, MAGIC, MAX_PAYLOAD, Msg, encode_frame, pack_channels, pack_text
from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigAccessError, RigServer, escape
from ipcosim.fmus.hil.tcpip import TcpipCard

ROOT = Path(__file__).resolve().parents[2]



@pytest.fixture
def server():
    made = []

    def make(clock: str = "lockstep", **kwargs) -> RigServer:
        lines: list[str] = []
        srv = RigServer(VirtualRig(RigConfig(clock=clock, pendulum_limit=None, cart_limit=None)), "127.0.0.1", 0,
                        log=lines.append, **kwargs).start()
        srv.lines = lines
        made.append(srv)
        return srv
    yield make
    for srv in made:
        srv.close()


def card(srv: RigServer, role: str = "control", name: str = "test", token: str | None = None) -> TcpipCard:
    return TcpipCard("q4", srv.uri, "127.0.0.1", srv.port, role=role, name=name, timeout=2.0, token=token)


def closed_by_peer(sock: socket.socket, limit: float) -> bool:
    sock.settimeout(limit)
    try:
        while True:
            if not sock.recv(4096):
                return True
    except socket.timeout:
        return False
    except OSError:
        return True


# --- leases and connections ------------------------------------------------------------------------

def test_a_client_that_opens_no_session_is_dropped_after_the_idle_timeout(server):
    srv = server(idle_timeout=0.3)
    with socket.create_connection(("127.0.0.1", srv.port)) as s:
        assert closed_by_peer(s, 10.0)
    assert srv.counters["idle_closed"] == 1


def test_a_silent_controller_loses_its_lease_safely_and_a_second_client_can_reset(server):
    srv = server(clock="wallclock", idle_timeout=0.4)
    ctl = card(srv)
    ctl.write_analog([0], [2.0])
    ctl.watchdog_start(5.0)
    assert srv.rig.motor_voltage() == pytest.approx(2.0, abs=0.005)
    mon = card(srv, role="monitor")
    with pytest.raises(HILError) as exc:
        mon.reset()                                         # refused while the controller holds its lease
    assert exc.value.code == ErrorCode.BUSY
    mon.close()
    assert wait_for(lambda: srv.rig.motor_voltage() == 0.0 and not srv.rig.watchdog.running)   # controller silent
    mon = card(srv, role="monitor")
    mon.reset()                                             # the lease lapsed: the operator's reset works
    assert mon.status().amplifier_enabled
    mon.close()
    assert any("lease lapsed" in line for line in srv.lines)
    card(srv).close()                                       # and a new controller may take the rig


def test_connections_are_bounded_and_idle_ones_do_not_block_later_clients(server):
    srv = server(idle_timeout=0.5, max_connections=3)
    idle = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(3)]
    try:
        assert wait_for(lambda: len(srv._conns) == 3)
        with pytest.raises(HILError):
            card(srv)                                       # a fourth is refused at once
        assert srv.counters["refused"] >= 1
        assert all(closed_by_peer(s, 10.0) for s in idle)   # the idle ones lose their lease
        c = card(srv)
        assert c.status().amplifier_enabled
        c.close()
    finally:
        for s in idle:
            s.close()


def test_a_frame_begun_must_be_completed_within_the_read_timeout(server):
    srv = server(io_timeout=0.2, idle_timeout=5.0)
    with socket.create_connection(("127.0.0.1", srv.port)) as s:
        s.sendall(encode_frame(Msg.HELLO, 1, b"\x00" + pack_text("slow"))[:10])   # then stops mid-header
        time.sleep(0.6)
        s.sendall(encode_frame(Msg.HELLO, 2, b"\x00" + pack_text("slow")))
        s.settimeout(5.0)
        reply = s.recv(4096)
    assert reply[:4] == MAGIC and HEADER.unpack_from(reply)[4] == 2
    assert srv.counters["truncated"] == 1


def test_a_client_that_takes_no_replies_is_dropped_after_the_write_timeout(server):
    srv = server(io_timeout=0.3, idle_timeout=30.0)
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", srv.port))
    try:
        s.sendall(encode_frame(Msg.HELLO, 1, b"\x00" + pack_text("deaf")))
        s.settimeout(5.0)
        try:
            for b in range(40):                             # replies pile up: the client never reads
                s.sendall(b"".join(encode_frame(Msg.STATUS, k) for k in range(2 + 4000 * b, 2 + 4000 * (b + 1))))
        except OSError:
            pass                                            # the server closed on us: what we test
        assert wait_for(lambda: srv.counters["write_timeouts"] == 1, 20.0)
        fresh = card(srv, role="monitor")
        assert fresh.status().amplifier_enabled
        fresh.close()
    finally:
        s.close()


# --- numbers -------------------------------------------------------------------------------------

@pytest.mark.parametrize("msg, payload", [
    (Msg.WD_START, struct.pack("!d", math.nan)), (Msg.WD_START, struct.pack("!d", -1.0)),
    (Msg.WD_START, struct.pack("!d", 1e9)), (Msg.ADVANCE, struct.pack("!q", -5)),
    (Msg.ADVANCE, struct.pack("!q", 2**62)),
    (Msg.WRITE_ANALOG, pack_channels([0]) + struct.pack("!d", math.inf)),
    (Msg.WD_SET_EXPIRATION, pack_channels([0]) + struct.pack("!d", math.nan)),
    (Msg.STEP, struct.pack("!qB", 2**62, 1) + pack_channels([0]) + struct.pack("!d", 0.0) + pack_channels([0])),
])
def test_every_numeric_argument_is_checked_with_a_clear_reply(server, msg, payload):
    srv = server()
    c = card(srv)
    t0 = time.monotonic()
    with pytest.raises(HILError) as exc:
        c._request(msg, payload)
    assert exc.value.code == ErrorCode.INVALID_ARGUMENT and time.monotonic() - t0 < 2.0
    assert c.status().amplifier_enabled                     # the session goes on
    c.close()


def test_a_step_far_into_the_future_of_a_wallclock_rig_is_refused_not_waited_for(server):
    srv = server(clock="wallclock")
    c = card(srv)
    with pytest.raises(HILError) as exc:
        c.step([0], [0.0], [0, 1], c.time() + 3600.0)
    assert exc.value.code == ErrorCode.INVALID_ARGUMENT and "more than 10 s" in exc.value.message
    c.close()


@pytest.mark.parametrize("option, value", [("--cart-limit", "-1"), ("--cart-limit", "nan"),
                                           ("--pendulum-limit-deg", "0"), ("--pendulum-limit-deg", "inf"),
                                           ("--idle-timeout", "nan"), ("--tick", "-0.001"), ("--latency", "1e9")])
def test_limits_and_durations_cannot_be_disabled_by_a_bad_value(option, value):
    run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--port", "0", "--duration",
                          "1", option, value], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert run.returncode != 0
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and option in lines[0], run.stderr


# --- access ----------------------------------------------------------------------------------------

def test_other_than_loopback_needs_a_token():
    with pytest.raises(RigAccessError, match="needs an access token"):
        RigServer(VirtualRig(RigConfig()), "0.0.0.0", 0).start()
    run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--host", "0.0.0.0", "--port",
                          "0", "--duration", "1"], capture_output=True, text=True, timeout=60, cwd=ROOT,
                         env={k: v for k, v in os.environ.items() if k != "IPCOSIM_RIG_TOKEN"})
    lines = run.stderr.strip().splitlines()
    assert run.returncode != 0 and len(lines) == 1 and "token" in lines[0], run.stderr


def test_every_client_presents_the_token(server, monkeypatch):
    srv = server(token="s3cret")
    monkeypatch.delenv("IPCOSIM_RIG_TOKEN", raising=False)
    for bad in ("", "wrong"):
        with pytest.raises(HILError) as exc:
            card(srv, role="monitor", token=bad)
        assert exc.value.code == ErrorCode.AUTH
    card(srv, token="s3cret").close()
    monkeypatch.setenv("IPCOSIM_RIG_TOKEN", "s3cret")
    card(srv).close()                                       # from the environment
    assert srv.counters["unauthorized"] == 2


def test_token_file_for_serve_status_and_reset(tmp_path):
    token = tmp_path / "token"
    token.write_text("from-a-file\n")
    env = {k: v for k, v in os.environ.items() if k != "IPCOSIM_RIG_TOKEN"}
    proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--port", "0", "--duration",
                             "60", "--token-file", str(token)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, env=env)
    try:
        line = proc.stdout.readline()
        assert "token required" in line, line
        port = line.split("127.0.0.1:")[1].split()[0]
        cli = [sys.executable, "-m", "ipcosim.harness.cli", "rig", "status", "--port", port]
        denied = subprocess.run(cli, capture_output=True, text=True, timeout=60, cwd=ROOT, env=env)
        assert denied.returncode != 0 and "access token" in denied.stderr
        ok = subprocess.run(cli + ["--token-file", str(token)], capture_output=True, text=True, timeout=60, cwd=ROOT,
                            env=env)
        assert ok.returncode == 0 and "amplifier on" in ok.stdout, ok.stderr
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)


# --- logs ------------------------------------------------------------------------------------------

def test_client_text_is_escaped_in_the_log(server):
    srv = server()
    forged = "evil\nrig: controlling session ended (forged)\r\x1b[2J"
    card(srv, name=forged).close()
    srv._relay_events()
    assert not any(line.startswith("rig: controlling session ended (forged") for line in srv.lines)
    assert all("\n" not in line and "\r" not in line and "\x1b" not in line for line in srv.lines)
    assert any(escape(forged) in line for line in srv.lines)


def test_repeated_drops_are_summarised_with_counts(server):
    srv = server()
    c = card(srv)
    for _ in range(300):
        c._sock.send(encode_frame(Msg.WRITE_ANALOG, 1, b"\x00"))   # replayed sequence number
    c._sock.send(b"junk" * 10)
    assert c.status().amplifier_enabled                              # the session goes on
    c.close()

    def logged() -> int:
        return sum(int(w) for line in srv.lines if "dropped" in line
                   for w, k in zip(line.split()[:-1], line.split()[1:]) if w.isdigit() and k.startswith("out-of-order"))
    assert wait_for(lambda: logged() == 300)                         # every drop counted in the summaries...
    assert 1 <= len([line for line in srv.lines if "dropped" in line]) <= 3   # ... not one line per frame


# --- fuzz ------------------------------------------------------------------------------------------

def _fuzz_frames(rng: random.Random) -> bytes:
    kind = rng.randrange(7)
    seq = rng.randrange(0, 50)
    mtype = rng.choice(list(Msg) + [0x00, 0x7F, 0x8B, 0xFF])
    if kind == 0:
        return rng.randbytes(rng.randrange(1, 200))                               # noise
    if kind == 1:
        return encode_frame(mtype, seq, rng.randbytes(rng.randrange(0, 64)))      # random payload
    if kind == 2:
        return HEADER.pack(MAGIC, 1, mtype, 0, seq, rng.choice([MAX_PAYLOAD + 1, 1 << 20, 2**32 - 1])) + \
            rng.randbytes(rng.randrange(0, 300))                                  # oversized
    if kind == 3:
        frame = encode_frame(mtype, seq, rng.randbytes(rng.randrange(0, 64)))
        return frame[:rng.randrange(1, len(frame))]                               # truncated
    if kind == 4:
        return encode_frame(Msg.HELLO, seq, bytes([rng.randrange(2)]) + pack_text(rng.randbytes(8).hex()),
                            version=rng.choice([1, 1, 2, 255]))                   # hellos, other versions
    if kind == 5:
        return encode_frame(rng.choice([Msg.ADVANCE, Msg.WD_START, Msg.STEP]), seq,
                            struct.pack("!q", rng.choice([-1, 0, 2**62, -2**63])) + rng.randbytes(rng.randrange(9)))
    return encode_frame(rng.choice([Msg.RESET, Msg.BYE, Msg.STATUS, Msg.TIME]), seq)   # out of order, mostly


def _fuzz_client(port: int, seed: int, until: float, sent: list[int]) -> None:
    rng = random.Random(seed)
    while time.monotonic() < until:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
                s.settimeout(0.05)
                for _ in range(rng.randrange(1, 60)):
                    s.sendall(_fuzz_frames(rng))
                    sent[0] += 1
                    if rng.random() < 0.2:
                        try:
                            s.recv(65536)
                        except (socket.timeout, BlockingIOError):
                            pass
                    if time.monotonic() >= until:
                        break
        except OSError:
            time.sleep(0.01)                                # refused or dropped: try again


def test_fuzzing_clients_cannot_stop_the_server_answering_a_well_behaved_one(server):
    srv = server(idle_timeout=1.0, io_timeout=0.3, max_connections=8)
    good = card(srv, name="well-behaved")                   # holds the rig; a lockstep controller
    good.watchdog_start(1.0)
    until = time.monotonic() + 3.0
    sent = [0]
    fuzzers = [threading.Thread(target=_fuzz_client, args=(srv.port, seed, until, sent), daemon=True)
               for seed in range(4)]
    for t in fuzzers:
        t.start()
    steps = 0
    t = 0.0
    started = time.monotonic()
    while time.monotonic() < until:
        t += 1e-3
        res = good.step([0], [0.5], [0, 1], t)              # raises (fails the test) if not answered in 2 s
        assert res.reloaded
        steps += 1
        time.sleep(0.002)
    for th in fuzzers:
        th.join(timeout=10.0)
    assert steps > 100 and sent[0] > 100
    assert srv.rig.time() == pytest.approx(t, abs=1e-9)       # every step was applied, nothing else moved the rig
    dropped = sum(srv.counters[k] for k in ("malformed", "oversized", "truncated", "out_of_order"))
    assert dropped > 0 and srv.counters["internal_errors"] == 0
    good.close()
    # the log was not flooded: at most the limiter's burst and rate, plus its summaries of what it held back
    limit = srv.log.burst + srv.log.rate * (time.monotonic() - started)
    assert len([line for line in srv.lines if "suppressed" not in line]) <= limit


def test_the_log_is_rate_limited_and_says_how_many_lines_it_held_back():
    from ipcosim.fmus.hil.server import RateLimitedLog

    now = [0.0]
    lines: list[str] = []
    log = RateLimitedLog(lines.append, rate=10.0, burst=5, clock=lambda: now[0])
    for k in range(50):
        log(f"line {k}")
    assert lines == [f"line {k}" for k in range(5)]
    now[0] += 0.1                                          # one more line may pass
    log("later")
    assert lines[5:] == ["rig: 45 log lines suppressed (more than 10 a second)", "later"]


# --- stopping ----------------------------------------------------------------------------------------

def _serve(*extra: str) -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--port", "0",
                             "--duration", "120", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)
    line = proc.stdout.readline()
    assert "card id" in line, line + proc.stderr.read()
    return proc, int(line.split("127.0.0.1:")[1].split()[0])


def _into_state(state: str, port: int) -> object:
    """Put a served rig into ``state``; returns what must stay referenced."""
    if state == "idle":
        return None
    if state == "no-session":
        return socket.create_connection(("127.0.0.1", port))
    c = TcpipCard("q4", f"0@tcpip://127.0.0.1:{port}", "127.0.0.1", port, timeout=2.0)
    c.write_analog([0], [2.0])
    c.watchdog_start(5.0)
    req = (struct.pack("!qB", int((c.time() + 9.0) * 1e9), 1) + pack_channels([0]) + struct.pack("!d", 2.0)
           + pack_channels([0])) if state == "waiting-step" else struct.pack("!q", int(9.9e9))
    c._seq += 1                                             # the rig is now busy: a 9 s wait or computation
    c._sock.send(encode_frame(Msg.STEP if state == "waiting-step" else Msg.ADVANCE, c._seq, req))
    time.sleep(0.3)
    return c


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_and_sigint_stop_the_server_in_every_state_with_the_motor_at_zero(sig):
    states = {"idle": (), "no-session": (), "waiting-step": ("--clock", "wallclock"),
              "long-advance": ("--clock", "lockstep", "--tick", "1e-5")}
    procs = {state: _serve(*extra) for state, extra in states.items()}
    held = {state: _into_state(state, port) for state, (_, port) in procs.items()}
    took = {}
    try:
        for state, (proc, _) in procs.items():
            t0 = time.monotonic()
            proc.send_signal(sig)
            _, err = proc.communicate(timeout=30)
            took[state] = time.monotonic() - t0
            assert proc.returncode == 0, err
            assert "motor at +0.000 V" in err.strip().splitlines()[-1], err
    finally:            # a rig that did not stop is not left serving after the test
        for proc, _ in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    for obj in held.values():
        if obj is not None:
            obj.close()
    print({k: f"{v * 1e3:.0f} ms" for k, v in took.items()})
    assert max(took.values()) < 5.0                          # generous here; the figures are printed


def test_a_stop_asked_from_a_signal_handler_takes_no_lock_its_serving_loop_may_hold(server):
    """SIGTERM's handler runs on the main thread, which may be at the instant ``serve``'s wait holds its
    Event's lock (each time it wakes): a ``request_stop`` that took that lock waited for itself for ever (a
    rig that outlived its duration and ignored every later signal). Held here on purpose, it must not block,
    and ``serve`` then returns at once."""
    import threading

    srv = server()
    asked = threading.Thread(target=lambda: (srv._stopping._cond.acquire(), srv.request_stop()), daemon=True)
    asked.start()
    asked.join(timeout=5)
    blocked = asked.is_alive()
    srv._stopping._cond.release()       # (a plain lock: released here, a blocked call goes on)
    asked.join(timeout=5)
    assert not blocked, "request_stop blocked on the lock the serving loop holds"
    began = time.monotonic()
    srv.serve(duration=30)
    assert time.monotonic() - began < 1.0
