"""TCP server of the virtual rig (protocol: :mod:`ipcosim.fmus.hil.protocol`).

One thread accepts connections, one thread serves each connection; every request goes
to the :class:`~ipcosim.fmus.hil.rig.VirtualRig` (itself thread-safe). Nothing a client sends
can stop or wedge the server:

* bad input is dropped and counted (``RigServer.counters``); the log gets the first drop of
  a connection and then at most one summary line with counts per ``DROP_LOG_INTERVAL``, and
  the whole log at most 10 lines a second (:class:`RateLimitedLog`: what is held back is
  counted and reported); everything a client sent that reaches the log is escaped;
* an unexpected exception while serving a request becomes an ``INTERNAL`` error reply;
* sessions are leases: a connection that sends no accepted request for ``idle_timeout``
  seconds is closed (a controlling session ends safely with it: 0 V, watchdog stopped);
* at most ``max_connections`` connections; a frame begun must be completed within
  ``io_timeout`` (read timeout) and a reply taken within ``io_timeout`` (write timeout),
  or the connection is dropped;
* every numeric argument is checked by the rig (finite, in range; one request spans at most
  ``MAX_REQUEST_SPAN_NS`` of rig time; watchdog timeouts are capped);
* :meth:`RigServer.close` ends every wait and computation in progress within a fraction
  of a second and leaves the motor at 0 V.

Access: the rig binds loopback by default; any other address needs a shared ``token`` that
every client presents in its HELLO (compared in constant time). See docs/hil.md for the
threat model.
"""
from __future__ import annotations

import collections
import gc
import hmac
import ipaddress
import socket
import struct
import threading
import time
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
    FrameDecoder,
    Msg,
    Reader,
    encode_frame,
    pack_ints,
    pack_text,
    reply_payload,
)
from ipcosim.fmus.hil.rig import NS, VirtualRig
from ipcosim.fmus.params import KINDS

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 18920
DEFAULT_IDLE_TIMEOUT = 5.0        # [s] lease: a connection silent this long is closed
DEFAULT_IO_TIMEOUT = 1.0          # [s] to complete a frame begun / to take a reply
DEFAULT_MAX_CONNECTIONS = 8
DROP_LOG_INTERVAL = 1.0           # [s] at most one drop summary per connection this often
_CLOSE = object()
_ANSWERED = object()
_POLL = 0.1                       # [s] how often a connection thread looks at the stop flag


def _timeval(seconds: float) -> bytes:
    """A ``struct timeval`` for SO_RCVTIMEO / SO_SNDTIMEO."""
    whole = int(seconds)
    return struct.pack("ll", whole, int(round((seconds - whole) * 1e6)))


class RigAccessError(HILError, ValueError):
    """The server would be reachable from other machines without an access token."""


def escape(text: str, limit: int = 80) -> str:
    """Client-sent text made safe for a one-line log: control and non-ASCII characters escaped, length capped."""
    out = text[:limit].encode("unicode_escape").decode("ascii").replace('"', '\\"')
    return out + ("..." if len(text) > limit else "")


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Session:
    def __init__(self, peer: str) -> None:
        self.peer = peer
        self.role: str | None = None      # "control" | "monitor"
        self.last_seq = 0
        self.steps = 0
        self.stalled = False
        self.drops: collections.Counter[str] = collections.Counter()   # not yet logged
        self.drop_logged_at = -1e9


