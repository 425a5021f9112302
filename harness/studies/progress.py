"""A sweep's progress bar on stderr: runs done of the total, their statuses, the rate and the time left.
"""
from __future__ import annotations

import math
import sys
import time
from typing import TextIO

from ipcosim.harness.studies.runners import STATUSES


class SweepProgress:
    """A one-line progress bar on stderr (redrawn in place on a terminal; on a pipe, a line
    every 10 % or 30 s)."""

    def __init__(self, total: int, done: int = 0, stream: TextIO | None = None, enabled: bool = True,
                 label: str = "sweep") -> None:
        self.total, self.done, self.label = total, done, label
        self.stream = stream or sys.stderr
        self.enabled = enabled and total > 0
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.counts = {s: 0 for s in STATUSES}
        self.start = time.monotonic()
        self.new = 0
        self._last_print = 0.0
        self._last_decile = -1

    def show(self) -> None:
        """Draw the bar now (before the first run ends: a sweep shows its size at once)."""
        if self.enabled:
            self._draw(end="\r" if self.tty else "\n")
            self._last_print = time.monotonic()
            self._last_decile = int(10 * self.done / self.total)

    def update(self, status: str) -> None:
        self.done += 1
        self.new += 1
        self.counts[status] = self.counts.get(status, 0) + 1
        if not self.enabled:
            return
        now = time.monotonic()
        decile = int(10 * self.done / self.total)
        if self.tty:
            if now - self._last_print > 0.1 or self.done == self.total:
                self._draw(end="\r")
                self._last_print = now
        elif decile != self._last_decile or now - self._last_print > 30:
            self._draw(end="\n")
            self._last_print, self._last_decile = now, decile

    def _draw(self, end: str) -> None:
        width = 24
        filled = int(width * self.done / self.total)
        elapsed = time.monotonic() - self.start
        rate = 60.0 * self.new / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / (rate / 60.0) if rate > 0 else math.nan
        eta = f"{int(left // 60)}:{int(left % 60):02d}" if math.isfinite(left) else "--:--"
        counts = " ".join(f"{s} {n}" for s, n in self.counts.items() if n)
        self.stream.write(f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} "
                          f"{counts}  {rate:.1f} runs/min  eta {eta}   {end}")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()
