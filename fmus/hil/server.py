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

The server, one idea to a module:

    server_log       what it logs of its clients: their text escaped, the lines rate-limited
    server_requests  its answers: each request checked, passed to the rig and its reply encoded
    server           (this module) its connections: listening, a thread per client, leases, timeouts
"""
from __future__ import annotations

import collections
import gc
import ipaddress
import socket
import struct
import threading
import time
from typing import Callable

from ipcosim.fmus.hil.api import ErrorCode, HILError
from ipcosim.fmus.hil.protocol import Frame, FrameDecoder
from ipcosim.fmus.hil.rig import VirtualRig
from ipcosim.fmus.hil.server_log import RateLimitedLog, escape
from ipcosim.fmus.hil.server_requests import _CLOSE, RigRequests, _Session, _WriteTimeout

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 18920
DEFAULT_IDLE_TIMEOUT = 5.0        # [s] lease: a connection silent this long is closed
DEFAULT_IO_TIMEOUT = 1.0          # [s] to complete a frame begun / to take a reply
DEFAULT_MAX_CONNECTIONS = 8
DROP_LOG_INTERVAL = 1.0           # [s] at most one drop summary per connection this often
_POLL = 0.1                       # [s] how often a connection thread looks at the stop flag


def _timeval(seconds: float) -> bytes:
    """A ``struct timeval`` for SO_RCVTIMEO / SO_SNDTIMEO."""
    whole = int(seconds)
    return struct.pack("ll", whole, int(round((seconds - whole) * 1e6)))


class RigAccessError(HILError, ValueError):
    """The server would be reachable from other machines without an access token."""


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class RigServer(RigRequests):
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
        self._stop_asked = False        # set by request_stop (a signal handler): a plain flag, no lock
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
        while not (self._stop_asked or self._stopping.is_set()):
            self._relay_events()
            if end is not None and time.monotonic() >= end:
                break
            self._stopping.wait(0.1)

    def request_stop(self) -> None:
        """Make :meth:`serve` return within 0.1 s; then call :meth:`close`.

        Safe from a signal handler: it sets a plain flag and takes no lock. (``Event.set`` takes the lock
        that :meth:`serve`'s ``Event.wait`` holds for an instant each time it wakes; a handler run in that
        instant, on the same thread, waited for itself for ever.)
        """
        self._stop_asked = True

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


__all__ = ["RigServer", "RigAccessError", "RateLimitedLog", "escape", "is_loopback", "DEFAULT_HOST", "DEFAULT_PORT",
           "DEFAULT_IDLE_TIMEOUT", "DEFAULT_IO_TIMEOUT", "DEFAULT_MAX_CONNECTIONS", "DROP_LOG_INTERVAL"]