class RateLimitedLog:
    """``log(line)`` passed on at most ``rate`` lines a second on average (bursts of ``burst``);
    lines beyond are counted and reported in one line once lines may pass again.

    Everything the server logs because of what a client did goes through it: a client that
    reconnects in a loop, or several at once, cannot flood the log.
    """

    def __init__(self, log: Callable[[str], None], rate: float = 10.0, burst: int = 30,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._log, self.rate, self.burst, self._clock = log, float(rate), int(burst), clock
        self._tokens = float(burst)
        self._last = clock()
        self.suppressed = 0
        self._lock = threading.Lock()

    def __call__(self, line: str) -> None:
        with self._lock:
            now = self._clock()
            self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
            self._last = now
            if self._tokens < 1.0:
                self.suppressed += 1
                return
            self._tokens -= 1.0
            pending, self.suppressed = self.suppressed, 0
        if pending:
            self._log(f"rig: {pending} log lines suppressed (more than {self.rate:g} a second)")
        self._log(line)


class _WriteTimeout(IpcosimError, Exception):
    """Internal: a client did not take a reply within the write timeout."""


class RigServer:
    """Serve a :class:`VirtualRig` over TCP.

    Parameters
    ----------
    rig : VirtualRig
        The rig to serve (its wallclock is started by :meth:`start`).
    host, port : str, int
        Address to bind (port 0: any free port; see :attr:`address`).
    stall_after_steps : int, optional
        Fault injection for tests: after this many STEP requests of a controlling
        session the server stops answering that session (it keeps reading and dropping).
    log : callable, optional
        ``log(line)`` for one-line notices (sessions, refusals, drops, limit trips).
    token : str, optional
        Shared access token every client must present; required unless ``host`` is loopback.
    idle_timeout : float
        Lease [s]: a connection that sends no accepted request for this long is closed.
    io_timeout : float
        Read and write timeout [s]: to complete a frame begun, and to take a reply.
    max_connections : int
        Connections served at once; more are closed at once (counted as ``refused``).

    Raises
    ------
    ValueError
        A timeout or limit that is not a finite positive number in range.
    """

    def __init__(self, rig: VirtualRig, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 stall_after_steps: int | None = None, log: Callable[[str], None] | None = None,
                 token: str | None = None, idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
                 io_timeout: float = DEFAULT_IO_TIMEOUT, max_connections: int = DEFAULT_MAX_CONNECTIONS) -> None:
        for label, value, hi in (("idle_timeout", idle_timeout, 3600.0), ("io_timeout", io_timeout, 60.0)):
            if not (isinstance(value, (int, float)) and 0 < value <= hi):   # NaN fails too
                raise ValueError(f"rig server {label} = {value}: must be in (0, {hi:g}] s")
        if not (isinstance(max_connections, int) and 1 <= max_connections <= 1024):
            raise ValueError(f"rig server max_connections = {max_connections}: must be 1..1024")
        self.rig = rig
        self.host = host
        self.port = port
        self.stall_after_steps = stall_after_steps
        self._raw_log = log or (lambda line: None)
        self.log = RateLimitedLog(self._raw_log)
        self.token = (token or "").strip() or None
        self.idle_timeout = float(idle_timeout)
        self.io_timeout = float(io_timeout)
        self.max_connections = max_connections
        self.counters: collections.Counter[str] = collections.Counter()
        self._lock = threading.Lock()
        self._controller: _Session | None = None
        self._sock: socket.socket | None = None
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: set[socket.socket] = set()
        self._events_seen = 0

    # --- lifecycle -----------------------------------------------------------------------------

    def start(self) -> "RigServer":
        """Bind, listen and serve in background threads; returns self.

        Raises
        ------
        RigAccessError
            ``host`` is not a loopback address and no token is set.
        HILError
            The address cannot be bound.
        """
        if not is_loopback(self.host) and not self.token:
            raise RigAccessError(ErrorCode.AUTH, f"rig refuses to serve {self.host}: an address other than loopback "
                                                 f"needs an access token (--token-file FILE or IPCOSIM_RIG_TOKEN)")
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise HILError(ErrorCode.CONNECTION, f"rig cannot listen on {self.host}:{self.port}: "
                                                 f"{exc.strerror or exc}") from exc
        sock.listen(16)
        sock.settimeout(_POLL)
        self._sock = sock
        self.port = sock.getsockname()[1]
        self.rig.start_clock()
        t = threading.Thread(target=self._accept_loop, name="rig-accept", daemon=True)
        t.start()
        self._threads.append(t)
        return self

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound."""
        return self.host, self.port

    @property
    def uri(self) -> str:
        """Card id for the tcpip backend, e.g. ``0@tcpip://127.0.0.1:18920``."""
        return f"0@tcpip://{self.host}:{self.port}"

    def serve(self, duration: float | None = None) -> None:
        """Block until :meth:`close` (or ``duration`` seconds), relaying new rig events to ``log``."""
        end = None if duration is None else time.monotonic() + duration
        while not self._stopping.is_set():
            self._relay_events()
            if end is not None and time.monotonic() >= end:
                break
            self._stopping.wait(0.1)

    def request_stop(self) -> None:
        """Make :meth:`serve` return (safe from a signal handler); then call :meth:`close`."""
        self._stopping.set()

    def close(self) -> None:
        """Stop serving: every wait ends, the motor goes to 0 V, connections close, the clock stops.

        Returns within a fraction of a second whatever the clients are doing.
        """
        self._stopping.set()
        self.rig.halt("rig server stopping")
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:
                pass
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        end = time.monotonic() + 0.5
        for t in self._threads:
            t.join(timeout=max(0.0, end - time.monotonic()))
        self.rig.stop_clock()
        self._relay_events(wait=0.2)

    def __enter__(self) -> "RigServer":
        return self if self._sock is not None else self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _relay_events(self, wait: float = 0.05) -> None:
        # never blocks for long: a request may hold the rig (stopping must not wait for it)
        if self.rig.event_count == self._events_seen:
            return      # nothing new: the rig's lock is not touched (a step may be in progress)
        if not self.rig.lock.acquire(timeout=wait):
            return
        try:
            events = list(self.rig.events)
            total = self.rig.event_count
        finally:
            self.rig.lock.release()
        new = min(total - self._events_seen, len(events))
        for ev in events[len(events) - new:] if new > 0 else []:
            # safety events always reach the log; session changes (client-driven) are rate-limited
            log = self.log if ev.topic == "session" else self._raw_log
            log(f"rig t={ev.time:.4f}s {ev.topic}: {escape(ev.message, 400)}")
        self._events_seen = total

    # --- connections ---------------------------------------------------------------------------

    def _accept_loop(self) -> None:
        assert self._sock is not None
        while not self._stopping.is_set():
            try:
                conn, addr = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                break
            peer = f"{addr[0]}:{addr[1]}"
            with self._lock:
                too_many = len(self._conns) >= self.max_connections
                if not too_many:
                    self._conns.add(conn)
            if too_many:
                self.counters["refused"] += 1
                conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # blocking, with the timeouts in the kernel: a request is one read, its reply one write
            conn.settimeout(None)
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, _timeval(_POLL))
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, _timeval(self.io_timeout))
            t = threading.Thread(target=self._serve_connection, args=(conn, peer), name=f"rig-{peer}",
                                 daemon=True)
            t.start()
            self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _serve_connection(self, conn: socket.socket, peer: str) -> None:
        """One client: answer its frames until the connection ends (:meth:`_receive`), then count its
        dropped input, release what it held and close (:meth:`_close_connection`)."""
        decoder = FrameDecoder()
        session = _Session(peer)
        seen = dict(decoder.counters)
        reason = "connection closed"
        try:
            reason = self._receive(conn, session, decoder, seen)
        except _WriteTimeout:
            reason = f"client did not take a reply within {self.io_timeout:g} s"
            self.counters["write_timeouts"] += 1
        finally:
            self._count_decoder_drops(session, decoder, seen)
            self._close_connection(conn, session, reason)

    def _receive(self, conn: socket.socket, session: _Session, decoder: FrameDecoder, seen: dict[str, int]) -> str:
        """Read frames and answer them until the client closes, its lease lapses, the line is lost, the
        session is closed or the server stops; returns why the connection ended. A frame begun and not
        completed within the I/O timeout is discarded."""
        reason = "connection closed"
        last_request = partial_since = time.monotonic()
        while not self._stopping.is_set():
            now = time.monotonic()
            if now - last_request > self.idle_timeout:
                reason = f"no request for {self.idle_timeout:g} s (lease lapsed)"
                self.counters["idle_closed"] += 1
                break
            if decoder.partial and now - partial_since > self.io_timeout:
                decoder.discard_partial()       # read timeout: a frame begun was not completed
            try:
                data = conn.recv(65536)
            except (socket.timeout, BlockingIOError):
                continue
            except OSError as exc:
                reason = f"connection lost: {exc}"
                break
            if not data:
                break
            if not decoder.partial:
                partial_since = time.monotonic()
            frames = decoder.feed(data)
            self._count_decoder_drops(session, decoder, seen)
            answered = self._answer(conn, session, frames)
            if answered is _CLOSE:
                return "session closed"
            if answered is not None:     # an accepted request renews the lease
                last_request = answered
        return "server stopped" if self._stopping.is_set() else reason

    def _answer(self, conn: socket.socket, session: _Session, frames: list[Frame]) -> object:
        """Answer each of ``frames`` (a stalled session's are counted, not answered); returns ``_CLOSE``
        when one closes the session, else when the last request was accepted (None: none was)."""
        accepted = None
        for frame in frames:
            if session.stalled:
                self.counters["stalled_requests"] += 1
                continue
            outcome = self._handle(conn, session, frame)
            if outcome is _CLOSE:
                return _CLOSE
            if outcome is not None:
                accepted = time.monotonic()
        return accepted

    def _close_connection(self, conn: socket.socket, session: _Session, reason: str) -> None:
        """Log the connection's dropped input, end its controlling session (or say it never had one) and
        close it."""
        self._log_drops(session, force=True)
        if session.role == "control":
            self._release(session, f"{session.peer}: {reason}")
        elif session.role is None:
            self.log(f"rig: connection from {session.peer} closed before a session ({reason})")
        with self._lock:
            self._conns.discard(conn)
        try:
            conn.close()
        except OSError:
            pass

    def _count_decoder_drops(self, session: _Session, decoder: FrameDecoder, seen: dict[str, int]) -> None:
        for key, value in decoder.counters.items():
            if value > seen[key]:
                self._note_drop(session, "malformed" if key == "garbage" else key, value - seen[key])
                seen[key] = value

    def _note_drop(self, session: _Session, kind: str, count: int = 1) -> None:
        """Count dropped input; the log gets a summary per connection at most every DROP_LOG_INTERVAL."""
        self.counters[kind] += count
        session.drops[kind] += count
        self._log_drops(session)

    def _log_drops(self, session: _Session, force: bool = False) -> None:
        now = time.monotonic()
        if not session.drops or (not force and now - session.drop_logged_at < DROP_LOG_INTERVAL):
            return
        what = ", ".join(f"{n} {k.replace('_', '-')}" for k, n in sorted(session.drops.items()))
        self.log(f"rig: dropped input from {session.peer}: {what}")
        session.drops.clear()
        session.drop_logged_at = now

    def _release(self, session: _Session, reason: str) -> None:
        with self._lock:
            if self._controller is session:
                self._controller = None
        session.role = "closed"
        self.rig.end_session(reason)
        self.log(f"rig: controlling session ended ({reason}); outputs at their expiration states")
        if not gc.isenabled():
            gc.collect()    # the collector is kept out of sessions (ipcosim rig serve): collect between them

    # --- requests ------------------------------------------------------------------------------

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


#: The handler of each request type but HELLO (``RigServer._hello``, which opens the session): it decodes
#: the request's body, calls the rig and returns the reply body (None: no reply).
_HANDLERS: dict[Msg, Callable[[RigServer, Reader, _Session], object]] = {
    Msg.WRITE_ANALOG: RigServer._write_analog,
    Msg.READ_ENCODER: RigServer._read_encoder,
    Msg.SET_ENCODER_COUNTS: RigServer._set_encoder_counts,
    Msg.WD_SET_EXPIRATION: RigServer._wd_set_expiration,
    Msg.WD_START: RigServer._wd_start,
    Msg.WD_RELOAD: RigServer._wd_reload,
    Msg.WD_IS_EXPIRED: RigServer._wd_is_expired,
    Msg.WD_CLEAR: RigServer._wd_clear,
    Msg.WD_STOP: RigServer._wd_stop,
    Msg.STEP: RigServer._step_request,
    Msg.ADVANCE: RigServer._advance,
    Msg.STATUS: RigServer._status,
    Msg.RESET: RigServer._reset,
    Msg.TIME: RigServer._time,
    Msg.BYE: RigServer._bye,
}
