"""The virtual IP02 rig: the plant physics behind a model of the Q4 card, the amplifier and the lab.

One source of truth: the motion is :class:`ipcosim.fmus.plant.Plant` (the same object the plant
FMUs step). Around it the rig models what a controller meets on the real bench:

* **DAC** -- 12 bits over +-10 V (two's-complement codes -2048..2047, 1 LSB = 20/4096 V);
  analog output 0 drives the power amplifier (gain 1), outputs 1..3 are not connected.
* **Encoders** -- quadrature, 4096 counts/rev, 32-bit wrapping counters: channel 0 the
  motor-driven cart (2.275e-5 m/count), channel 1 the pendulum (1.534e-3 rad/count,
  counter-clockwise positive), channel 2 the passive cart of the double mass (2.275e-5
  m/count); channel 3 is not connected. A counter reads ``offset + floor(position /
  resolution + encoder_phase)``: with the default phase 0.5 the count edges lie half a
  count either side of the zero, so a reading is the nearest count (within half a count
  of the true position).
* **Software limits** (the lab's safety supervisor) -- cart +-0.30 m (every cart),
  pendulum +-20 deg, checked on the encoder readings after every physics step while an
  experiment runs (from the start and from each new controlling session until that
  session ends). A trip latches the amplifier off (0 V to the motor, whatever the card
  writes) until :meth:`VirtualRig.reset` (the operator's reset).
* **Hard end stops** at +-0.407 m (half the 0.814 m track): a cart reaching one stops
  dead (inelastic; its outward velocity is set to zero).
* **Watchdog** -- as on the Q4 (see :mod:`ipcosim.fmus.hil.api`), timed on the rig's clock
  (its registers: :class:`Watchdog`).
  Expiry forces the analog outputs to their expiration states (0 V unless configured)
  and latches: writes are refused until ``watchdog_clear``.
* **Noise and latency** (optional) -- Gaussian count noise of standard deviation
  ``noise_counts`` (seeded); a one-way transport latency: a write reaches the amplifier
  ``latency`` seconds after it was made, a reading shows the encoders ``latency``
  seconds before it was taken.


Clocks. ``lockstep``: the rig's time advances only when asked (:meth:`VirtualRig.advance`,
:meth:`VirtualRig.step`); deterministic, for CI. ``wallclock``: the rig's time is the host's
monotonic clock since :meth:`start_clock`, counted in steps of the clock's ``resolution``
(10 us). Neither ticks: the physics is computed when a request comes (or a status is asked),
exactly from where it was to the request's instant with the voltage held, and what happens
inside that interval is located there (:mod:`ipcosim.fmus.hil.rig_physics`). A STEP to a sample
instant ``until`` is answered at once with the reading at ``until``: the voltage it writes is
held to then, and the client waits for ``until`` before it acts again (:meth:`VirtualRig.exchange`).
So a wall-clock run's physics is the lockstep replay of its own requests. Time is kept in integer
nanoseconds (never accumulated floats); the clock is a :class:`RigClock`. The rig is
thread-safe (one re-entrant lock).

The rig, one idea to a module:

    rig_config   what defines a rig: the card's and the lab's facts, experiments, RigConfig
    rig_clock    its timekeeping: the card's watchdog registers and the rig's clock
    rig_physics  the plant advanced between requests, the watchdog's expiry and limit trips located
    rig          (this module) the rig a card talks to: VirtualRig's card and lab operations
"""
from __future__ import annotations

import collections
import math
import threading
import time
from typing import Callable, Sequence

import numpy as np

