"""What defines a virtual rig: the Q4 card's and the IP02's facts, the lab's limits, the experiments a rig
can be set up for, and :class:`RigConfig` (the rig itself: :mod:`ipcosim.fmus.hil.rig`).

Time is kept in integer nanoseconds (:func:`to_ns`); the DAC's codes are :func:`dac_quantize`'s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from ipcosim.errors import closest
from ipcosim.fmus import instruments
from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS

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
