"""``tcpip`` backend: a :class:`Card` on a virtual rig served by ``ipcosim rig serve``.

Card id ``N@tcpip://HOST:PORT`` (e.g. ``0@tcpip://127.0.0.1:18920``). Every call is one
request/reply exchange of :mod:`ipcosim.fmus.hil.protocol`; a reply that does not come within
``timeout`` seconds raises ``HILError(TIMEOUT)`` naming the request. The socket blocks with its
timeouts in the kernel (``SO_RCVTIMEO``, ``SO_SNDTIMEO``) and ``TCP_NODELAY``: a request is one
write, its reply (as a rule) one read. A wall-clock rig answers a STEP at once with the reading
at its sample instant; :meth:`TcpipCard.step` reads the reply and then waits on the host for that
instant, as a card's own step does.

The rig's clock is reckoned from bounds, as a network time client does: a reply stamped ``t`` by the
rig, to a request sent at host time ``s`` and read at ``r``, says the rig's clock is between
``t - r`` and ``t - s`` ahead of the host's (:class:`ClockOffset`). A reply read late (the client
preempted between its arrival and the read) only loosens its own lower bound: it never dates the
rig's clock by the read, as reckoning from the last reply's stamp plus the host time since did.
"""
from __future__ import annotations

import numbers
import os
import socket
import struct
import time
import weakref
from typing import Sequence

from ipcosim.fmus.hil.api import (
    Card,
    CardInfo,
    ErrorCode,
    HILError,
    RigStatus,
    StepResult,
    as_channels,
    as_finite,
    policy_spin_ns,
    wait_until_ns,
)
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
    MAX_TOKEN,
    PROTOCOL_VERSION,
    REPLY_BIT,
    REPLY_PREFIX,
    STATUS_REPLY,
    STEP_REPLY,
    STEP_REQUEST,
    TOKEN_ENV,
    WD_START_REQUEST,
    DecodeError,
    FrameDecoder,
    Msg,
    Reader,
    encode_frame,
    pack_channels,
    pack_doubles,
    pack_ints,
    pack_text,
)
from ipcosim.fmus.params import KINDS

NS = 1_000_000_000
#: How long before a sample instant :meth:`TcpipCard.step` stops sleeping and reads the clock [ns], under any
#: policy (more under a real-time one, :func:`~ipcosim.fmus.hil.api.policy_spin_ns`): without it, a wait
#: that sleeps to the instant made 12 to 26 % of a quiet host's walkthrough steps late.
WAIT_SPIN_NS = 50_000

#: How fast the rig's clock may drift from the host's [parts per million]: the bounds on their offset
#: widen this fast as they age (a rig on the same host: not at all; a crystal: tens of ppm).
DRIFT_PPM = 100

#: Open tcpip cards of this process (diagnostics and fault-injection tests).
OPEN_CARDS: "weakref.WeakSet[TcpipCard]" = weakref.WeakSet()


