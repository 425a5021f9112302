"""The rig server's answers: each request of the wire protocol (:mod:`ipcosim.fmus.hil.protocol`) checked
(its version, its sequence number, the session's role), HELLO opening a session (the access token, one
controlling client at a time), every other request decoded by its handler (``_HANDLERS``: the protocol's
requests in one table, docs/hil.md), passed to the rig and its reply encoded. The connections these
requests come in on, their leases and dropped input are :class:`~ipcosim.fmus.hil.server.RigServer`'s.
"""
from __future__ import annotations

import collections
import hmac
import socket
import threading
from typing import Callable

from ipcosim.errors import IpcosimError
from ipcosim.fmus.hil.api import ErrorCode, HILError
from ipcosim.fmus.hil.protocol import (
    ADVANCE_REQUEST,
    COUNT,
    COUNTER_VALUE,
    FLAG_AMPLIFIER,
    FLAG_LIMIT,
    FLAG_REPLY,
    FLAG_WD_EXPIRED,
    FLAG_WD_RUNNING,
    HELLO_REPLY,
    HELLO_REQUEST,
    PROTOCOL_VERSION,
    REPLY_BIT,
    STATUS_REPLY,
    STEP_REPLY,
    STEP_REQUEST,
    WD_START_REQUEST,
    DecodeError,
    Frame,
    Msg,
    Reader,
    encode_frame,
    pack_ints,
    pack_text,
    reply_payload,
)
from ipcosim.fmus.hil.rig import VirtualRig
from ipcosim.fmus.hil.rig_config import NS
from ipcosim.fmus.hil.server_log import escape
from ipcosim.fmus.params import KINDS

_CLOSE = object()
_ANSWERED = object()


class _Session:
    def __init__(self, peer: str) -> None:
        self.peer = peer
        self.role: str | None = None      # "control" | "monitor"
        self.last_seq = 0
        self.steps = 0
        self.stalled = False
        self.drops: collections.Counter[str] = collections.Counter()   # not yet logged
        self.drop_logged_at = -1e9


class _WriteTimeout(IpcosimError, Exception):
    """Internal: a client did not take a reply within the write timeout."""


