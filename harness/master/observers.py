"""Observers: what watches an execution without changing it (recording, progress, metrics,
real-time pacing and statistics).

An observer is called at the start (state at ``t0``, after initialization), at the ticks it
asks for, and at the end (also after a failure). Asking for few ticks keeps the stepping loop
free of Python calls; an observer that needs every step (real-time pacing) asks for every
tick. The order inside one tick is fixed: manipulators, the algorithm's step, observers.

Interface (subclass :class:`Observer`, override what you need)::

    start(execution)            after initialization; execution.tick == 0
    next_tick(n) -> int | None  the next tick count (> n) at which to call step; None: never
    step(execution, n)          after n ticks, i.e. at time execution.time_of(n)
    finish(execution, error)    once, at the end; error is the exception or None
    metrics() -> dict           entries merged into the run's metrics.json

The result recorder itself is built into the stepping loop (one ``memmove`` per step, see
``ipcosim.harness.master.pyloop``); :class:`Progress` is the progress bar. Real-time pacing is
:class:`ipcosim.harness.master.realtime.RealtimePacer`, which the run engine adds when a run
asks for ``realtime=True`` or a swapped-in component asks for it.
"""
from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.execution import Execution



class Observer:
    """Base class of observers (every hook does nothing)."""

    def start(self, execution: "Execution") -> None:
        """Called once after initialization (``execution.tick == 0``)."""

    def next_tick(self, n: int) -> int | None:
        """The next tick count after ``n`` at which :meth:`step` is to be called, or None."""
        return None

    def step(self, execution: "Execution", n: int) -> None:
        """Called when ``n`` ticks are done (simulated time ``execution.time_of(n)``)."""

    def finish(self, execution: "Execution", error: BaseException | None) -> None:
        """Called once at the end, also after a failure."""

    def metrics(self) -> dict[str, Any]:
        """Entries to merge into the run's metrics."""
        return {}


class Progress(Observer):
    """The run's progress on ``stream`` for runs that last longer than ``delay`` seconds: a bar
    redrawn in place on a terminal; elsewhere (a pipe, a log file) a plain line every ``interval``
    seconds of wall time, the first after ``max(delay, 2 s)``, and one at the end.

    Parameters
    ----------
    stream : text stream
        Where to write (stderr by default).
    delay : float
        Wall-clock seconds before the bar appears.
    force : bool
        Draw the terminal's bar whatever ``stream`` is.
    interval : float
        Wall-clock seconds between two lines where ``stream`` is not a terminal.
    """

    def __init__(self, stream: TextIO | None = None, delay: float = 1.0, force: bool = False, width: int = 30,
                 interval: float = 5.0) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.delay = delay
        self.width = width
        self.tty = force or bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval
        self.shown = False
        self._every = 1
        self._t0 = 0.0
        self._total = 1
        self._next_line = 0.0

    def start(self, execution: "Execution") -> None:
        self._t0 = time.perf_counter()
        self._total = execution.n_ticks
        self._every = max(1, execution.n_ticks // 200)
        self._next_line = max(self.delay, 2.0)

    def next_tick(self, n: int) -> int | None:
        return (n // self._every + 1) * self._every

    def step(self, execution: "Execution", n: int) -> None:
        elapsed = time.perf_counter() - self._t0
        if elapsed < self.delay:
            return
        frac = n / self._total
        eta = elapsed / frac - elapsed if frac > 0 else 0.0
        if not self.tty:
            if elapsed >= self._next_line:
                self.shown = True
                self._next_line = elapsed + self.interval
                self._line(execution, n, elapsed, eta)
            return
        self.shown = True
        filled = int(self.width * frac)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {100 * frac:5.1f}%  "
                          f"t = {execution.time_of(n):.3f} s  ETA {eta:5.1f} s")
        self.stream.flush()

    def _line(self, execution: "Execution", n: int, elapsed: float, eta: float) -> None:
        """One plain line: how far the run is, in simulated and wall time."""
        self.stream.write(f"run: {100 * n / self._total:5.1f} %  t = {execution.time_of(n):.3f} s of "
                          f"{execution.time_of(self._total):.3f} s, {elapsed:.1f} s elapsed, ETA {eta:.1f} s\n")
        self.stream.flush()

    def finish(self, execution: "Execution", error: BaseException | None) -> None:
        if self.shown and not self.tty:
            if error is None:
                self._line(execution, self._total, time.perf_counter() - self._t0, 0.0)
            return
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()