class TcpipCard(Card):
    """Client of a virtual rig.

    Parameters
    ----------
    card_type, card_id : str
        As given to :func:`ipcosim.fmus.hil.open_card` (for messages).
    host, port : str, int
        The rig's address.
    timeout : float
        Seconds to wait for a reply (beyond the sample instant, for STEP on a wallclock rig).
    role : str
        ``control`` (default) or ``monitor`` (status, time and reset only).
    name : str
        Client name shown in the rig's log.
    token : str, optional
        The rig's shared access token (default: the ``IPCOSIM_RIG_TOKEN`` environment variable).
    """

    #: The rig leases the session: a client that stays silent longer than the rig's idle timeout
    #: is dropped (the HIL adapter therefore connects again when stepping begins).
    leased = True
    #: False: :meth:`step` returns at its sample instant, as :meth:`Card.step <ipcosim.fmus.hil.api.Card.step>`
    #: says. True: it returns with the reading at once (the rig computes the sample instant's reading
    #: exactly when the request comes) and the wait for that instant moves to the start of the next
    #: :meth:`step`, so no request is ever sent before the last one's sample instant. The adapter FMU
    #: steps so: a host that paces to the wall clock (``ipcosim run --realtime``) then does not wait
    #: twice for one instant, and a host that does not pace is held back at its next ``doStep``.
    defer_wait = False

    def __init__(self, card_type: str, card_id: str, host: str, port: int, *, timeout: float = 1.0,
                 role: str = "control", name: str = "ipcosim", token: str | None = None) -> None:
        self.card_type, self.card_id = card_type, card_id
        self.where = f"tcpip://{host}:{port}"
        self.timeout = float(timeout)
        self._seq = 0
        self._decoder = FrameDecoder()
        self.stale_replies = 0
        self._sock: socket.socket | None = None
        self._last_rig_ns = 0
        self._sent_ns = 0
        self.offset = ClockOffset()
        self._step_channels: dict[tuple, tuple[int, bytes, bytes]] = {}
        self.last_flags = 0
        #: Requests made (each one round trip).
        self.requests = 0
        #: How long the last :meth:`step` waited for its sample instant [ns].
        self.last_wait_ns = 0
        self._applied_timeout = 0.0
        self._deferred_ns: int | None = None     # the last sample instant, with defer_wait
        try:
            sock = socket.create_connection((host, port), timeout=max(self.timeout, 2.0))
        except OSError as exc:
            raise HILError(ErrorCode.CONNECTION, f"cannot connect to the virtual rig at {self.where}: "
                                                 f"{exc.strerror or exc} (is `ipcosim rig serve` running?)") from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(None)
        self._sock = sock
        try:
            if token is None:
                token = os.environ.get(TOKEN_ENV, "")
            r = self._request(Msg.HELLO, HELLO_REQUEST.pack(1 if role == "control" else 0) + pack_text(name, 200)
                              + pack_text(token.strip(), MAX_TOKEN), timeout=max(self.timeout, 2.0))
            plant, clock, n_ao, n_enc, bits, cpr, lo, hi, tick_ns, version = r.take(HELLO_REPLY)
        except HILError:
            self._abort()
            raise
        self.info = CardInfo(card_type=card_type, card_id=card_id, analog_outputs=n_ao, encoder_inputs=n_enc,
                             dac_bits=bits, analog_min=lo, analog_max=hi, counts_per_rev=cpr,
                             clock="lockstep" if clock == 0 else "wallclock", tick=tick_ns / NS,
                             plant=KINDS[plant] if plant < len(KINDS) else "", protocol_version=version)
        OPEN_CARDS.add(self)

    # --- transport -----------------------------------------------------------------------------

    def _abort(self) -> None:
        OPEN_CARDS.discard(self)
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:
                pass
            self._sock = None

    def _set_timeout(self, seconds: float) -> None:
        """The socket's read and write timeouts (set only when they change: no call per request)."""
        seconds = max(seconds, 1e-3)          # 0 would mean no timeout
        if seconds != self._applied_timeout and self._sock is not None:
            whole = int(seconds)
            tv = struct.pack("ll", whole, int(round((seconds - whole) * 1e6)))
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
            self._applied_timeout = seconds

    def _request(self, msg: Msg, payload: bytes = b"", timeout: float | None = None) -> Reader:
        """One round trip: send ``msg``, then wait for its reply (see :meth:`_send`, :meth:`_receive`)."""
        return self._receive(msg, *self._send(msg, payload, timeout))

    def _send(self, msg: Msg, payload: bytes = b"", timeout: float | None = None) -> tuple[int, float]:
        """Send one request; returns its sequence number and the reply's time limit [s]."""
        if self._sock is None:
            raise HILError(ErrorCode.NOT_OPEN, f"card {self.card_id} is closed")
        self._seq += 1
        self.requests += 1
        seq = self._seq
        limit = self.timeout if timeout is None else timeout
        self._set_timeout(limit)
        self._sent_ns = time.monotonic_ns()
        try:
            self._sock.sendall(encode_frame(msg, seq, payload))
        except (socket.timeout, BlockingIOError):
            raise HILError(ErrorCode.TIMEOUT, f"the virtual rig at {self.where} does not take data") from None
        except OSError as exc:
            self._abort()
            raise HILError(ErrorCode.CONNECTION, f"lost the virtual rig at {self.where} sending {msg.name}: "
                                                 f"{exc.strerror or exc}") from exc
        return seq, limit

    def _receive(self, msg: Msg, seq: int, limit: float) -> Reader:
        """The reply to request ``seq`` (``msg``), within ``limit`` seconds of now."""
        assert self._sock is not None
        self._set_timeout(limit)
        deadline = time.monotonic() + limit
        while True:
            try:
                data = self._sock.recv(65536)
            except (socket.timeout, BlockingIOError):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise HILError(ErrorCode.TIMEOUT, f"the virtual rig at {self.where} did not answer "
                                                      f"{msg.name} (seq {seq}) within {limit:g} s") from None
                self._set_timeout(remaining)
                continue
            except OSError as exc:
                self._abort()
                raise HILError(ErrorCode.CONNECTION, f"lost the virtual rig at {self.where} waiting for "
                                                     f"{msg.name}: {exc.strerror or exc}") from exc
            if not data:
                self._abort()
                raise HILError(ErrorCode.CONNECTION, f"the virtual rig at {self.where} closed the connection "
                                                     f"(waiting for {msg.name})")
            for frame in self._decoder.feed(data):
                if frame.seq != seq or frame.type != (msg | REPLY_BIT):
                    self.stale_replies += 1
                    continue
                return self._parse_reply(msg, frame.payload)

    def rig_now_ns(self) -> int:
        """The rig's clock [ns] as this host reckons it (:class:`ClockOffset`)."""
        now = time.monotonic_ns()
        return now + self.offset.at(now)

    def _parse_reply(self, msg: Msg, payload: bytes) -> Reader:
        r = Reader(payload)
        try:
            code, flags, t_ns = r.take(REPLY_PREFIX)
            self.last_flags = flags
            self._last_rig_ns = t_ns
            self.offset.update(t_ns, self._sent_ns, time.monotonic_ns())
            if code != 0:
                message = r.text()
                if msg == Msg.HELLO:
                    self._abort()       # a refused session: the rig closes the connection
                raise HILError(code, f"virtual rig at {self.where}: {message}")
        except DecodeError as exc:
            raise HILError(ErrorCode.PROTOCOL, f"malformed {msg.name} reply from {self.where}: {exc}") from exc
        return r

    def _body(self, r: Reader, fmt: str | struct.Struct, msg: str) -> tuple:
        try:
            return r.take(fmt)
        except DecodeError as exc:
            raise HILError(ErrorCode.PROTOCOL, f"malformed {msg} reply from {self.where}: {exc}") from exc

    # --- the card API --------------------------------------------------------------------------

    def write_analog(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        ch = as_channels(channels, "analog output")
        self._request(Msg.WRITE_ANALOG, pack_channels(ch) + pack_doubles(as_finite(volts, len(ch), "write_analog")))

    def read_encoder(self, channels: Sequence[int]) -> list[int]:
        ch = as_channels(channels, "encoder")
        r = self._request(Msg.READ_ENCODER, pack_channels(ch))
        (n,) = self._body(r, COUNT, "READ_ENCODER")
        return list(self._body(r, f"{n}i", "READ_ENCODER"))  # int32 on the wire

    def set_encoder_counts(self, channels: Sequence[int], counts: Sequence[int]) -> None:
        ch = as_channels(channels, "encoder")
        if isinstance(counts, numbers.Integral):
            counts = [int(counts)] * len(ch)
        counts = [int(c) for c in counts]
        if len(counts) != len(ch):
            raise HILError(ErrorCode.INVALID_ARGUMENT, f"set_encoder_counts: {len(counts)} counts for "
                                                       f"{len(ch)} channels")
        self._request(Msg.SET_ENCODER_COUNTS, pack_channels(ch) + pack_ints(counts))

    def watchdog_set_analog_expiration_state(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        ch = as_channels(channels, "analog output")
        self._request(Msg.WD_SET_EXPIRATION,
                      pack_channels(ch) + pack_doubles(as_finite(volts, len(ch), "expiration state")))

    def watchdog_start(self, timeout: float) -> None:
        self._request(Msg.WD_START, WD_START_REQUEST.pack(float(timeout)))

    def watchdog_reload(self) -> bool:
        return bool(self._body(self._request(Msg.WD_RELOAD), FLAG_REPLY, "WD_RELOAD")[0])

    def watchdog_is_expired(self) -> bool:
        return bool(self._body(self._request(Msg.WD_IS_EXPIRED), FLAG_REPLY, "WD_IS_EXPIRED")[0])

    def watchdog_clear(self) -> None:
        self._request(Msg.WD_CLEAR)

    def watchdog_stop(self) -> None:
        self._request(Msg.WD_STOP)

    def time(self) -> float:
        self._request(Msg.TIME)
        return self._last_rig_ns / NS

    def advance(self, dt: float) -> None:
        """Lockstep rig: advance by ``dt`` seconds."""
        self._request(Msg.ADVANCE, ADVANCE_REQUEST.pack(int(round(dt * NS))))

    def step(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
             until: float, reload: bool = True) -> StepResult:
        n_ao, ao_packed, enc_packed = self._packed_channels(analog_channels, encoder_channels)
        self.last_wait_ns = 0
        if self._deferred_ns is not None:    # not before the last request's sample instant
            self._wait_for(self._deferred_ns)
            self._deferred_ns = None
        until_ns = int(round(until * NS))
        payload = (STEP_REQUEST.pack(until_ns, 1 if reload else 0) + ao_packed
                   + pack_doubles(as_finite(volts, n_ao, "step")) + enc_packed)
        r = self._request(Msg.STEP, payload)
        reloaded, late_ns, n = self._body(r, STEP_REPLY, "STEP")
        counts = list(self._body(r, f"{n}i", "STEP"))  # int32 on the wire
        now = self._last_rig_ns
        if self.info.clock == "wallclock" and self.defer_wait:
            self._deferred_ns = until_ns
        elif self.info.clock == "wallclock":   # the reading is the sample instant's: not before it
            now = max(now, self._wait_for(until_ns))
        return StepResult(counts=counts, reloaded=bool(reloaded), time=now / NS, late=late_ns / NS,
                          status=self._flags_status())

    def _packed_channels(self, analog_channels: Sequence[int], encoder_channels: Sequence[int]
                         ) -> tuple[int, bytes, bytes]:
        """A STEP's channels checked and packed: (analog outputs, their bytes, the encoders' bytes), once for
        each set of channels a run steps with."""
        try:
            key = (tuple(analog_channels), tuple(encoder_channels))
            packed = self._step_channels.get(key)
        except TypeError:           # not sequences of hashable numbers: as_channels says what is wrong
            key, packed = None, None
        if packed is None:
            ao = as_channels(analog_channels, "analog output")
            packed = (len(ao), pack_channels(ao), pack_channels(as_channels(encoder_channels, "encoder")))
            if key is not None:
                self._step_channels[key] = packed
        return packed

    def _wait_for(self, until_ns: int) -> int:
        """Wait until the rig's clock reaches ``until_ns`` (adding the time to :attr:`last_wait_ns`);
        returns the rig's clock then [ns]."""
        began = time.monotonic_ns()
        offset = self.offset.at(began)        # for the wait: its bounds widen 0.1 us a millisecond
        now = wait_until_ns(lambda: time.monotonic_ns() + offset, until_ns,
                            spin_ns=max(WAIT_SPIN_NS, policy_spin_ns()))
        self.last_wait_ns += time.monotonic_ns() - began
        return now

    def _flags_status(self) -> RigStatus:
        f = self.last_flags
        return RigStatus(amplifier_enabled=bool(f & FLAG_AMPLIFIER), limit_tripped=bool(f & FLAG_LIMIT),
                         watchdog_expired=bool(f & FLAG_WD_EXPIRED), watchdog_running=bool(f & FLAG_WD_RUNNING),
                         time=self._last_rig_ns / NS)

    def status(self) -> RigStatus:
        r = self._request(Msg.STATUS)
        try:
            volts, last, expired_at = r.take(STATUS_REPLY)
            message = r.text()
            (k,) = r.take(COUNT)
            counters = {}
            for _ in range(k):
                name = r.text()
                counters[name] = r.one(COUNTER_VALUE)
        except DecodeError as exc:
            raise HILError(ErrorCode.PROTOCOL, f"malformed STATUS reply from {self.where}: {exc}") from exc
        st = self._flags_status()
        st.limit_message = message
        st.motor_voltage = volts
        counters["wd_last_reload_ns"] = last
        counters["wd_expired_at_ns"] = expired_at
        st.counters = counters
        return st

    def reset(self) -> None:
        """The operator's reset of the virtual rig (clears a limit latch)."""
        self._request(Msg.RESET)

    def close(self) -> None:
        if self._sock is None:
            return
        try:
            self._request(Msg.BYE, timeout=min(self.timeout, 0.5))
        except HILError:
            pass
        self._abort()


class ClockOffset:
    """How far the rig's clock is ahead of the host's [ns], from the bounds each reply gives.

    A reply stamped ``t_ns`` (rig clock) to a request sent at ``sent_ns`` and read at ``read_ns``
    (host clock) bounds the offset: ``t_ns - read_ns <= offset <= t_ns - sent_ns``. The tightest
    lower and upper bound are kept, each widened by :data:`DRIFT_PPM` of its age. The rig answers at
    once, so the upper bound is tight (a request's way there, renewed by every reply), while a reply
    read late (the client preempted before its read) gives a loose lower bound: the offset is the upper
    bound less half the shortest round trip seen (a request's way there, as near as the link tells),
    never below the lower bound.
    Bounds that no longer overlap (the rig's clock jumped) give way to the newest reply's.
    """

    def __init__(self) -> None:
        self.low = self.high = 0
        self._low_at = self._high_at = 0
        self.shortest_round_trip = 0
        self._known = False

    def _bounds(self, now_ns: int) -> tuple[int, int]:
        return (self.low - (now_ns - self._low_at) * DRIFT_PPM // 1_000_000,
                self.high + (now_ns - self._high_at) * DRIFT_PPM // 1_000_000)

    def update(self, t_ns: int, sent_ns: int, read_ns: int) -> None:
        """Take the bounds of one reply (see the class)."""
        low, high = t_ns - read_ns, t_ns - sent_ns
        if self._known:
            was_low, was_high = self._bounds(read_ns)
            if max(low, was_low) <= min(high, was_high):          # consistent: the tighter bound of each
                take_low, take_high = low > was_low, high < was_high
            else:                                                # the rig's clock jumped: the newest reply's
                take_low = take_high = True
            self.shortest_round_trip = min(self.shortest_round_trip, read_ns - sent_ns)
        else:
            take_low = take_high = self._known = True
            self.shortest_round_trip = read_ns - sent_ns
        if take_low:
            self.low, self._low_at = low, read_ns
        if take_high:
            self.high, self._high_at = high, read_ns

    def at(self, now_ns: int) -> int:
        """The offset [ns] reckoned at host time ``now_ns``."""
        low, high = self._bounds(now_ns)
        return max(low, high - self.shortest_round_trip // 2)


__all__ = ["TcpipCard", "ClockOffset", "PROTOCOL_VERSION"]