class RigRequests:
    """The requests' side of :class:`~ipcosim.fmus.hil.server.RigServer` (see the module docstring): it
    answers on the server's rig, counters, log, token and controlling session; a dropped frame is counted by
    the server's ``_note_drop``, a released session ends by its ``_release``."""

    rig: VirtualRig
    counters: collections.Counter[str]
    log: Callable[[str], None]
    token: str | None
    stall_after_steps: int | None
    _lock: threading.Lock
    _controller: _Session | None

    def _send(self, conn: socket.socket, frame: Frame, code: int, body: bytes = b"", message: str = "") -> None:
        """One reply: the rig's flags and clock as they stand (nothing is computed for them), one write."""
        rig = self.rig
        with rig.lock:
            amplifier, limit, expired, running = rig.flags()
            now = rig.now_ns()
        flags = ((FLAG_AMPLIFIER if amplifier else 0) | (FLAG_LIMIT if limit else 0)
                 | (FLAG_WD_EXPIRED if expired else 0) | (FLAG_WD_RUNNING if running else 0))
        try:
            conn.sendall(encode_frame(frame.type | REPLY_BIT, frame.seq,
                                      reply_payload(code, flags, now, body, message)))
        except (socket.timeout, BlockingIOError):
            raise _WriteTimeout() from None
        except OSError:
            pass  # the receive loop notices the loss

    def _drop(self, counter: str, session: _Session, frame: Frame, why: str) -> None:
        self._note_drop(session, counter)

    def _handle(self, conn: socket.socket, session: _Session, frame: Frame) -> object:
        if frame.version != PROTOCOL_VERSION:
            if frame.type == Msg.HELLO and session.role is None:
                self.counters["version"] += 1
                self._send(conn, frame, ErrorCode.VERSION,
                           message=f"protocol version {frame.version} not supported; this rig speaks version "
                                   f"{PROTOCOL_VERSION}")
                return _CLOSE
            self._drop("malformed", session, frame, f"protocol version {frame.version}")
            return None
        if frame.type & REPLY_BIT or frame.type not in Msg._value2member_map_:
            self._drop("malformed", session, frame, "unknown message type")
            return None
        if frame.seq <= session.last_seq:
            self._drop("out_of_order", session, frame, f"sequence number not above {session.last_seq}")
            return None
        msg = Msg(frame.type)
        reader = Reader(frame.payload)
        try:
            if session.role is None and msg != Msg.HELLO:
                session.last_seq = frame.seq
                self._send(conn, frame, ErrorCode.NOT_CONTROLLER, message="the first request must be HELLO")
                return None
            if msg == Msg.HELLO:
                return self._hello(conn, session, frame, reader)
            if session.role == "monitor" and msg not in (Msg.STATUS, Msg.TIME, Msg.RESET, Msg.BYE):
                session.last_seq = frame.seq
                self._send(conn, frame, ErrorCode.NOT_CONTROLLER,
                           message=f"{msg.name} needs the controlling session; this is a monitor session")
                return None
            body = self._dispatch(msg, reader, session)
        except DecodeError as exc:
            self._drop("malformed", session, frame, str(exc))
            return None
        except HILError as exc:
            session.last_seq = frame.seq
            self._send(conn, frame, exc.code, message=exc.message)
            return None
        except Exception as exc:  # noqa: BLE001 -- the server never crashes on a request
            session.last_seq = frame.seq
            self.counters["internal_errors"] += 1
            self._send(conn, frame, ErrorCode.INTERNAL, message=f"rig internal error: {type(exc).__name__}: {exc}")
            return None
        if body is _CLOSE:
            return _CLOSE
        if body is None:  # stalled: no reply
            return None
        session.last_seq = frame.seq
        self._send(conn, frame, ErrorCode.OK, body)
        if msg == Msg.BYE:
            return _CLOSE
        return _ANSWERED

    def _hello(self, conn: socket.socket, session: _Session, frame: Frame, reader: Reader) -> object:
        role_code = reader.one(HELLO_REQUEST)
        name = escape(reader.text())
        token = reader.text() if reader.pos < len(reader.data) else ""
        reader.end()
        session.last_seq = frame.seq
        if session.role is not None:
            self._send(conn, frame, ErrorCode.PROTOCOL, message="HELLO twice in one connection")
            return None
        if self.token is not None and not hmac.compare_digest(token.encode("utf-8"), self.token.encode("utf-8")):
            self.counters["unauthorized"] += 1
            self.log(f"rig: refused {session.peer} ({name}): {'wrong' if token else 'no'} access token")
            self._send(conn, frame, ErrorCode.AUTH, message="access token missing or wrong (this rig needs the "
                                                            "token it was started with: IPCOSIM_RIG_TOKEN)")
            return _CLOSE
        role = "control" if role_code else "monitor"
        if role == "control":
            with self._lock:
                holder = self._controller
                if holder is None:
                    self._controller = session
            if holder is not None:
                self.counters["refused"] += 1
                self.log(f"rig: refused {session.peer} ({name}): rig busy, controlled by {holder.peer}")
                self._send(conn, frame, ErrorCode.BUSY,
                           message=f"rig busy: it is controlled by {holder.peer}; one controlling client at a "
                                   f"time")
                return _CLOSE
            self.rig.new_session(f"{name} at {session.peer}")
            self.log(f"rig: controlling session opened by {name} at {session.peer}")
        session.role = role
        info = self.rig.info()
        body = HELLO_REPLY.pack(KINDS.index(info.plant), 0 if info.clock == "lockstep" else 1,
                                info.analog_outputs, info.encoder_inputs, info.dac_bits, info.counts_per_rev,
                                info.analog_min, info.analog_max, int(round(info.tick * NS)), PROTOCOL_VERSION)
        self._send(conn, frame, ErrorCode.OK, body)
        return _ANSWERED

    def _dispatch(self, msg: Msg, r: Reader, session: _Session) -> object:
        """Decode one request's body, call the rig and encode the reply body (None: do not answer), by
        the handler of its message type (``_HANDLERS``: the protocol's requests in one table, docs/hil.md)."""
        handler = _HANDLERS.get(msg)
        if handler is None:
            raise DecodeError(f"unhandled message {msg.name}")
        return handler(self, r, session)

    def _write_analog(self, r: Reader, session: _Session) -> bytes:
        ch = r.channels()
        v = r.doubles(len(ch))
        r.end()
        self.rig.write_analog(ch, v)
        return b""

    def _read_encoder(self, r: Reader, session: _Session) -> bytes:
        ch = r.channels()
        r.end()
        counts = self.rig.read_encoder(ch)
        return COUNT.pack(len(counts)) + pack_ints([int(c) for c in counts])

    def _set_encoder_counts(self, r: Reader, session: _Session) -> bytes:
        ch = r.channels()
        n = r.ints(len(ch))
        r.end()
        self.rig.set_encoder_counts(ch, n)
        return b""

    def _wd_set_expiration(self, r: Reader, session: _Session) -> bytes:
        ch = r.channels()
        v = r.doubles(len(ch))
        r.end()
        self.rig.watchdog_set_analog_expiration_state(ch, v)
        return b""

    def _wd_start(self, r: Reader, session: _Session) -> bytes:
        (timeout,) = r.take(WD_START_REQUEST)
        r.end()
        self.rig.watchdog_start(timeout)
        return b""

    def _wd_reload(self, r: Reader, session: _Session) -> bytes:
        r.end()
        return FLAG_REPLY.pack(1 if self.rig.watchdog_reload() else 0)

    def _wd_is_expired(self, r: Reader, session: _Session) -> bytes:
        r.end()
        return FLAG_REPLY.pack(1 if self.rig.watchdog_is_expired() else 0)

    def _wd_clear(self, r: Reader, session: _Session) -> bytes:
        r.end()
        self.rig.watchdog_clear()
        return b""

    def _wd_stop(self, r: Reader, session: _Session) -> bytes:
        r.end()
        self.rig.watchdog_stop()
        return b""

    def _step_request(self, r: Reader, session: _Session) -> bytes | None:
        until, reload = r.take(STEP_REQUEST)
        ao = r.channels()
        volts = r.doubles(len(ao))
        enc = r.channels()
        r.end()
        return self._step(session, ao, volts, enc, until, bool(reload))

    def _advance(self, r: Reader, session: _Session) -> bytes:
        (dt,) = r.take(ADVANCE_REQUEST)
        r.end()
        if dt < 0:
            raise HILError(ErrorCode.INVALID_ARGUMENT, f"advance: dt = {dt} ns must be >= 0")
        self.rig.advance(dt / NS)
        return b""

    def _status(self, r: Reader, session: _Session) -> bytes:
        r.end()
        return self._status_body()

    def _reset(self, r: Reader, session: _Session) -> bytes:
        r.end()
        with self._lock:
            holder = self._controller
        if holder is not None and holder is not session:
            raise HILError(ErrorCode.BUSY, f"reset refused: the rig is controlled by {holder.peer}")
        self.rig.reset()
        self.log(f"rig: operator reset by {session.peer}")
        return b""

    def _time(self, r: Reader, session: _Session) -> bytes:
        r.end()
        return b""

    def _bye(self, r: Reader, session: _Session) -> bytes:
        r.end()
        if session.role == "control":   # release before replying: the client may reconnect at once
            self._release(session, f"{session.peer}: BYE")
        return b""

    def _step(self, session: _Session, ao: list[int], volts: list[float], enc: list[int], until: int,
              reload: bool) -> bytes | None:
        """STEP: write the voltages, advance the rig to ``until`` [ns] and read the encoders; the
        reply is (reloaded, lateness [ns], counts). With ``stall_after_steps`` (fault injection),
        None once the session has had that many steps: the request is left unanswered."""
        session.steps += 1
        if self.stall_after_steps is not None and session.steps > self.stall_after_steps:
            session.stalled = True
            self.counters["stalled_requests"] += 1
            self.log(f"rig: fault injection: no longer answering {session.peer} "
                     f"(after {self.stall_after_steps} steps)")
            return None
        reloaded, late, counts = self.rig.exchange(ao, volts, enc, until, reload)
        return STEP_REPLY.pack(1 if reloaded else 0, late, len(counts)) + pack_ints(counts)

    def _status_body(self) -> bytes:
        """STATUS: motor voltage, watchdog times [ns] (-1: none), the limit message and the rig's
        and server's counters by name."""
        rig = self.rig
        st = rig.status()
        with rig.lock:
            last = rig.watchdog.last_reload_ns if rig.watchdog.last_reload_ns is not None else -1
            expired_at = rig.watchdog.expired_at_ns if rig.watchdog.expired_at_ns is not None else -1
        counters = {**{f"rig.{k}": v for k, v in st.counters.items()},
                    **{f"server.{k}": v for k, v in self.counters.items()}}
        body = STATUS_REPLY.pack(st.motor_voltage, last, expired_at) + pack_text(st.limit_message)
        body += COUNT.pack(len(counters))
        for k, v in sorted(counters.items()):
            body += pack_text(k, 200) + COUNTER_VALUE.pack(int(v))
        return body


#: The handler of each request type but HELLO (``RigRequests._hello``, which opens the session): it decodes
#: the request's body, calls the rig and returns the reply body (None: no reply).
_HANDLERS: dict[Msg, Callable[[RigRequests, Reader, _Session], object]] = {
    Msg.WRITE_ANALOG: RigRequests._write_analog,
    Msg.READ_ENCODER: RigRequests._read_encoder,
    Msg.SET_ENCODER_COUNTS: RigRequests._set_encoder_counts,
    Msg.WD_SET_EXPIRATION: RigRequests._wd_set_expiration,
    Msg.WD_START: RigRequests._wd_start,
    Msg.WD_RELOAD: RigRequests._wd_reload,
    Msg.WD_IS_EXPIRED: RigRequests._wd_is_expired,
    Msg.WD_CLEAR: RigRequests._wd_clear,
    Msg.WD_STOP: RigRequests._wd_stop,
    Msg.STEP: RigRequests._step_request,
    Msg.ADVANCE: RigRequests._advance,
    Msg.STATUS: RigRequests._status,
    Msg.RESET: RigRequests._reset,
    Msg.TIME: RigRequests._time,
    Msg.BYE: RigRequests._bye,
}
