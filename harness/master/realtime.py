"""Real-time pacing of a fixed-step loop, and its timing statistics.

:class:`Pacer` holds a loop of period ``h`` to the wall clock. Step ``n`` may start no
earlier than its deadline ``t0 + n*h``, computed from integer nanoseconds every time
(never by adding periods, so no drift accumulates, and a late step does not shift the
following deadlines). Waiting is "sleep, then spin": sleep until ``spin`` before the
deadline, then busy-wait on the clock to the deadline itself. The spin is 0.2 ms under a
real-time policy (the OS wakes a sleeper tens of microseconds late; a real-time process
takes no one's share by spinning) and none under the default policy, where a process that
spins spends its fair share of a CPU and is then woken behind a busy neighbour (see
:func:`default_spin`); there the timer slack is cut to 1 us instead (:func:`realtime_setup`).
On the C stepping loop the loop itself waits, on the pacer's schedule (``CLoop.pace``, :meth:`Pacer.took`).

Statistics (:meth:`Pacer.metrics`, the keys ``ipcosim run --realtime`` adds to
metrics.json):

``period_jitter_p50_s``, ``period_jitter_p99_s``, ``period_jitter_max_s``
    Percentiles of ``|actual period - h|``, the actual period being the time between
    the starts of consecutive steps (from the second step on: the first one starts when
    the pacer does).
``overruns``, ``overrun_fraction``
    Steps (and their fraction of ``realtime_steps``) that started later than ``tolerance``
    (default: half a period) after their deadline, i.e. whose predecessor ended that late.
    Lateness is measured against the schedule ``t0 + n*h`` anchored at the step that ran earliest: when the pacer paces,
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
``lateness_histogram``
    Steps by lateness: ``{"<50us": n, "50-100us": n, ..., ">=5ms": n}``.
``realtime_setup``
    What the pacer arranged, each item ``applied ...`` or ``not applied: why``: ``gc``
    (cyclic garbage collection off during the loop, start-up objects frozen), ``cpu_affinity``
    and ``sched_fifo`` (only when asked for), ``sched_slice`` (under the default policy) and
    ``timer_slack``.
``loop_cpu_per_step_us``
    The process's CPU time over the paced steps, per step [us]: on a busy host the share of late
    steps grows with it (docs/hil.md, "Real time on your host").
``realtime_priority``
    Whether the run was under real-time priority (``SCHED_FIFO``, ``IPCOSIM_RT_PRIORITY``).
``overrun_budget``, ``overrun_budget_exceeded``
    The overrun fraction allowed (``ipcosim run --overrun-budget``, else
    ``IPCOSIM_RT_OVERRUN_BUDGET``, else :data:`DEFAULT_OVERRUN_BUDGET`) and whether the run went
    beyond it: such a run was degraded by the host (its control may differ from the
    controller's real behaviour); :func:`budget_warning` is the one line that says so.

Options come from the environment, so that any run (``ipcosim run``, the Python API, a
study) can ask for them without new arguments:

``IPCOSIM_RT_CPU=K``
    Pin the process to CPU ``K`` (``os.sched_setaffinity``).
``IPCOSIM_RT_PRIORITY=P``
    Run under ``SCHED_FIFO`` at priority ``P`` (1..99) while paced (needs CAP_SYS_NICE or
    an rtprio limit; otherwise reported as not applied and the run goes on).
``IPCOSIM_RT_SLICE_US=S``
    Under the default policy (no ``SCHED_FIFO``), ask Linux's fair scheduler (6.12 and later, no
    privilege needed) for a time slice of ``S`` microseconds instead of its default (0.7 ms times
    1 + log2 of the CPU count: 1.4 ms on 2 CPUs): a waking loop with a shorter slice than a CPU
    hog's preempts it at once instead of waiting out the hog's slice. Default
    :data:`DEFAULT_SLICE_US`; ``0`` leaves the slice alone.
``IPCOSIM_RT_OVERRUN_BUDGET=F``
    Overruns allowed, as a fraction of the steps (e.g. ``0.005``), where the run is not given
    one (``ipcosim run --overrun-budget``); default :data:`DEFAULT_OVERRUN_BUDGET`.
``IPCOSIM_RT_TIMELINE=FILE``
    Write every step's start (host monotonic clock [ns], shared by the machine's processes)
    and lateness [ns] to ``FILE`` (``.npz``: ``starts_ns``, ``lateness_ns``, ``period_ns``)
    when the run ends, to lay the loop's timing beside another process's, e.g. a probe of the
    host's stalls (docs/hil.md, Measured).

What a run learns from a card it drives (its faults, its overruns) is recorded by the
hardware-in-the-loop room's own observer, :mod:`ipcosim.harness.hil.observer`.
"""
from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ipcosim.harness.master.host_setup import env_number, realtime_setup
from ipcosim.harness.master.observers import Observer