from ipcosim.fmus.hil.api import (
    CardInfo,
    ErrorCode,
    HILError,
    RigStatus,
    StepResult,
    as_channels,
    as_finite,
    wait_until_ns,
    wrap_int32,
)
from ipcosim.fmus.hil.rig_clock import RigClock, Watchdog
from ipcosim.fmus.hil.rig_config import (
    AMPLIFIER_GAIN,
    ANALOG_OUTPUTS,
    CART_ENCODER,
    CART_LIMIT_M,
    CART_M_PER_COUNT,
    CLOCKS,
    COUNTS_PER_REV,
    DAC_BITS,
    DAC_LSB,
    DAC_RANGE,
    DEFAULT_RESOLUTION,
    DEFAULT_TICK,
    ENCODER_INPUTS,
    END_STOP_M,
    EXPERIMENTS,
    LOCATE_NS,
    MAX_REQUEST_SPAN_NS,
    MAX_WATCHDOG_TIMEOUT,
    MOTOR_CHANNEL,
    NS,
    PASSIVE_CART_ENCODER,
    PENDULUM_ENCODER,
    PENDULUM_LIMIT_RAD,
    PENDULUM_RAD_PER_COUNT,
    RigConfig,
    RigEvent,
    dac_quantize,
    experiment_config,
    to_ns,
)
from ipcosim.fmus.hil.rig_physics import RigPhysics
from ipcosim.fmus.params import DEFAULT_PRESET, preset
from ipcosim.fmus.physics import MEASURED
from ipcosim.fmus.plant import Plant

#: The plants' steppers by step size, one table per plant parameters, shared by every rig of this process.
_STEPPERS: dict = {}


