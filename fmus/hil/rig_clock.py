"""The rig's timekeeping, which :class:`~ipcosim.fmus.hil.rig.VirtualRig` composes: the card's watchdog
(its registers: :class:`Watchdog`, as on the Q4, see :mod:`ipcosim.fmus.hil.api`) and the rig's clock
(:class:`RigClock`: lockstep or the host's monotonic clock), both in integer nanoseconds of rig time.
"""
from __future__ import annotations

import time
from typing import Callable


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
