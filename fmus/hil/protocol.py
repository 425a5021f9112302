"""Wire protocol of the virtual rig, version 1 (``tcpip`` backend <-> ``ipcosim rig serve``).

Transport: one TCP connection per client; the rig binds 127.0.0.1 unless told otherwise.
Every message is a frame: a 16-byte header, then ``length`` bytes of payload. All
integers and floats are big-endian (network order); floats are IEEE-754 doubles.

Header (``!4sBBHII``)::

    magic    4 bytes  b"IPRG"
    version  u8       PROTOCOL_VERSION (1)
    type     u8       message type (requests < 0x80; a reply is request type | 0x80)
    flags    u16      0 (reserved)
    seq      u32      sequence number: a client numbers its requests 1, 2, 3 ... (strictly
                      increasing within a connection); a reply carries its request's number
    length   u32      payload size in bytes, at most MAX_PAYLOAD (4096)

Every reply payload starts with ``!iIq``: error code (``ipcosim.fmus.hil.api.ErrorCode``, 0 =
OK), status flags (bit 0 amplifier enabled, 1 limit tripped, 2 watchdog expired, 3
watchdog running) and the rig's time in nanoseconds. On error a UTF-8 message follows
(``!H`` length + bytes); on success the type's reply body.

Requests (``n`` = ``!H`` count, ``ch`` = n x ``!I`` channels, ``V`` = n x ``!d`` volts,
``N`` = n x ``!i`` counts):

====  ====================  =============================  ==========================
type  name                  request payload                reply body
====  ====================  =============================  ==========================
0x01  HELLO                 role u8 (1 control, 0 monitor), plant u8 (0 single, 1
                            name: ``!H`` + UTF-8,           double), clock u8 (0 lockstep,
                            [token: ``!H`` + UTF-8]
                                                            1 wallclock), n_ao u8, n_enc
                                                            u8, dac_bits u8, counts/rev
                                                            u32, ao min d, ao max d, tick
                                                            ns q, version u16
0x02  WRITE_ANALOG          n ch V                          --
0x03  READ_ENCODER          n ch                            n N
0x04  SET_ENCODER_COUNTS    n ch N                          --
0x05  WD_SET_EXPIRATION     n ch V                          --
0x06  WD_START              timeout d [s]                   --
0x07  WD_RELOAD             --                              reloaded u8
0x08  WD_IS_EXPIRED         --                              expired u8
0x09  WD_CLEAR              --                              --
0x0A  WD_STOP               --                              --
0x0B  STEP                  until q [ns], reload u8,        reloaded u8, late q [ns],
                            n ch V (outputs), n ch          n N
                            (encoders)
0x0C  ADVANCE               dt q [ns] (lockstep)            --
0x0D  STATUS                --                              motor volts d, last reload q,
                                                            expired at q (-1 = none),
                                                            limit message (!H + UTF-8),
                                                            counters: !H k, k x (!H name,
                                                            !q value)
0x0E  RESET                 --                              -- (the operator's reset)
0x0F  TIME                  --                              -- (time is in every reply)
0x10  BYE                   --                              -- (session ends cleanly)
====  ====================  =============================  ==========================

Session rules: the first request of a connection is HELLO; a rig started with an access
token answers a HELLO without the right token with an AUTH error and closes the
connection. Sessions are leases: a connection that sends no accepted request for the
rig's idle timeout (a few seconds) is closed, and a controlling session ends with it. One controlling session at
a time: a second HELLO with role control gets a BUSY error reply and the connection is
closed. Monitor sessions may only ask STATUS, TIME and (when nobody controls the rig)
RESET. The rig drops -- without a reply -- and counts: bytes that are not a frame
(it resynchronizes on the next magic), frames of another protocol version (except a
HELLO, answered with a VERSION error), oversized frames (payload > MAX_PAYLOAD; the
payload is skipped), payloads that do not decode for their type, and requests whose
sequence number is not above the last accepted one (out of order or replayed). The
session goes on after any of these. When a controlling connection ends (BYE, close or
loss) the rig forces its outputs to their watchdog expiration states (0 V).
"""
from __future__ import annotations

import enum
import functools
import struct
from typing import NamedTuple, Sequence

from ipcosim.errors import IpcosimError

