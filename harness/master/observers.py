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
    """A progress bar on ``stream`` for runs that last longer than ``delay`` seconds.

    Parameters
    ----------
    stream : text stream
        Where to draw (stderr by default); nothing is drawn unless it is a terminal or
        ``force`` is set.
    delay : float
        Wall-clock seconds before the bar appears.
    """

    def __init__(self, stream: TextIO | None = None, delay: float = 1.0, force: bool = False, width: int = 30) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.delay = delay
        self.width = width
        self.enabled = force or bool(getattr(self.stream, "isatty", lambda: False)())
        self.shown = False
        self._every = 1
        self._t0 = 0.0
        self._total = 1

    def start(self, execution: "Execution") -> None:
        self._t0 = time.perf_counter()
        self._total = execution.n_ticks
        self._every = max(1, execution.n_ticks // 200)

    def next_tick(self, n: int) -> int | None:
        if not self.enabled:
            return None
        return (n // self._every + 1) * self._every

    def step(self, execution: "Execution", n: int) -> None:
        elapsed = time.perf_counter() - self._t0
        if elapsed < self.delay:
            return
        self.shown = True
        frac = n / self._total
        filled = int(self.width * frac)
        eta = elapsed / frac - elapsed if frac > 0 else 0.0
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {100 * frac:5.1f}%  "
                          f"t = {execution.time_of(n):.3f} s  ETA {eta:5.1f} s")
        self.stream.flush()

    def finish(self, execution: "Execution", error: BaseException | None) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()
