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
exactly from where it was to the request's instant with the voltage held -- a DAC holds its
value, an encoder is read when asked --, in sub-steps of at most ``tick``. Inside such an
interval the rig locates what happens on its own: a watchdog's expiry at its deadline, a
software limit's trip at the first instant (to the clock's resolution) its encoder reading is
beyond the limit; either latches at that instant. A STEP to a sample instant ``until`` is
answered at once with the reading at ``until``: the voltage it writes is held to then, and
the client waits for ``until`` before it acts again (:meth:`VirtualRig.exchange`). So a
wall-clock run's physics is the lockstep replay of its own requests. Time is kept in integer
nanoseconds (never accumulated floats); the clock is a :class:`RigClock`. The rig is
thread-safe (one re-entrant lock).
"""
from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from ipcosim.errors import closest
from ipcosim.fmus import instruments
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
from ipcosim.fmus.instruments import end_stop_state
from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, preset
from ipcosim.fmus.physics import MEASURED
from ipcosim.fmus.plant import Plant, PlantStepError

# Q4 card and IP02 facts (the thesis, sec. 3.3: Q4 card, 4096-count encoders; docs/plant.md, Parameters).
ANALOG_OUTPUTS = 4
ENCODER_INPUTS = 4
DAC_BITS = instruments.DAC_BITS
DAC_RANGE = instruments.DAC_RANGE_V      # +-10 V
DAC_LSB = instruments.DAC_V_PER_CODE
COUNTS_PER_REV = 4096
CART_M_PER_COUNT = 2.275e-5
PENDULUM_RAD_PER_COUNT = 1.534e-3
AMPLIFIER_GAIN = 1.0
MOTOR_CHANNEL = 0
CART_ENCODER, PENDULUM_ENCODER, PASSIVE_CART_ENCODER = 0, 1, 2
CART_LIMIT_M = instruments.CART_LIMIT_M
PENDULUM_LIMIT_RAD = instruments.PENDULUM_LIMIT_RAD
END_STOP_M = 0.407
CLOCKS = ("lockstep", "wallclock")
DEFAULT_TICK = {"lockstep": 1e-3, "wallclock": 5e-4}
#: The clock's resolution [s]: a wall-clock request's instant is counted in these steps, so that every
#: sub-step the physics takes is a whole number of them and its stepper is made once, before the run.
DEFAULT_RESOLUTION = {"lockstep": 1e-9, "wallclock": 1e-5}
#: How finely a limit trip is located in a lockstep rig (whose clock counts nanoseconds) [ns].
LOCATE_NS = 10_000

NS = 1_000_000_000
#: Longest stretch of rig time one request may ask for (STEP to an instant, ADVANCE) [ns]: a
#: client cannot make the rig wait, or compute, for longer than this.
MAX_REQUEST_SPAN_NS = 10 * NS
#: Longest watchdog timeout a client may set [s].
MAX_WATCHDOG_TIMEOUT = 10.0
#: The plants' steppers by step size, one table per plant parameters, shared by every rig of this process.
_STEPPERS: dict = {}


#: Experiments the rig can be set up for (``ipcosim rig serve --experiment NAME``): the pose it starts
#: in and its software limits. ``identify``: the pendulum hanging (the excitation of
#: ``{single-mass,double-mass}-identify`` swings it about its stable equilibrium), so the pendulum limit
#: (an upright-balancing guard) is off; the cart limit stays (the excitation holds the cart within 0.25 m).
EXPERIMENTS: dict[str, dict[str, object]] = {
    "identify": {"initial_state": {"pendulum_angle": math.pi}, "pendulum_limit": None, "cart_limit": CART_LIMIT_M},
}


def experiment_config(name: str | None, given: Mapping[str, object]) -> dict[str, object]:
    """``RigConfig`` keywords for the experiment ``name`` (``EXPERIMENTS``; None: none) under the ones
    ``given``: a given value wins, given initial-state values join the experiment's."""
    if name is not None and name not in EXPERIMENTS:
        raise ValueError(f"--experiment {name}: no such rig experiment; {closest(name, EXPERIMENTS)}")
    setup = EXPERIMENTS.get(name or "", {})
    out = {**{k: v for k, v in setup.items() if k != "initial_state"}, **given}
    out["initial_state"] = {**setup.get("initial_state", {}), **given.get("initial_state", {})}  # type: ignore[dict-item]
    return out


