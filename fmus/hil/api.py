"""The HIL card interface: volts and counts, mirroring the Quanser HIL API.

A :class:`Card` is what a controller sees of a data-acquisition card (the Quanser Q4 of
the IP02 lab): analog outputs in volts, 32-bit encoder counters, a watchdog timer. The
methods follow the Quanser HIL API (``quanser.hardware.HIL``) one to one, with Python
sequences instead of (channel array, count, buffer) triples:

=====================================  ============================================
Quanser HIL API                        :class:`Card`
=====================================  ============================================
``HIL(card_type, card_id)``            :func:`ipcosim.fmus.hil.open_card`
``write_analog(ch, n, volts)``         ``write_analog(channels, volts)``
``read_encoder(ch, n, counts)``        ``read_encoder(channels) -> int32 counts``
``set_encoder_counts(ch, n, counts)``  ``set_encoder_counts(channels, counts)``
``watchdog_set_analog_expiration_      ``watchdog_set_analog_expiration_state(
state(ch, n, volts)``                  channels, volts)``
``watchdog_start(timeout)``            ``watchdog_start(timeout)``
``watchdog_reload() -> bool``          ``watchdog_reload() -> bool``
``watchdog_is_expired() -> bool``      ``watchdog_is_expired() -> bool``
``watchdog_clear()``                   ``watchdog_clear()``
``watchdog_stop()``                    ``watchdog_stop()``
``close()``                            ``close()``
``HILError`` (error code, message)     :class:`HILError` (``code``, ``message``)
=====================================  ============================================

Two additions serve sample-synchronous co-simulation and are not in the Quanser API:

* :meth:`Card.time` -- the card's clock [s]: the host's monotonic clock for a real card,
  the rig's clock for the virtual rig (simulated time in ``lockstep`` mode).
* :meth:`Card.step` -- one sample period: reload the watchdog, write the analog outputs
  now, let the card's clock run to a given instant and read the encoders at that instant.
  On a real card this is write / wait / read on the host clock (what a hardware-timed
  QUARC model does); the virtual rig does it in one request, and in ``lockstep`` mode
  "let the clock run" means "advance the simulation", so a co-simulation step of ``h``
  advances the rig by exactly ``h``.

Watchdog semantics (as on the Q4): once started, the watchdog must be reloaded within
its timeout; when it expires the analog outputs are forced to their expiration states
and the card refuses further writes (:attr:`ErrorCode.WATCHDOG_EXPIRED`) until
:meth:`Card.watchdog_clear`. ``watchdog_stop`` stops the timer without clearing an
expiry.
"""
from __future__ import annotations

import enum
import math
import numbers
import os
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

from ipcosim.errors import IpcosimError


class ErrorCode(enum.IntEnum):
    """Error codes of :class:`HILError` (the virtual rig's wire protocol carries them too)."""

    OK = 0
    BUSY = 1                 #: another client controls the rig
    VERSION = 2              #: protocol version mismatch
    BAD_CHANNEL = 3          #: channel number out of range
    INVALID_ARGUMENT = 4     #: non-finite volts, negative timeout, mismatched lengths ...
    WATCHDOG_EXPIRED = 5     #: write refused: the watchdog expired and was not cleared
    TIMEOUT = 6              #: the card did not answer in time
    CONNECTION = 7           #: cannot connect / connection lost
    NOT_OPEN = 8             #: the card is closed
    BACKEND_MISSING = 9      #: the backend's package is not installed
    PROTOCOL = 10            #: malformed or unexpected reply
    NOT_CONTROLLER = 11      #: operation needs the controlling session
    CLOCK = 12               #: a sample instant in the past of a lockstep rig
    LIMIT_TRIPPED = 13       #: a safety limit latched the amplifier off
    BAD_URI = 14             #: malformed card URI
    INTERNAL = 15            #: the rig failed internally (e.g. non-finite plant state)
    AUTH = 16                #: missing or wrong access token


