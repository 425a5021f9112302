"""Real-time pacing of a fixed-step loop, and its timing statistics.

:class:`Pacer` holds a loop of period ``h`` to the wall clock. Step ``n`` may start no
earlier than its deadline ``t0 + n*h``, computed from integer nanoseconds every time
(never by adding periods, so no drift accumulates, and a late step does not shift the
following deadlines). Waiting is "sleep, then spin": sleep until ``spin`` before the
deadline (the OS wakes us up late by tens of microseconds), then busy-wait on the
clock to the deadline itself.

Statistics (:meth:`Pacer.metrics`, the keys ``ipcosim run --realtime`` adds to
metrics.json):

``period_jitter_p50_s``, ``period_jitter_p99_s``, ``period_jitter_max_s``
    Percentiles of ``|actual period - h|``, the actual period being the time between
    the starts of consecutive steps (from the second step on: the first one starts when
    the pacer does).
``overruns``
    Steps that started later than ``tolerance`` (default: half a period) after their
    deadline, i.e. whose predecessor ended that late. Lateness is measured against the
    schedule ``t0 + n*h`` anchored at the step that ran earliest: when the pacer paces,
    that is its own schedule; in a HIL run the card's clock paces the loop (the adapter
    returns at the card's sample instants, a constant offset after the pacer's deadlines)
    and the offset is not counted as lateness.
``worst_step_time_s``
    Longest time from the start to the end of one step (in a HIL run this includes the
    wait for the card's sample instant).
``lateness_p99_s``, ``lateness_max_s``
    How late steps started relative to their deadlines.
``realtime_steps``
    Number of paced steps.
"""
from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ipcosim.harness.master.observers import Observer

NS = 1_000_000_000


def wait_until(deadline_ns: int, clock_ns: Callable[[], int] = time.perf_counter_ns,
               spin_ns: int = 200_000, sleep: Callable[[float], None] = time.sleep) -> int:
    """Sleep, then spin, until ``clock_ns() >= deadline_ns``.

    Parameters
    ----------
    deadline_ns : int
        The instant to wait for, on ``clock_ns``'s scale.
    clock_ns : callable
        Monotonic clock in nanoseconds.
    spin_ns : int
        Sleep only until this long before the deadline, then busy-wait.
    sleep : callable
        ``sleep(seconds)``.

    Returns
    -------
    int
        The clock reading when the wait ended (>= ``deadline_ns``).
    """
    now = clock_ns()
    remaining = deadline_ns - now
    if remaining > spin_ns:
        sleep((remaining - spin_ns) / NS)
        now = clock_ns()
    while now < deadline_ns:
        now = clock_ns()
    return now


@dataclass(frozen=True)
class RealtimeStats:
    """Timing statistics of a paced run [s]."""

    steps: int
    period_jitter_p50: float
    period_jitter_p99: float
    period_jitter_max: float
    overruns: int
    worst_step_time: float
    lateness_p99: float
    lateness_max: float

    def as_metrics(self) -> dict[str, float | int]:
        """The metrics.json keys (see the module docstring)."""
        return {"period_jitter_p50_s": self.period_jitter_p50, "period_jitter_p99_s": self.period_jitter_p99,
                "period_jitter_max_s": self.period_jitter_max, "overruns": self.overruns,
                "worst_step_time_s": self.worst_step_time, "lateness_p99_s": self.lateness_p99,
                "lateness_max_s": self.lateness_max, "realtime_steps": self.steps}

    def summary(self) -> str:
        """One line for humans."""
        us = 1e6
        return (f"{self.steps} steps: period jitter p50 {self.period_jitter_p50 * us:.0f} us, "
                f"p99 {self.period_jitter_p99 * us:.0f} us, max {self.period_jitter_max * us:.0f} us; "
                f"{self.overruns} overruns; worst step {self.worst_step_time * us:.0f} us")