def to_ns(seconds: float) -> int:
    """Seconds -> integer nanoseconds (rounded)."""
    return int(round(float(seconds) * NS))


def dac_quantize(volts: float) -> float:
    """The DAC: the nearest 12-bit code in [-2048, 2047], back in volts."""
    code = int(round(volts / DAC_LSB))
    code = max(-(1 << (DAC_BITS - 1)), min((1 << (DAC_BITS - 1)) - 1, code))
    return code * DAC_LSB


@dataclass(frozen=True)
class RigConfig:
    """Everything that defines a virtual rig.

    Parameters
    ----------
    plant : str
        ``single-mass`` or ``double-mass``.
    preset : str, optional
        Physical parameter preset (default: the plant's thesis preset).
    params : mapping
        Physical parameter overrides (``ipcosim.fmus.params`` names).
    initial_state : mapping
        Initial values by state name (``ipcosim.fmus.physics.state_names``); others 0.
    clock : str
        ``lockstep`` or ``wallclock``.
    tick : float, optional
        Physics step [s]: the largest sub-step the physics takes.
    cart_limit, pendulum_limit : float or None
        Software limits [m], [rad]; None disables one.
    end_stop : float
        Hard end stops [m].
    noise_counts : float
        Standard deviation of encoder noise [counts]; 0 = none.
    latency : float
        One-way transport latency [s].
    seed : int
        Seed of the noise generator.
    encoder_phase : float
        Where the encoders' count edges lie relative to the zero position, in counts: a
        counter reads ``floor(position / resolution + encoder_phase)``. 0.5 (default): the
        edges are half a count either side of the zero (the reading is the nearest count,
        no bias); 0: an edge at the zero (the reading is up to one count below).
    cart_m_per_count, pendulum_rad_per_count : float
        Encoder resolutions (default: the thesis's IP02 encoders).
    resolution : float, optional
        The clock's resolution [s] (default: 1 ns lockstep, 10 us wallclock); ``tick`` is a
        whole number of it. A lockstep replay of a wall-clock run takes the wall clock's.
    """

    plant: str = "single-mass"
    preset: str | None = None
    params: Mapping[str, float] = field(default_factory=dict)
    initial_state: Mapping[str, float] = field(default_factory=dict)
    clock: str = "lockstep"
    tick: float | None = None
    cart_limit: float | None = CART_LIMIT_M
    pendulum_limit: float | None = PENDULUM_LIMIT_RAD
    end_stop: float = END_STOP_M
    noise_counts: float = 0.0
    latency: float = 0.0
    seed: int = 0
    encoder_phase: float = 0.5
    cart_m_per_count: float = CART_M_PER_COUNT
    pendulum_rad_per_count: float = PENDULUM_RAD_PER_COUNT
    resolution: float | None = None

    def checked(self) -> "RigConfig":
        """Validate; raises ``ValueError`` naming the offending field."""
        if self.plant not in DEFAULT_PRESET:
            raise ValueError(f"rig plant {self.plant!r}: expected {' or '.join(DEFAULT_PRESET)}")
        if self.clock not in CLOCKS:
            raise ValueError(f"rig clock {self.clock!r}: expected lockstep or wallclock")
        name = self.preset or DEFAULT_PRESET[self.plant]
        if name in PRESETS and PRESETS[name][0] != self.plant:
            raise ValueError(f"rig preset {name!r} is a {PRESETS[name][0]} preset, not {self.plant}")
        for label, value, lo in (("tick", self.tick_s, 1e-6), ("end_stop", self.end_stop, 0.0),
                                 ("resolution", self.resolution_s, 0.0)):
            if not (math.isfinite(value) and value > lo):
                raise ValueError(f"rig {label} = {value}: must be a finite number > {lo:g}")
        res_ns = max(1, to_ns(self.resolution_s))
        if to_ns(self.tick_s) % res_ns:
            raise ValueError(f"rig tick = {self.tick_s} s: must be a whole number of the clock's resolution "
                             f"({self.resolution_s:g} s)")
        if not (math.isfinite(self.encoder_phase) and 0 <= self.encoder_phase < 1):
            raise ValueError(f"rig encoder_phase = {self.encoder_phase}: must be in [0, 1) counts")
        for label, value in (("cart_m_per_count", self.cart_m_per_count),
                             ("pendulum_rad_per_count", self.pendulum_rad_per_count)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"rig {label} = {value}: must be > 0")
        for label, value in (("noise_counts", self.noise_counts), ("latency", self.latency)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"rig {label} = {value}: must be a finite number >= 0")
        for label, value in (("cart_limit", self.cart_limit), ("pendulum_limit", self.pendulum_limit)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"rig {label} = {value}: must be > 0 (or disabled)")
        return self

    @property
    def tick_s(self) -> float:
        """The physics step [s] (the clock's default if not given)."""
        return float(self.tick) if self.tick is not None else DEFAULT_TICK[self.clock]

    @property
    def resolution_s(self) -> float:
        """The clock's resolution [s] (the clock's default if not given)."""
        return float(self.resolution) if self.resolution is not None else DEFAULT_RESOLUTION[self.clock]