class VirtualRig(RigPhysics):
    """The virtual IP02 + Q4 rig (see the module docstring).

    Parameters
    ----------
    config : RigConfig
        The rig's definition.
    clock_ns : callable
        Monotonic host clock in nanoseconds (wallclock mode; injectable for tests).
    """

    def __init__(self, config: RigConfig | None = None,
                 clock_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.config = (config or RigConfig()).checked()
        self.kind = self.config.plant
        self.params = preset(self.config.preset or DEFAULT_PRESET[self.kind], **dict(self.config.params))
        self.clock = RigClock(self.config.clock, clock_ns)
        self.lock = threading.RLock()
        self.tick_ns = max(1, to_ns(self.config.tick_s))
        self.res_ns = max(1, to_ns(self.config.resolution_s))
        self.latency_ns = self._on_clock(to_ns(self.config.latency))
        self.plant = Plant(self.params)
        if self.res_ns > 1:   # every sub-step is a whole number of resolutions: make their steppers now
            self.plant.prepare_steps([m * self.res_ns / NS for m in range(1, self.tick_ns // self.res_ns + 1)],
                                     _STEPPERS)
        else:
            self.plant.prepare_steps([], _STEPPERS)
        self._x0 = self._initial_state()
        self.plant.set_state(self._x0)
        self._rng = np.random.default_rng(self.config.seed)
        self._t_ns = 0                      # time of the physics state
        self._halted = threading.Event()
        #: How long the last wall-clock :meth:`step` waited for its sample instant [ns].
        self.last_wait_ns = 0
        self.events: collections.deque[RigEvent] = collections.deque(maxlen=1000)
        self.event_count = 0
        self.counters: collections.Counter[str] = collections.Counter()
        self.amplifier_enabled = True
        self.limit_message = ""
        #: The lab's supervisor watches the limits while an experiment runs: armed from the start
        #: and by every new session, disarmed when a controlling session ends (the pendulum then
        #: falls with the motor at 0 V, which is no fault of the next experiment).
        self.limits_armed = True
        self._reset_card_state()
        self._measured_index = [self.plant.state_names.index(n) for n in MEASURED[self.kind]]
        cart = self._measured_index[0]
        pend = self.plant.state_names.index("pendulum_angle")
        # encoder channel -> (state index, resolution)
        cfg = self.config
        self._phase = cfg.encoder_phase
        self._encoders: dict[int, tuple[int, float]] = {CART_ENCODER: (cart, cfg.cart_m_per_count),
                                                        PENDULUM_ENCODER: (pend, cfg.pendulum_rad_per_count)}
        for name in [n for n in MEASURED[self.kind][1:] if n != "pendulum_angle"][:1]:  # a second cart
            self._encoders[PASSIVE_CART_ENCODER] = (self.plant.state_names.index(name), cfg.cart_m_per_count)
        self._carts = [(i, i + 1, n) for i, n in enumerate(self.plant.state_names) if n.endswith("cart_position")]
        self._cart_indices = [(ip, iv) for ip, iv, _ in self._carts]
        # with a transport latency the encoders show the past: the states of the last ``latency``
        self._history: collections.deque[tuple[int, np.ndarray]] = collections.deque()
        self._record_history()

    # --- construction helpers ----------------------------------------------------------------

    def _initial_state(self) -> np.ndarray:
        names = self.plant.state_names
        x0 = np.zeros(len(names))
        for key, value in self.config.initial_state.items():
            if key not in names:
                raise ValueError(f"rig initial state: {self.kind} has no state {key!r} "
                                 f"(states: {', '.join(names)})")
            if not math.isfinite(float(value)):
                raise ValueError(f"rig initial state {key} = {value}: not finite")
            x0[names.index(key)] = float(value)
        return x0

    def _reset_card_state(self) -> None:
        self._ao = [0.0] * ANALOG_OUTPUTS            # DAC registers (as written)
        self._applied = [0.0] * ANALOG_OUTPUTS       # what reached the amplifier (after latency)
        self._pending: collections.deque[tuple[int, int, float]] = collections.deque()
        self._expiration = [0.0] * ANALOG_OUTPUTS
        self._enc_offset = [0] * ENCODER_INPUTS
        self.watchdog = Watchdog()

    def info(self, card_type: str = "q4", card_id: str = "0") -> CardInfo:
        """The card description a client gets on opening."""
        return CardInfo(card_type=card_type, card_id=card_id, analog_outputs=ANALOG_OUTPUTS,
                        encoder_inputs=ENCODER_INPUTS, dac_bits=DAC_BITS, analog_min=-DAC_RANGE,
                        analog_max=DAC_RANGE, counts_per_rev=COUNTS_PER_REV, clock=self.config.clock,
                        tick=self.tick_ns / NS, plant=self.kind)

    # --- clock ---------------------------------------------------------------------------------

    @property
    def lockstep(self) -> bool:
        """True for the ``lockstep`` clock."""
        return self.clock.lockstep

    def start_clock(self) -> None:
        """Wallclock: set rig time 0 to now (once)."""
        if self.lockstep:
            return
        with self.lock:
            self.clock.start(self._t_ns)

    def stop_clock(self) -> None:
        """Nothing runs in the background to stop (kept for the server's shutdown sequence)."""

    def now_ns(self) -> int:
        """The rig's clock [ns]: simulated (lockstep) or host time since start_clock (wallclock)."""
        if self.lockstep:
            return self._t_ns
        if self.clock.wall0_ns is None:
            self.start_clock()
        return self.clock.now_ns(self._t_ns)

    def _on_clock(self, t_ns: int) -> int:
        """``t_ns`` rounded up to the clock's resolution."""
        return -(-t_ns // self.res_ns) * self.res_ns

    def time(self) -> float:
        """The rig's clock [s]."""
        with self.lock:
            self.sync()
            return self.now_ns() / NS

    def sync(self) -> None:
        """Wallclock: compute the physics up to now (to the clock's resolution), unless it is there or
        beyond (a STEP computes it to its sample instant at once). Lockstep: nothing."""
        if self.lockstep or self._halted.is_set():
            return      # a halted rig's physics stands still
        target = self.now_ns() // self.res_ns * self.res_ns
        if target > self._t_ns:
            self._advance_to(target)

    def advance(self, dt: float) -> None:
        """Lockstep: advance the rig by ``dt`` seconds (sub-steps of at most ``tick``). Wallclock: sync."""
        with self.lock:
            if not self.lockstep:
                self.sync()
                return
            if not (math.isfinite(dt) and 0 <= dt <= MAX_REQUEST_SPAN_NS / NS):
                raise HILError(ErrorCode.INVALID_ARGUMENT, f"advance: dt = {dt} s must be finite, >= 0 and at "
                                                           f"most {MAX_REQUEST_SPAN_NS / NS:g} s per request")
            self._advance_to(self._t_ns + to_ns(dt))


    # --- card operations (every one syncs the wallclock first) ------------------------------------

    @staticmethod
    def _check_channels(channels: Sequence[int], what: str, count: int) -> list[int]:
        chans = as_channels(channels, what)
        for c in chans:
            if c >= count:
                raise HILError(ErrorCode.BAD_CHANNEL, f"{what} channel {c} does not exist "
                                                      f"(the card has 0..{count - 1})")
        return chans

    def _check_ao(self, channels: Sequence[int]) -> list[int]:
        return self._check_channels(channels, "analog output", ANALOG_OUTPUTS)

    def _check_enc(self, channels: Sequence[int]) -> list[int]:
        return self._check_channels(channels, "encoder", ENCODER_INPUTS)

    def write_analog(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        """Write analog outputs [V] (DAC-quantized; refused after a watchdog expiry)."""
        with self.lock:
            self.sync()
            self._write(channels, volts)

    def _write(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        """:meth:`write_analog` at the rig's time as it stands."""
        chans = self._check_ao(channels)
        values = as_finite(volts, len(chans), "write_analog")
        if self.watchdog.expired:
            raise HILError(ErrorCode.WATCHDOG_EXPIRED,
                           f"write_analog refused: the watchdog expired at rig time "
                           f"{(self.watchdog.expired_at_ns or 0) / NS:.4f} s and was not cleared")
        for c, v in zip(chans, values):
            q = dac_quantize(v)
            self._ao[c] = q
            if self.latency_ns:
                self._pending.append((self._t_ns + self.latency_ns, c, q))
            else:
                self._applied[c] = q

    def read_encoder(self, channels: Sequence[int], at_ns: int | None = None) -> np.ndarray:
        """Encoder counts (int32), as of now or of the rig time ``at_ns`` (a recent instant)."""
        with self.lock:
            self.sync()
            return np.array(self._counts(self._check_enc(channels), at_ns), dtype=np.int32)

    def _counts(self, chans: list[int], at_ns: int | None) -> list[int]:
        """The counters ``chans`` as of rig time ``at_ns`` (None: now), with the encoders' noise."""
        x = self._sensed_state(at_ns)
        sigma = self.config.noise_counts
        out = []
        for c in chans:
            n = self._enc_offset[c] + self._position_counts(c, x)
            if sigma and c in self._encoders:
                n += int(round(self._rng.normal(0.0, sigma)))
            out.append(wrap_int32(n))
        return out

    def set_encoder_counts(self, channels: Sequence[int], counts: Sequence[int]) -> None:
        """Load the counters."""
        with self.lock:
            self.sync()
            chans = self._check_enc(channels)
            if isinstance(counts, (int, np.integer)):
                counts = [int(counts)] * len(chans)
            counts = [int(c) for c in counts]
            if len(counts) != len(chans):
                raise HILError(ErrorCode.INVALID_ARGUMENT, f"set_encoder_counts: {len(counts)} counts for "
                                                           f"{len(chans)} channels")
            x = self._sensed_state()
            for c, n in zip(chans, counts):
                self._enc_offset[c] = wrap_int32(n) - self._position_counts(c, x)

    def watchdog_set_analog_expiration_state(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        """Voltages forced on the outputs when the watchdog expires."""
        with self.lock:
            self.sync()
            chans = self._check_ao(channels)
            values = as_finite(volts, len(chans), "watchdog_set_analog_expiration_state")
            for c, v in zip(chans, values):
                self._expiration[c] = dac_quantize(v)

    def watchdog_start(self, timeout: float) -> None:
        """Start the watchdog."""
        with self.lock:
            self.sync()
            if not (math.isfinite(timeout) and 0 < timeout <= MAX_WATCHDOG_TIMEOUT):
                raise HILError(ErrorCode.INVALID_ARGUMENT, f"watchdog_start: timeout = {timeout} s must be in "
                                                           f"(0, {MAX_WATCHDOG_TIMEOUT:g}] s")
            self.watchdog.start(max(self.res_ns, self._on_clock(to_ns(timeout))), self._t_ns)

    def watchdog_reload(self) -> bool:
        """Reload; False if the watchdog had expired."""
        with self.lock:
            self.sync()
            return self.watchdog.reload(self._t_ns)

    def watchdog_is_expired(self) -> bool:
        """Whether the watchdog expired and was not cleared."""
        with self.lock:
            self.sync()
            return self.watchdog.expired

    def watchdog_clear(self) -> None:
        """Clear an expiry (outputs stay at their expiration states until written)."""
        with self.lock:
            self.sync()
            self.watchdog.clear(self._t_ns)

    def watchdog_stop(self) -> None:
        """Stop the timer (an expiry stays until cleared)."""
        with self.lock:
            self.sync()
            self.watchdog.stop()

    def exchange(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
                 until_ns: int, reload: bool = True) -> tuple[bool, int, list[int]]:
        """One sample period's request, answered at once: ``(reloaded, lateness [ns], counts)``.

        At the request's instant (wallclock: its arrival; lockstep: the rig's time) the watchdog is
        reloaded and the outputs written; the physics runs on with them held to the sample instant
        ``until_ns`` (rig time), where the encoders are read. The client waits for ``until_ns`` before it
        acts again (:meth:`step`, ``TcpipCard.step``), so nothing can change the outputs before then. A
        request that arrives after its sample instant is read at its arrival, and counted late.
        """
        with self.lock:
            self.sync()
            arrival = self.now_ns()
            if self.lockstep and until_ns < arrival:
                raise HILError(ErrorCode.CLOCK, f"step: sample instant {until_ns / NS:.6f} s is before the "
                                                f"lockstep rig's time {arrival / NS:.6f} s")
            if until_ns - arrival > MAX_REQUEST_SPAN_NS:
                raise HILError(ErrorCode.INVALID_ARGUMENT, f"step: sample instant {until_ns / NS:.6f} s is more "
                                                           f"than {MAX_REQUEST_SPAN_NS / NS:g} s after the rig's "
                                                           f"time {arrival / NS:.6f} s")
            reloaded = self.watchdog.reload(self._t_ns) if reload else True   # one instant for all of it
            self._write(analog_channels, volts)
            enc = self._check_enc(encoder_channels)
            self._advance_to(self._on_clock(until_ns))
            late = max(0, arrival - until_ns)
            if late:
                self.counters["late_samples"] += 1
            return reloaded, late, self._counts(enc, self._t_ns)

    def step(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
             until_ns: int, reload: bool = True) -> StepResult:
        """One sample period (see :meth:`ipcosim.fmus.hil.api.Card.step`); ``until_ns`` is rig time.

        :meth:`exchange`, then (wallclock) a wait until the rig's clock reaches ``until_ns``.
        """
        reloaded, late, counts = self.exchange(analog_channels, volts, encoder_channels, until_ns, reload)
        self.last_wait_ns = self.wait_for(until_ns)
        with self.lock:
            return StepResult(counts=np.array(counts, dtype=np.int32), reloaded=reloaded,
                              time=max(self._t_ns, self.now_ns()) / NS, late=late / NS, status=self._status())

    def wait_for(self, until_ns: int) -> int:
        """Wallclock: wait until the rig's clock reaches ``until_ns`` (a sample instant); returns how long
        it waited [ns] (lockstep: 0, nothing to wait for).

        Raises
        ------
        HILError
            The rig was halted meanwhile (``CONNECTION``).
        """
        if self.lockstep:
            return 0
        began = time.monotonic_ns()
        wait_until_ns(self.now_ns, until_ns, abort=self._halted.is_set)
        if self._halted.is_set():
            raise HILError(ErrorCode.CONNECTION, "the rig is shutting down")
        return time.monotonic_ns() - began

    def flags(self) -> tuple[bool, bool, bool, bool]:
        """``(amplifier enabled, limit tripped, watchdog expired, watchdog running)`` as they stand."""
        return (self.amplifier_enabled, bool(self.limit_message) and not self.amplifier_enabled,
                self.watchdog.expired, self.watchdog.running)

    # --- lab operations ----------------------------------------------------------------------------

    def new_session(self, who: str = "client") -> None:
        """A controller takes the rig: the operator has put the carts at 0 and the pendulum upright.

        The card's registers are reset (outputs 0 V, watchdog stopped and cleared, counters at
        0); a latched limit trip is *not* cleared (that needs :meth:`reset`).
        """
        with self.lock:
            self.sync()
            self._reset_card_state()
            self.plant.set_state(self._x0)
            self._history.clear()
            self._record_history()
            self.counters["sessions"] += 1
            self.limits_armed = True
            self._event(self._t_ns, "session", f"session opened by {who}")

    def end_session(self, reason: str) -> None:
        """The controller left (or was lost): outputs to their expiration states, watchdog stopped."""
        with self.lock:
            try:
                self.sync()
            except HILError:
                pass
            for ch in range(ANALOG_OUTPUTS):
                self._ao[ch] = self._expiration[ch]
                self._applied[ch] = self._expiration[ch]
            self._pending.clear()
            self.watchdog.stop()
            self.limits_armed = False
            self._event(self._t_ns, "session", f"session ended ({reason}): outputs set to their expiration "
                                               f"states, limits disarmed")

    def reset(self) -> None:
        """The operator's reset: re-home the plant, clear the limit latch, re-enable the amplifier."""
        with self.lock:
            try:
                self.sync()
            except HILError:
                pass
            self._reset_card_state()
            self.plant.set_state(self._x0)
            self._history.clear()
            self._record_history()
            self.amplifier_enabled = True
            self.limit_message = ""
            self.counters["resets"] += 1
            self._event(self._t_ns, "reset", "operator reset: amplifier enabled, limit latch cleared")

    def halt(self, reason: str = "rig stopped") -> None:
        """Shut down: every wait and computation in progress ends, the outputs go to 0 V, the watchdog stops."""
        self._halted.set()
        with self.lock:
            for ch in range(ANALOG_OUTPUTS):
                self._ao[ch] = self._applied[ch] = 0.0
            self._pending.clear()
            self.watchdog.stop()
            self.limits_armed = False
            self._event(self._t_ns, "halt", f"{reason}: outputs at 0 V")

    def motor_voltage(self) -> float:
        """Voltage the amplifier applies to the motor now [V]."""
        with self.lock:
            self.sync()
            return AMPLIFIER_GAIN * self._applied[MOTOR_CHANNEL] if self.amplifier_enabled else 0.0

    def status(self) -> RigStatus:
        """Safety status, the clock and the counters."""
        with self.lock:
            self.sync()
            return self._status()

    def _status(self) -> RigStatus:
        """:meth:`status` as the physics stands (nothing computed for it)."""
        return RigStatus(amplifier_enabled=self.amplifier_enabled,
                         limit_tripped=bool(self.limit_message) and not self.amplifier_enabled,
                         watchdog_expired=self.watchdog.expired, watchdog_running=self.watchdog.running,
                         limit_message=self.limit_message, time=self.now_ns() / NS,
                         motor_voltage=AMPLIFIER_GAIN * self._applied[MOTOR_CHANNEL] if self.amplifier_enabled else 0.0,
                         counters=dict(self.counters))

    def true_state(self) -> dict[str, float]:
        """The plant's true state by name (for tests and diagnostics; a controller never sees it)."""
        with self.lock:
            self.sync()
            return self.plant.values()


__all__ = ["VirtualRig", "RigConfig", "RigEvent", "RigClock", "Watchdog", "RigPhysics", "EXPERIMENTS",
           "experiment_config", "to_ns", "dac_quantize", "NS", "ANALOG_OUTPUTS", "ENCODER_INPUTS", "DAC_BITS",
           "DAC_RANGE", "DAC_LSB", "COUNTS_PER_REV", "CART_M_PER_COUNT", "PENDULUM_RAD_PER_COUNT", "AMPLIFIER_GAIN",
           "MOTOR_CHANNEL", "CART_ENCODER", "PENDULUM_ENCODER", "PASSIVE_CART_ENCODER", "CART_LIMIT_M",
           "PENDULUM_LIMIT_RAD", "END_STOP_M", "CLOCKS", "DEFAULT_TICK", "DEFAULT_RESOLUTION", "LOCATE_NS",
           "MAX_REQUEST_SPAN_NS", "MAX_WATCHDOG_TIMEOUT"]