class Pacer:
    """Paces steps ``n = 0, 1, 2, ...`` of period ``period`` to the wall clock.

    Use: ``begin(n)`` before step ``n`` (waits for its deadline), ``end(n)`` after it.

    Parameters
    ----------
    period : float
        Step period [s].
    clock_ns : callable
        Monotonic clock [ns] (injectable for tests).
    sleep : callable
        ``sleep(seconds)`` (injectable for tests).
    spin : float
        Busy-wait this long before each deadline [s].
    tolerance : float, optional
        Lateness beyond which a step counts as an overrun [s] (default ``period / 2``).
    """

    def __init__(self, period: float, *, clock_ns: Callable[[], int] = time.perf_counter_ns,
                 sleep: Callable[[float], None] = time.sleep, spin: float = 200e-6,
                 tolerance: float | None = None) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"real-time period = {period} s must be positive")
        self.period_ns = int(round(period * NS))
        self.clock_ns = clock_ns
        self.sleep = sleep
        self.spin_ns = int(round(spin * NS))
        self.tolerance_ns = int(round((period / 2 if tolerance is None else tolerance) * NS))
        self.t0_ns: int | None = None
        self._first_tick = 0
        self._starts: list[int] = []
        self._lateness: list[int] = []
        self._durations: list[int] = []
        self._current_start = 0

    def start(self, first_tick: int = 0, t0_ns: int | None = None) -> None:
        """Anchor tick ``first_tick`` at ``t0_ns`` (default: now)."""
        self._first_tick = first_tick
        self.t0_ns = self.clock_ns() if t0_ns is None else t0_ns

    def deadline_ns(self, tick: int) -> int:
        """Clock reading at which step ``tick`` may start."""
        if self.t0_ns is None:
            self.start(tick)
        assert self.t0_ns is not None
        return self.t0_ns + (tick - self._first_tick) * self.period_ns

    def begin(self, tick: int) -> int:
        """Wait for step ``tick``'s deadline; returns its lateness [ns] (0 if on time)."""
        deadline = self.deadline_ns(tick)
        now = wait_until(deadline, self.clock_ns, self.spin_ns, self.sleep)
        self._current_start = now
        self._starts.append(now)
        late = now - deadline
        self._lateness.append(late)
        return late

    def end(self, tick: int | None = None) -> int:
        """Mark the end of the current step; returns its duration [ns]."""
        d = self.clock_ns() - self._current_start
        self._durations.append(d)
        return d

    def stats(self) -> RealtimeStats:
        """Statistics so far (jitter zero for fewer than three steps)."""
        starts = np.asarray(self._starts, dtype=np.int64)
        if len(starts):
            schedule = np.arange(len(starts), dtype=np.int64) * self.period_ns
            late = starts - schedule
            # anchored at the earliest-running step (see the module doc); the first step starts
            # when the pacer does and says nothing about the schedule
            late -= late[1:].min() if len(late) > 1 else late[0]
            np.maximum(late, 0, out=late)
        else:
            late = np.zeros(0, dtype=np.int64)
        dur = np.asarray(self._durations, dtype=np.int64)
        if len(starts) >= 3:
            jitter = np.abs(np.diff(starts[1:]) - self.period_ns) / NS
            p50, p99, jmax = (float(np.percentile(jitter, 50)), float(np.percentile(jitter, 99)),
                              float(jitter.max()))
        else:
            p50 = p99 = jmax = 0.0
        return RealtimeStats(steps=len(starts), period_jitter_p50=p50, period_jitter_p99=p99,
                             period_jitter_max=jmax, overruns=int(np.count_nonzero(late > self.tolerance_ns)),
                             worst_step_time=float(dur.max()) / NS if len(dur) else 0.0,
                             lateness_p99=float(np.percentile(late, 99)) / NS if len(late) else 0.0,
                             lateness_max=float(late.max()) / NS if len(late) else 0.0)

    def metrics(self) -> dict[str, float | int]:
        """``stats().as_metrics()``."""
        return self.stats().as_metrics()


class RealtimePacer(Observer):
    """Observer (``ipcosim.harness.master.observers``) pacing a co-simulation to the wall clock.

    Step ``n`` (from ``t_n`` to ``t_n+1``) starts no earlier than ``t0 + n*h`` on the host's
    clock. Its :meth:`metrics` add the statistics of :class:`RealtimeStats` to metrics.json,
    plus ``card_overruns``: the sum of the ``overruns`` outputs of the components that have
    one (the HIL adapter counts the steps whose request reached the card after their sample
    instant), read after the last step.

    Parameters
    ----------
    spin : float
        Busy-wait this long before each deadline [s].
    tolerance : float, optional
        Overrun tolerance [s] (default half a step).
    """

    def __init__(self, spin: float = 200e-6, tolerance: float | None = None) -> None:
        self.spin = spin
        self.tolerance = tolerance
        self.pacer: Pacer | None = None
        self._open = False
        self._card_overruns: int | None = None

    def start(self, execution) -> None:  # noqa: ANN001 -- ipcosim.harness.master.execution.Execution
        # No cyclic garbage collection while paced: a full collection of a process holding
        # numpy, fmpy and the FMUs takes milliseconds. Reference counting still frees everything
        # that is not in a cycle; the collector runs again (and once now) around the run.
        gc.collect()
        self._gc_was_enabled = gc.isenabled()
        gc.disable()
        self.pacer = Pacer(execution.step_size, spin=self.spin, tolerance=self.tolerance)
        self.pacer.start(0)
        self.pacer.begin(0)
        self._open = True

    def next_tick(self, n: int) -> int | None:
        return n + 1

    def step(self, execution, n: int) -> None:  # noqa: ANN001
        assert self.pacer is not None
        self.pacer.end()
        self._open = False
        if n >= execution.n_ticks:
            self._read_card_overruns(execution)
            return
        self.pacer.begin(n)
        self._open = True

    def finish(self, execution, error: BaseException | None) -> None:  # noqa: ANN001
        if self._open and self.pacer is not None:
            self.pacer.end()
            self._open = False
        if getattr(self, "_gc_was_enabled", False):
            gc.enable()

    def _read_card_overruns(self, execution) -> None:  # noqa: ANN001
        total = None
        for inst, slave in zip(execution.instances, execution.slaves):
            var = inst.model.variables.get("overruns")
            if var is None or var.causality != "output":
                continue
            try:
                total = (total or 0) + int(slave.get_values([var])[0])
            except Exception:  # noqa: BLE001 -- statistics must not fail a run
                pass
        self._card_overruns = total

    def metrics(self) -> dict[str, float | int]:
        if self.pacer is None:
            return {}
        out = self.pacer.metrics()
        if self._card_overruns is not None:
            out["card_overruns"] = self._card_overruns
        return out