@dataclass(frozen=True)
class RigEvent:
    """Something the rig's log keeps: a limit trip, a watchdog expiry, a session change..."""

    time: float
    topic: str  # limit, fault, watchdog, session, reset, halt
    message: str


# --- the card's watchdog and the rig's clock, which the rig composes -----------------------------

class Watchdog:
    """The watchdog's registers: running, expired (latched), timeout, deadline, last reload, expiry time [ns]."""

    def __init__(self) -> None:
        self.running = False
        self.expired = False
        self.timeout_ns = 0
        self.deadline_ns = 0
        self.last_reload_ns: int | None = None
        self.expired_at_ns: int | None = None

    def start(self, timeout_ns: int, now_ns: int) -> None:
        """Run with ``timeout_ns``, reloaded at ``now_ns``."""
        self.timeout_ns = timeout_ns
        self.running = True
        self._reloaded(now_ns)

    def reload(self, now_ns: int) -> bool:
        """Reload at ``now_ns``; False (and nothing done) if it had expired."""
        if self.expired:
            return False
        if self.running:
            self._reloaded(now_ns)
        return True

    def clear(self, now_ns: int) -> None:
        """Clear an expiry; a running watchdog is reloaded at ``now_ns``."""
        self.expired = False
        if self.running:
            self._reloaded(now_ns)

    def stop(self) -> None:
        """Stop the timer (an expiry stays until cleared)."""
        self.running = False

    def due(self, t_ns: int) -> bool:
        """Whether it expires at rig time ``t_ns`` (running, not yet expired, deadline reached)."""
        return self.running and not self.expired and t_ns >= self.deadline_ns

    def expire(self, t_ns: int) -> None:
        """Latch the expiry at rig time ``t_ns``."""
        self.expired = True
        self.expired_at_ns = t_ns

    def _reloaded(self, now_ns: int) -> None:
        self.last_reload_ns = now_ns
        self.deadline_ns = now_ns + self.timeout_ns