NS = 1_000_000_000


#: The spin before a deadline under a real-time policy [s].
RT_SPIN = 200e-6


def default_spin() -> float:
    """:data:`RT_SPIN` when this thread runs under a real-time policy (SCHED_FIFO or SCHED_RR), else 0 [s].

    Measured at 1 kHz beside two CPU hogs (docs/hil.md): a run that spun 0.2 ms a step under the
    default policy had up to ten times the late steps of one that slept to the deadline.
    """
    try:
        return RT_SPIN if os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR) else 0.0
    except (AttributeError, OSError):     # no scheduling policies on this OS
        return 0.0


def wait_until(deadline_ns: int, clock_ns: Callable[[], int] = time.monotonic_ns,
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
    while deadline_ns - now > spin_ns:      # a sleep may end early (signals): sleep again
        sleep((deadline_ns - now - spin_ns) / NS)
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
    lateness_histogram: dict[str, int] = field(default_factory=dict)

    def as_metrics(self) -> dict[str, Any]:
        """The metrics.json keys (see the module docstring)."""
        return {"period_jitter_p50_s": self.period_jitter_p50, "period_jitter_p99_s": self.period_jitter_p99,
                "period_jitter_max_s": self.period_jitter_max, "overruns": self.overruns,
                "worst_step_time_s": self.worst_step_time, "lateness_p99_s": self.lateness_p99,
                "lateness_max_s": self.lateness_max, "realtime_steps": self.steps,
                "overrun_fraction": self.overruns / self.steps if self.steps else 0.0,
                "lateness_histogram": dict(self.lateness_histogram)}

    def summary(self) -> str:
        """One line for humans."""
        us = 1e6
        return (f"{self.steps} steps: period jitter p50 {self.period_jitter_p50 * us:.0f} us, "
                f"p99 {self.period_jitter_p99 * us:.0f} us, max {self.period_jitter_max * us:.0f} us; "
                f"{self.overruns} overruns; worst step {self.worst_step_time * us:.0f} us")


#: A step is *late* when it starts this long or more after its deadline [s]: the one threshold of
#: every late fraction, a run's (:func:`late_fraction`) and the host's floor measured beside it
#: (a bare C loop on ``clock_nanosleep``, docs/hil.md). An edge of the lateness histogram's bins.
LATE_S = 500e-6
#: Upper edges of the lateness histogram's bins [us] (the last bin is open).
LATENESS_BINS_US = (50, 100, 250, round(LATE_S * 1e6), 1000, 2000, 5000)


def _bin_labels() -> list[str]:
    """The histogram's keys, in the order of its bins."""
    edges = LATENESS_BINS_US
    return [f"<{edges[0]}us"] + [f"{a}-{b}us" for a, b in zip(edges, edges[1:])] + [f">={edges[-1]}us"]


def lateness_histogram(late_ns: np.ndarray) -> dict[str, int]:
    """Count steps by lateness into the bins of ``LATENESS_BINS_US`` (keys like ``"100-250us"``)."""
    edges = np.asarray(LATENESS_BINS_US, dtype=np.int64) * 1000
    counts = np.bincount(np.searchsorted(edges, np.asarray(late_ns, dtype=np.int64), side="right"),
                         minlength=len(edges) + 1)
    return {label: int(n) for label, n in zip(_bin_labels(), counts)}


def late_fraction(metrics: dict[str, Any]) -> float:
    """The fraction of a paced run's steps that started :data:`LATE_S` or more late.

    Parameters
    ----------
    metrics : dict
        A paced run's metrics (``lateness_histogram`` and ``realtime_steps``).

    Returns
    -------
    float
        Late steps / steps, from the run's own histogram (its bins from :data:`LATE_S` on).
    """
    first = LATENESS_BINS_US.index(round(LATE_S * 1e6)) + 1
    late = sum(metrics["lateness_histogram"].get(label, 0) for label in _bin_labels()[first:])
    return late / metrics["realtime_steps"] if metrics["realtime_steps"] else 0.0


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
    spin : float, optional
        Busy-wait this long before each deadline [s] (default :func:`default_spin`).
    tolerance : float, optional
        Lateness beyond which a step counts as an overrun [s] (default ``period / 2``).
    """

    def __init__(self, period: float, *, clock_ns: Callable[[], int] = time.monotonic_ns,
                 sleep: Callable[[float], None] = time.sleep, spin: float | None = None,
                 tolerance: float | None = None) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"real-time period = {period} s must be positive")
        self.period_ns = int(round(period * NS))
        self.clock_ns = clock_ns
        self.sleep = sleep
        self.spin_ns = int(round((default_spin() if spin is None else spin) * NS))
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

    def took(self, first_tick: int, starts: Sequence[int], ends: Sequence[int]) -> None:
        """Ticks ``first_tick``, ``first_tick + 1``, ... paced by the C stepping loop on this pacer's schedule
        (``CLoop.pace``): their starts and ends [ns]."""
        for k, (start, end) in enumerate(zip(starts, ends)):
            self._starts.append(start)
            self._lateness.append(start - self.deadline_ns(first_tick + k))
            self._durations.append(end - start)

    def lateness_since(self, k: int) -> list[int]:
        """How late steps ``k``, ``k + 1``, ... started [ns] against the deadlines they waited for (a
        running count for a live view; :meth:`lateness_ns` is the run's own account)."""
        return self._lateness[k:]

    def starts_ns(self) -> np.ndarray:
        """The clock readings at which the steps so far started [ns]."""
        return np.asarray(self._starts, dtype=np.int64)

    def lateness_ns(self) -> np.ndarray:
        """How late each step so far started [ns], against the schedule anchored at the
        earliest-running step (see the module doc); the first step starts when the pacer does
        and says nothing about the schedule."""
        starts = self.starts_ns()
        if not len(starts):
            return np.zeros(0, dtype=np.int64)
        late = starts - np.arange(len(starts), dtype=np.int64) * self.period_ns
        late -= late[1:].min() if len(late) > 1 else late[0]
        return np.maximum(late, 0)

    def stats(self) -> RealtimeStats:
        """Statistics so far (jitter zero for fewer than three steps)."""
        starts, late = self.starts_ns(), self.lateness_ns()
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
                             lateness_max=float(late.max()) / NS if len(late) else 0.0,
                             lateness_histogram=lateness_histogram(late))

    def metrics(self) -> dict[str, float | int]:
        """``stats().as_metrics()``."""
        return self.stats().as_metrics()


#: Overruns a paced run may have, as a fraction of its steps, before it counts as degraded.
DEFAULT_OVERRUN_BUDGET = 0.01


def budget_warning(metrics: dict[str, Any]) -> str | None:
    """The one line telling that a paced run went over its overrun budget (None if it did not).

    Parameters
    ----------
    metrics : dict
        A run's metrics (the keys :class:`RealtimePacer` adds).
    """
    if not metrics.get("overrun_budget_exceeded"):
        return None
    priority = ("under real-time priority" if metrics.get("realtime_priority") else
                "real-time priority not in force (IPCOSIM_RT_PRIORITY=P; the rig: ipcosim rig serve --rt-priority P)")
    return (f"real-time run degraded: {100 * metrics['overrun_fraction']:.2f} % of {metrics['realtime_steps']} steps "
            f"started late (budget {100 * metrics['overrun_budget']:.2f} %, --overrun-budget), worst lateness "
            f"{1e3 * metrics['lateness_max_s']:.3g} ms, {priority}: the results may not show the controller's "
            f"behaviour on a real-time host")


#: A paced run hands its rows to the writer this often [s] (wall clock = simulated time): 20 rows at
#: 1 kHz cost 0.25-0.45 ms (measured), inside a step's slack, where 0.2 s of rows took 1-5 ms.
PACED_WRITE_SECONDS = 0.02


class RealtimePacer(Observer):
    """Observer (``ipcosim.harness.master.observers``) pacing a co-simulation to the wall clock.

    Step ``n`` (from ``t_n`` to ``t_n+1``) starts no earlier than ``t0 + n*h`` on the host's
    monotonic clock. The first step is the start-up step of real-time components (the HIL
    adapter opens its card and arms the watchdog there, whatever the other components'
    initialization took), and the schedule is anchored when it ends: ``t0`` is the end of
    step 0. Its :meth:`metrics` add the statistics of :class:`RealtimeStats` to
    metrics.json and ``realtime_setup`` (see :func:`realtime_setup`).

    Parameters
    ----------
    spin : float, optional
        Busy-wait this long before each deadline [s] (default: :func:`default_spin` once the
        real-time setup is in force).
    tolerance : float, optional
        Overrun tolerance [s] (default half a step).
    overrun_budget : float, optional
        Allowed overruns as a fraction of the steps (default: ``IPCOSIM_RT_OVERRUN_BUDGET``, else
        :data:`DEFAULT_OVERRUN_BUDGET`).
    """

    def __init__(self, spin: float | None = None, tolerance: float | None = None,
                 overrun_budget: float | None = None) -> None:
        self.spin = spin
        self.tolerance = tolerance
        if overrun_budget is None:
            overrun_budget = env_number("IPCOSIM_RT_OVERRUN_BUDGET", float, 0.0, 1.0)
        self.overrun_budget: float = DEFAULT_OVERRUN_BUDGET if overrun_budget is None else overrun_budget
        self.pacer: Pacer | None = None
        self._open = False
        self._setup: dict[str, str] = {}
        self._restore: Callable[[], None] = lambda: None
        self._over_budget = False
        self._cpu_s: list[float] = []      # process CPU time when the schedule starts, and at the end
        self._in_loop = False              # whether the C loop paces the ticks (from tick 1 on)

    def start(self, execution) -> None:  # noqa: ANN001 -- ipcosim.harness.master.execution.Execution
        self._setup, self._restore = realtime_setup()
        rows_per_second = 1 / (execution.step_size * execution.record_every)
        execution.recorder.max_pending_rows = max(1, int(PACED_WRITE_SECONDS * rows_per_second))
        self.pacer = Pacer(execution.step_size, spin=self.spin, tolerance=self.tolerance)
        self.pacer.start(0)
        self.pacer.begin(0)
        self._open = True

    def next_tick(self, n: int) -> int | None:
        return None if self._in_loop else n + 1

    def step(self, execution, n: int) -> None:  # noqa: ANN001
        assert self.pacer is not None
        if self._in_loop:       # the C loop paces every tick itself
            return
        self.pacer.end()
        self._open = False
        if n >= execution.n_ticks:
            return
        if n == 1:      # the start-up step is done: the real-time schedule starts now
            self.pacer.start(1)
            self._cpu_s = [time.process_time()]
            if self._pace_in_loop(execution):
                return
        self.pacer.begin(n)
        self._open = True

    def _pace_in_loop(self, execution) -> bool:  # noqa: ANN001
        """From tick 1 on, let the C stepping loop wait for each deadline itself (``CLoop.pace``), where the
        run has one and the pacer keeps the host's clock: the ticks between two writes of rows then run with
        no Python between them, and this observer is not called again."""
        loop, pacer = getattr(execution, "cloop", None), self.pacer
        if (loop is None or pacer is None or pacer.clock_ns is not time.monotonic_ns or pacer.sleep is not time.sleep
                or not loop.pace(pacer)):
            return False
        self._in_loop = True
        return True

    def finish(self, execution, error: BaseException | None) -> None:  # noqa: ANN001
        if self._open and self.pacer is not None:
            self.pacer.end()
            self._open = False
        if self._in_loop:
            execution.cloop.pace(None)
        self._restore()
        self._cpu_s[1:] = [time.process_time()] if self._cpu_s else []
        if self.pacer is not None:
            st = self.pacer.stats()
            self._over_budget = bool(st.steps) and st.overruns > self.overrun_budget * st.steps
            timeline = os.environ.get("IPCOSIM_RT_TIMELINE", "").strip()
            if timeline:
                try:
                    np.savez(timeline, starts_ns=self.pacer.starts_ns(), lateness_ns=self.pacer.lateness_ns(),
                             period_ns=self.pacer.period_ns)
                except OSError as exc:
                    print(f"ipcosim run: IPCOSIM_RT_TIMELINE={timeline}: not written ({exc.strerror or exc})",
                          file=sys.stderr)

    def metrics(self) -> dict[str, Any]:
        if self.pacer is None:
            return {}
        out: dict[str, Any] = self.pacer.metrics()
        paced = out["realtime_steps"] - 1         # the steps after the start-up step
        if len(self._cpu_s) == 2 and paced > 0:
            out["loop_cpu_per_step_us"] = round(1e6 * (self._cpu_s[1] - self._cpu_s[0]) / paced, 1)
        out["realtime_setup"] = dict(self._setup)
        out["realtime_priority"] = self._setup.get("sched_fifo", "").startswith("applied")
        out["overrun_budget"] = self.overrun_budget
        out["overrun_budget_exceeded"] = self._over_budget
        return out
