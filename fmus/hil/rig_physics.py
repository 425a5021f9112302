"""The rig's physics between two requests: the plant advanced exactly from where it was to a request's
instant with the voltage held, and what happens inside that interval located on the rig's own.

Neither clock ticks: the physics is computed when a request comes (or a status is asked), exactly from
where it was to the request's instant with the voltage held -- a DAC holds its value, an encoder is read
when asked --, in sub-steps of at most ``tick``. Inside such an interval the rig locates what happens on
its own: a watchdog's expiry at its deadline, a delayed write reaching the amplifier, a software limit's
trip at the first instant (to the clock's resolution) its encoder reading is beyond the limit; either
latches at that instant. The hard end stops act after every sub-step; with a transport latency the
encoders show the states of ``latency`` earlier.
"""
from __future__ import annotations

import collections
import math
import threading
from typing import Sequence

import numpy as np

from ipcosim.fmus.hil.api import ErrorCode, HILError
from ipcosim.fmus.hil.rig_clock import Watchdog
from ipcosim.fmus.hil.rig_config import (
    AMPLIFIER_GAIN,
    ANALOG_OUTPUTS,
    LOCATE_NS,
    MOTOR_CHANNEL,
    NS,
    PENDULUM_ENCODER,
    RigConfig,
    RigEvent,
)
from ipcosim.fmus.instruments import end_stop_state
from ipcosim.fmus.plant import Plant, PlantStepError


class RigPhysics:
    """The plant stepping and event location of :class:`~ipcosim.fmus.hil.rig.VirtualRig` (see the module
    docstring), on the state the rig keeps: its time ``_t_ns`` [ns], plant, watchdog, DAC registers as
    applied and pending (with a latency), limits, counters and log."""

    config: RigConfig
    plant: Plant
    watchdog: Watchdog
    counters: collections.Counter[str]
    events: collections.deque[RigEvent]
    event_count: int
    amplifier_enabled: bool
    limits_armed: bool
    limit_message: str
    tick_ns: int
    res_ns: int
    latency_ns: int
    _t_ns: int
    _halted: threading.Event
    _applied: list[float]
    _ao: list[float]
    _expiration: list[float]
    _pending: collections.deque[tuple[int, int, float]]
    _history: collections.deque[tuple[int, np.ndarray]]
    _encoders: dict[int, tuple[int, float]]
    _carts: list[tuple[int, int, str]]
    _cart_indices: list[tuple[int, int]]
    _phase: float

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
        stopped = end_stop_state(x, self._cart_indices, self.config.end_stop)
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