class RigClock:
    """Rig time [ns] of one rig.

    Parameters
    ----------
    mode : str
        ``lockstep`` or ``wallclock``.
    clock_ns : callable
        Monotonic host clock in nanoseconds (wallclock; injectable for tests).
    """

    def __init__(self, mode: str, clock_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.mode = mode
        self.clock_ns = clock_ns
        self.wall0_ns: int | None = None   # wallclock: host time of rig time 0

    @property
    def lockstep(self) -> bool:
        """True for the ``lockstep`` clock."""
        return self.mode == "lockstep"

    def start(self, physics_ns: int) -> None:
        """Wallclock: rig time ``physics_ns`` is now (once; later calls keep the first start)."""
        if self.wall0_ns is None:
            self.wall0_ns = self.clock_ns() - physics_ns

    def now_ns(self, physics_ns: int) -> int:
        """The rig's time: ``physics_ns`` (lockstep) or host time since :meth:`start` (wallclock,
        started now if it was not)."""
        if self.lockstep:
            return physics_ns
        if self.wall0_ns is None:
            self.start(physics_ns)
        return self.clock_ns() - self.wall0_ns


class VirtualRig:
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

    def _advance_to(self, target_ns: int) -> None:
        """Compute the physics to ``target_ns``, in pieces that end where something is due inside the
        interval (a watchdog deadline, a delayed write reaching the amplifier)."""
        while self._t_ns < target_ns:
            self._piece(min(target_ns, self._next_due(target_ns)))

    def _next_due(self, horizon_ns: int) -> int:
        """The first instant after now and before ``horizon_ns`` at which something is due (else the horizon)."""
        t, out = self._t_ns, horizon_ns
        wd = self.watchdog
        if wd.running and not wd.expired and t < wd.deadline_ns < out:
            out = wd.deadline_ns
        if self._pending and t < self._pending[0][0] < out:
            out = self._pending[0][0]
        return out

    def _piece(self, end_ns: int) -> None:
        """From now to ``end_ns`` in ``ceil(interval / tick)`` sub-steps as equal as the clock's resolution
        allows (a lockstep rig: as equal as nanoseconds allow)."""
        interval = end_ns - self._t_ns
        q = self.res_ns if interval % self.res_ns == 0 else 1
        units = interval // q
        n = -(-interval // self.tick_ns)
        done = 0
        halted = self._halted.is_set
        for k in range(1, n + 1):
            if halted():
                raise HILError(ErrorCode.CONNECTION, "the rig is shutting down")
            upto = units * k // n * q
            self._substep(upto - done)
            done = upto

    # --- physics ---------------------------------------------------------------------------------

    def _substep(self, dt_ns: int) -> None:
        t_ns = self._t_ns
        while self._pending and self._pending[0][0] <= t_ns:
            _, ch, v = self._pending.popleft()
            self._applied[ch] = v
        if self.watchdog.due(t_ns):
            self._expire_watchdog(t_ns)
        v = AMPLIFIER_GAIN * self._applied[MOTOR_CHANNEL] if self.amplifier_enabled else 0.0
        armed = self.amplifier_enabled and self.limits_armed
        start = self.plant.snapshot() if armed and not self.latency_ns else None
        self._plant_step(t_ns, dt_ns, v)
        if not armed:
            return
        beyond = self._beyond_limit()
        if beyond is None:
            return
        if start is not None:
            beyond = self._locate_trip(start, t_ns, dt_ns, v, beyond)
        self._trip(*beyond)
        if self._t_ns < t_ns + dt_ns:      # the rest of the sub-step with the amplifier off
            self._substep(t_ns + dt_ns - self._t_ns)

    def _plant_step(self, t_ns: int, dt_ns: int, v: float) -> None:
        """One step of the plant from ``t_ns`` (the hard end stops after it)."""
        try:
            self.plant.do_step(t_ns / NS, dt_ns / NS, v)
        except (PlantStepError, ValueError) as exc:
            self.amplifier_enabled = False
            self.limit_message = f"plant fault: {exc}"
            self._event(t_ns, "fault", self.limit_message)
            raise HILError(ErrorCode.INTERNAL, f"virtual rig: {exc}") from exc
        self._t_ns = t_ns + dt_ns
        self._end_stops()
        self._record_history()

    def _locate_trip(self, start: tuple, t_ns: int, dt_ns: int, v: float,
                     beyond: tuple[int, float, float]) -> tuple[int, float, float]:
        """The first instant of the sub-step from ``t_ns`` (state ``start``) at which a reading is beyond
        its limit, by bisection on the clock's resolution (``LOCATE_NS`` on a lockstep clock): the
        plant is left there, with what is beyond."""
        q = self.res_ns if self.res_ns > 1 else LOCATE_NS
        lo, hi = 0, dt_ns
        end = self.plant.snapshot()
        while True:
            mid = (lo + (hi - lo) // 2) // q * q
            if mid <= lo:
                mid = lo + q
            if mid >= hi:
                break
            self.plant.restore(start)
            self._plant_step(t_ns, mid, v)
            found = self._beyond_limit()
            if found is None:
                lo = mid
            else:
                hi, beyond, end = mid, found, self.plant.snapshot()
        self.plant.restore(end)
        self._t_ns = t_ns + hi
        return beyond

    def _end_stops(self) -> None:
        x = self.plant.state
        stopped = end_stop_state(x, [(ip, iv) for ip, iv, _ in self._carts], self.config.end_stop)
        if stopped is None:
            return
        for ip, _, name in self._carts:
            if stopped[ip] != x[ip]:
                self.counters[f"end_stop:{name}"] += 1
        self.plant.set_state(stopped)

    def _record_history(self) -> None:
        """With a transport latency: keep the states the encoders may still show."""
        if not self.latency_ns:
            return
        self._history.append((self._t_ns, self.plant.state))
        keep_from = self._t_ns - self.latency_ns
        while len(self._history) > 1 and self._history[1][0] <= keep_from:
            self._history.popleft()

    def _sensed_state(self, at_ns: int | None = None) -> Sequence[float]:
        """The state the encoders show at rig time ``at_ns`` (default: now), i.e. ``latency`` earlier."""
        if not self.latency_ns:
            return self.plant.state
        when = (self._t_ns if at_ns is None else at_ns) - self.latency_ns
        chosen = self._history[0][1]
        for t, x in reversed(self._history):
            if t <= when:
                chosen = x
                break
        return chosen

    def _position_counts(self, channel: int, x: Sequence[float]) -> int:
        if channel not in self._encoders:
            return 0
        index, res = self._encoders[channel]
        return math.floor(x[index] / res + self._phase)

    def _beyond_limit(self) -> tuple[int, float, float] | None:
        """``(encoder channel, reading, limit)`` of the first reading beyond its software limit, or None."""
        x = self._sensed_state()
        cfg = self.config
        for ch, (index, res) in self._encoders.items():
            limit = cfg.pendulum_limit if ch == PENDULUM_ENCODER else cfg.cart_limit
            value = math.floor(x[index] / res + self._phase) * res
            if limit is not None and abs(value) > limit:
                return ch, value, limit
        return None

    def _trip(self, ch: int, value: float, limit: float) -> None:
        """Latch the amplifier off now: the reading of encoder ``ch`` is ``value``, beyond ``limit``."""
        name = self.plant.state_names[self._encoders[ch][0]]
        unit = "rad" if ch == PENDULUM_ENCODER else "m"
        extra = f" ({math.degrees(value):+.2f} deg, limit +-{math.degrees(limit):.0f} deg)" \
            if ch == PENDULUM_ENCODER else ""
        self.amplifier_enabled = False
        self.limit_message = (f"{'pendulum' if ch == PENDULUM_ENCODER else 'cart'} limit tripped: "
                              f"{name} = {value:+.4f} {unit} beyond +-{limit:.4g} {unit}{extra} "
                              f"at rig time {self._t_ns / NS:.4f} s; amplifier latched off until reset")
        self.counters["limit_trips"] += 1
        self._event(self._t_ns, "limit", self.limit_message)

    def _expire_watchdog(self, t_ns: int) -> None:
        wd = self.watchdog
        wd.expire(t_ns)
        for ch in range(ANALOG_OUTPUTS):
            self._ao[ch] = self._expiration[ch]
            self._applied[ch] = self._expiration[ch]  # the card forces its outputs at once
        self._pending.clear()
        self.counters["watchdog_expiries"] += 1
        last = wd.last_reload_ns if wd.last_reload_ns is not None else t_ns
        self._event(t_ns, "watchdog", f"watchdog expired at rig time {t_ns / NS:.4f} s "
                                      f"({(t_ns - last) / NS:.4f} s after the last reload; timeout "
                                      f"{wd.timeout_ns / NS:g} s): outputs forced to their expiration "
                                      f"states")

    def _event(self, t_ns: int, topic: str, message: str) -> None:
        self.events.append(RigEvent(t_ns / NS, topic, message))
        self.event_count += 1

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
        self.last_wait_ns = 0
        if not self.lockstep:
            began = time.monotonic_ns()
            wait_until_ns(self.now_ns, until_ns, abort=self._halted.is_set)
            self.last_wait_ns = time.monotonic_ns() - began
            if self._halted.is_set():
                raise HILError(ErrorCode.CONNECTION, "the rig is shutting down")
        with self.lock:
            return StepResult(counts=np.array(counts, dtype=np.int32), reloaded=reloaded,
                              time=max(self._t_ns, self.now_ns()) / NS, late=late / NS, status=self._status())

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