PROTOCOL_VERSION = 1
MAGIC = b"IPRG"
HEADER = struct.Struct("!4sBBHII")
HEADER_SIZE = HEADER.size
MAX_PAYLOAD = 4096
MAX_TOKEN = 256             # bytes of an access token
TOKEN_ENV = "IPCOSIM_RIG_TOKEN"
MAX_SKIP = 1 << 20          # oversized frames up to this size are skipped exactly; beyond: resync
REPLY_BIT = 0x80
REPLY_PREFIX = struct.Struct("!iIq")

# The fixed parts of the messages, one named struct each (the table above; counts, channel lists,
# values and texts follow them as ``!H`` n + n items). Both ends pack and unpack with these.
#: HELLO request: role u8 (1 control, 0 monitor); then the name and the optional token (texts).
HELLO_REQUEST = struct.Struct("!B")
#: HELLO reply: plant, clock, n_ao, n_enc, dac_bits (u8), counts/rev (u32), ao min, ao max (d), tick [ns] (q),
#: protocol version (u16).
HELLO_REPLY = struct.Struct("!BBBBBIddqH")
#: WD_START request: the watchdog timeout [s].
WD_START_REQUEST = struct.Struct("!d")
#: WD_RELOAD and WD_IS_EXPIRED reply: reloaded / expired u8.
FLAG_REPLY = struct.Struct("!B")
#: STEP request: until [ns], reload u8; then the output channels and volts, the encoder channels.
STEP_REQUEST = struct.Struct("!qB")
#: STEP reply: reloaded u8, lateness [ns], count n; then n encoder counts.
STEP_REPLY = struct.Struct("!BqH")
#: ADVANCE request: dt [ns] (lockstep).
ADVANCE_REQUEST = struct.Struct("!q")
#: STATUS reply: motor volts, last reload [ns], expired at [ns] (-1 = none); then the limit message, the
#: counter count k and k x (name, COUNTER_VALUE).
STATUS_REPLY = struct.Struct("!dqq")
#: One counter's value in the STATUS reply.
COUNTER_VALUE = struct.Struct("!q")
#: A count n (of channels, encoder counts or counters) before the n items.
COUNT = struct.Struct("!H")

FLAG_AMPLIFIER = 1
FLAG_LIMIT = 2
FLAG_WD_EXPIRED = 4
FLAG_WD_RUNNING = 8


class Msg(enum.IntEnum):
    """Request types."""

    HELLO = 0x01
    WRITE_ANALOG = 0x02
    READ_ENCODER = 0x03
    SET_ENCODER_COUNTS = 0x04
    WD_SET_EXPIRATION = 0x05
    WD_START = 0x06
    WD_RELOAD = 0x07
    WD_IS_EXPIRED = 0x08
    WD_CLEAR = 0x09
    WD_STOP = 0x0A
    STEP = 0x0B
    ADVANCE = 0x0C
    STATUS = 0x0D
    RESET = 0x0E
    TIME = 0x0F
    BYE = 0x10


class DecodeError(IpcosimError, ValueError):
    """A payload that does not decode for its message type."""


class Frame(NamedTuple):
    """One received frame (a named tuple: one is made for every request)."""

    version: int
    type: int
    flags: int
    seq: int
    payload: bytes


def encode_frame(msg_type: int, seq: int, payload: bytes = b"", version: int = PROTOCOL_VERSION) -> bytes:
    """Header + payload."""
    return HEADER.pack(MAGIC, version, msg_type, 0, seq & 0xFFFFFFFF, len(payload)) + payload