class HILError(IpcosimError, RuntimeError):
    """A card operation failed; carries a numeric ``code`` (:class:`ErrorCode`) and a ``message``.

    Mirrors ``quanser.hardware.HILError`` (``error_code``, ``get_error_message()``).
    """

    def __init__(self, code: int, message: str) -> None:
        self.code = int(code)
        self.message = str(message)
        super().__init__(self.message)

    @property
    def error_code(self) -> int:
        """Alias of ``code`` (the Quanser name)."""
        return self.code

    @property
    def code_name(self) -> str:
        """Symbolic name of the code (``TIMEOUT``...) or the number as text."""
        try:
            return ErrorCode(self.code).name
        except ValueError:
            return str(self.code)

    def get_error_message(self) -> str:
        """The message (the Quanser name)."""
        return self.message

    def __str__(self) -> str:
        return f"{self.message} [HIL error {self.code_name}]"


@dataclass(frozen=True)
class CardInfo:
    """What a card tells about itself on opening."""

    card_type: str
    card_id: str
    analog_outputs: int
    encoder_inputs: int
    dac_bits: int = 12
    analog_min: float = -10.0
    analog_max: float = 10.0
    counts_per_rev: int = 4096
    clock: str = "wallclock"        #: ``lockstep`` (simulated time) or ``wallclock``
    tick: float = 0.0               #: the card clock's grid [s] (0: continuous)
    plant: str = ""                 #: virtual rig only: ``single-mass`` / ``double-mass``
    protocol_version: int = 0       #: tcpip backend: the rig's protocol version


@dataclass
class StepResult:
    """Outcome of :meth:`Card.step`."""

    counts: Sequence[int]            #: int32 counts, one per encoder channel asked for
    reloaded: bool                   #: watchdog_reload()'s result (True if it had not expired)
    time: float                      #: card time of the sample [s]
    late: float = 0.0                #: how far the card's clock was past the sample instant on arrival [s]
    status: "RigStatus | None" = None


@dataclass
class RigStatus:
    """Safety status of a card (for a real card only the watchdog fields are known)."""

    amplifier_enabled: bool = True
    limit_tripped: bool = False
    watchdog_expired: bool = False
    watchdog_running: bool = False
    limit_message: str = ""
    time: float = 0.0
    motor_voltage: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)


def as_channels(channels: Sequence[int] | int, what: str = "channels") -> list[int]:
    """Channel numbers as a list of non-negative ints.

    Raises
    ------
    HILError
        ``BAD_CHANNEL`` for a negative or non-integer channel.
    """
    if isinstance(channels, numbers.Integral):
        channels = [int(channels)]
    out = []
    for c in channels:
        if type(c) is not int and (isinstance(c, bool) or not isinstance(c, numbers.Integral)) or c < 0:
            raise HILError(ErrorCode.BAD_CHANNEL, f"{what}: channel {c!r} is not a non-negative integer")
        out.append(int(c))
    return out


def as_finite(values: Sequence[float] | float, n: int, what: str) -> list[float]:
    """``n`` finite floats (a scalar is broadcast)."""
    if isinstance(values, numbers.Real):
        values = [float(values)] * n
    values = [float(v) for v in values]
    if len(values) != n:
        raise HILError(ErrorCode.INVALID_ARGUMENT, f"{what}: {len(values)} values for {n} channels")
    for v in values:
        if not math.isfinite(v):
            raise HILError(ErrorCode.INVALID_ARGUMENT, f"{what}: value {v} is not finite")
    return values


INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1


def wrap_int32(value: int) -> int:
    """A count wrapped like a 32-bit two's-complement hardware counter."""
    return ((int(value) - INT32_MIN) % (1 << 32)) + INT32_MIN


def count_difference(new: int, old: int) -> int:
    """Signed difference of two 32-bit counter readings, correct across one wrap-around."""
    return wrap_int32(int(new) - int(old))


#: How long before a deadline a wait stops sleeping and reads the clock, under a real-time policy [ns].
RT_SPIN_NS = 200_000


