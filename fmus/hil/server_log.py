"""What the rig server writes of its clients to its log: their text escaped (:func:`escape`) and the lines
rate-limited (:class:`RateLimitedLog`), so that no client can forge or flood the log
(:mod:`ipcosim.fmus.hil.server`).
"""
from __future__ import annotations

import threading
import time
from typing import Callable


def escape(text: str, limit: int = 80) -> str:
    """Client-sent text made safe for a one-line log: control and non-ASCII characters escaped, length capped."""
    out = text[:limit].encode("unicode_escape").decode("ascii").replace('"', '\\"')
    return out + ("..." if len(text) > limit else "")


class RateLimitedLog:
    """``log(line)`` passed on at most ``rate`` lines a second on average (bursts of ``burst``);
    lines beyond are counted and reported in one line once lines may pass again.

    Everything the server logs because of what a client did goes through it: a client that
    reconnects in a loop, or several at once, cannot flood the log.
    """

    def __init__(self, log: Callable[[str], None], rate: float = 10.0, burst: int = 30,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._log, self.rate, self.burst, self._clock = log, float(rate), int(burst), clock
        self._tokens = float(burst)
        self._last = clock()
        self.suppressed = 0
        self._lock = threading.Lock()

    def __call__(self, line: str) -> None:
        with self._lock:
            now = self._clock()
            self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
            self._last = now
            if self._tokens < 1.0:
                self.suppressed += 1
                return
            self._tokens -= 1.0
            pending, self.suppressed = self.suppressed, 0
        if pending:
            self._log(f"rig: {pending} log lines suppressed (more than {self.rate:g} a second)")
        self._log(line)