class FrameDecoder:
    """Incremental frame parser that never raises on bad input.

    Feed it bytes as they arrive; it returns complete frames and counts what it dropped
    in ``counters`` (``garbage`` resynchronizations, ``oversized`` frames).
    """

    def __init__(self, max_payload: int = MAX_PAYLOAD) -> None:
        self.max_payload = max_payload
        self._buf = bytearray()
        self._skip = 0
        self._in_garbage = False
        self.counters: dict[str, int] = {"garbage": 0, "oversized": 0, "truncated": 0}

    @property
    def partial(self) -> bool:
        """True while part of a frame (or of a payload being skipped) waits for more bytes."""
        return bool(self._buf) or self._skip > 0

    def discard_partial(self) -> None:
        """Drop an incomplete frame (its sender stopped in the middle: a read timeout); counted."""
        if self.partial:
            self._buf.clear()
            self._skip = 0
            self._in_garbage = False
            self.counters["truncated"] += 1

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return the frames now complete."""
        self._buf += data
        frames: list[Frame] = []
        buf = self._buf
        while True:
            if self._skip:
                n = min(self._skip, len(buf))
                del buf[:n]
                self._skip -= n
                if self._skip:
                    break
            if len(buf) < len(MAGIC):
                if buf and not MAGIC.startswith(bytes(buf)):
                    self._garbage(len(buf))
                break
            if buf[:4] != MAGIC:
                i = buf.find(MAGIC, 1)
                if i < 0:
                    # keep a tail that may be the start of the next magic
                    keep = next((k for k in (3, 2, 1) if bytes(buf[-k:]) == MAGIC[:k]), 0)
                    self._garbage(len(buf) - keep)
                    break
                self._garbage(i)
                continue
            if len(buf) < HEADER_SIZE:
                break
            _, version, mtype, flags, seq, length = HEADER.unpack_from(buf)
            if length > self.max_payload:
                self.counters["oversized"] += 1
                if length <= MAX_SKIP:
                    del buf[:HEADER_SIZE]
                    self._skip = length
                else:
                    del buf[:1]      # implausible length: treat the header as garbage
                    self._in_garbage = True
                continue
            if len(buf) < HEADER_SIZE + length:
                break
            payload = bytes(buf[HEADER_SIZE:HEADER_SIZE + length])
            del buf[:HEADER_SIZE + length]
            self._in_garbage = False
            frames.append(Frame(version, mtype, flags, seq, payload))
        return frames

    def _garbage(self, n: int) -> None:
        if n <= 0:
            return
        del self._buf[:n]
        if not self._in_garbage:
            self.counters["garbage"] += 1
            self._in_garbage = True


@functools.lru_cache(maxsize=256)
def network_struct(fmt: str) -> struct.Struct:
    """The struct of a format in network order (``"2I"`` -> ``!2I``), made once: every request of a
    session has the same channel counts."""
    return struct.Struct("!" + fmt)


class Reader:
    """Sequential payload decoder raising :class:`DecodeError` on short or trailing data."""

    def __init__(self, payload: bytes) -> None:
        self.data = payload
        self.pos = 0

    def take(self, fmt: str | struct.Struct) -> tuple:
        """The next values: of a message's named struct, or of a format (network order implied)."""
        s = fmt if isinstance(fmt, struct.Struct) else network_struct(fmt)
        if self.pos + s.size > len(self.data):
            raise DecodeError(f"payload too short for {s.format.removeprefix('!')!r} at byte {self.pos}")
        out = s.unpack_from(self.data, self.pos)
        self.pos += s.size
        return out

    def one(self, fmt: str | struct.Struct):  # noqa: ANN201 -- any scalar
        return self.take(fmt)[0]

    def text(self) -> str:
        n = self.one(COUNT)
        if self.pos + n > len(self.data):
            raise DecodeError("string runs past the payload")
        raw = self.data[self.pos:self.pos + n]
        self.pos += n
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DecodeError(f"string is not UTF-8: {exc}") from None

    def channels(self, limit: int = 64) -> list[int]:
        n = self.one(COUNT)
        if n > limit:
            raise DecodeError(f"{n} channels (at most {limit})")
        return list(self.take(f"{n}I")) if n else []

    def doubles(self, n: int) -> list[float]:
        return list(self.take(f"{n}d")) if n else []

    def ints(self, n: int) -> list[int]:
        return list(self.take(f"{n}i")) if n else []

    def end(self) -> None:
        if self.pos != len(self.data):
            raise DecodeError(f"{len(self.data) - self.pos} trailing bytes")


def pack_text(text: str, limit: int = 1024) -> bytes:
    raw = text.encode("utf-8")[:limit]
    return COUNT.pack(len(raw)) + raw


def pack_channels(channels: Sequence[int]) -> bytes:
    return struct.pack(f"!H{len(channels)}I", len(channels), *channels)


def pack_doubles(values: Sequence[float]) -> bytes:
    return struct.pack(f"!{len(values)}d", *values)


def pack_ints(values: Sequence[int]) -> bytes:
    return struct.pack(f"!{len(values)}i", *values)


def reply_payload(code: int, flags: int, time_ns: int, body: bytes = b"", message: str = "") -> bytes:
    """Reply payload: the common prefix, then the body (OK) or the message (error)."""
    prefix = REPLY_PREFIX.pack(int(code), flags, time_ns)
    return prefix + (body if code == 0 else pack_text(message))