def policy_spin_ns() -> int:
    """:data:`RT_SPIN_NS` when this thread runs under a real-time policy (SCHED_FIFO or SCHED_RR), else 0.

    The OS wakes a sleeper tens of microseconds late, so a real-time process spins the rest (it takes
    no one's share). Under the default policy a spin is paid for: a 1 kHz loop that spins 0.2 ms a step
    spends its fair share of a CPU beside a busy neighbour and is then woken behind it, milliseconds late
    (docs/hil.md, "What a host must give").
    """
    try:
        return RT_SPIN_NS if os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR) else 0
    except (AttributeError, OSError):     # no scheduling policies on this OS
        return 0


def wait_until_ns(clock_ns: Callable[[], int], deadline_ns: int, spin_ns: int | None = None,
                  abort: Callable[[], bool] = lambda: False) -> int:
    """Sleep (in slices of at most 1 ms), then spin, until ``clock_ns() >= deadline_ns`` or ``abort()``.

    Sleeping ends ``spin_ns`` before the deadline (default: :func:`policy_spin_ns`); the rest is spent
    reading the clock. Returns the clock at the end.
    """
    if spin_ns is None:
        spin_ns = policy_spin_ns()
    now = clock_ns()
    while deadline_ns - now > spin_ns and not abort():
        time.sleep(min(deadline_ns - now - spin_ns, 1_000_000) / 1e9)
        now = clock_ns()
    while now < deadline_ns and not abort():
        now = clock_ns()
    return now


class Card:
    """Base class of the backends; see the module docstring for the semantics.

    Subclasses implement the ``_``-free methods below; :meth:`step` and :meth:`time` have
    host-clock defaults suitable for real hardware.
    """

    info: CardInfo

    # --- the Quanser HIL API -----------------------------------------------------------------

    def write_analog(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        """Set analog outputs [V] (quantized by the DAC)."""
        raise NotImplementedError

    def read_encoder(self, channels: Sequence[int]) -> Sequence[int]:
        """Encoder counts (int32) of ``channels``."""
        raise NotImplementedError

    def set_encoder_counts(self, channels: Sequence[int], counts: Sequence[int]) -> None:
        """Load encoder counters with ``counts`` (usually 0: zero the encoders)."""
        raise NotImplementedError

    def watchdog_set_analog_expiration_state(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        """Voltages the analog outputs are forced to when the watchdog expires."""
        raise NotImplementedError

    def watchdog_start(self, timeout: float) -> None:
        """Start the watchdog with ``timeout`` [s]."""
        raise NotImplementedError

    def watchdog_reload(self) -> bool:
        """Reload the watchdog; ``False`` if it had already expired."""
        raise NotImplementedError

    def watchdog_is_expired(self) -> bool:
        """Whether the watchdog expired (and was not cleared)."""
        raise NotImplementedError

    def watchdog_clear(self) -> None:
        """Clear an expiry: writes are accepted again."""
        raise NotImplementedError

    def watchdog_stop(self) -> None:
        """Stop the watchdog timer (an expiry stays until cleared)."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the card (idempotent)."""
        raise NotImplementedError

    # --- additions for sample-synchronous co-simulation ----------------------------------------

    def time(self) -> float:
        """The card's clock [s] (default: the host's monotonic clock)."""
        return time.monotonic()

    def status(self) -> RigStatus:
        """Safety status (default: the watchdog's state only)."""
        return RigStatus(watchdog_expired=self.watchdog_is_expired(), time=self.time())

    def step(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
             until: float, reload: bool = True) -> StepResult:
        """One sample period: reload the watchdog, write now, wait for card time ``until``, read.

        Parameters
        ----------
        analog_channels, volts : sequence
            Outputs to write immediately.
        encoder_channels : sequence of int
            Encoders to read at ``until``.
        until : float
            Card time [s] of the sample instant.
        reload : bool
            Reload the watchdog first.

        Returns
        -------
        StepResult
        """
        reloaded = self.watchdog_reload() if reload else True
        self.write_analog(analog_channels, volts)
        now = self.time()
        late = max(0.0, now - until)
        remaining = until - now
        if remaining > 0.002:
            time.sleep(remaining - 0.001)
        while self.time() < until:
            pass
        counts = self.read_encoder(encoder_channels)
        return StepResult(counts=counts, reloaded=reloaded, time=self.time(), late=late)

    def __enter__(self) -> "Card":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
