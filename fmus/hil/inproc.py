"""In-process backend: a :class:`Card` calling a :class:`VirtualRig` directly (no network).

Card id ``N@inproc://NAME[?plant=double-mass&clock=lockstep]``: the rig registered under
``NAME`` (:func:`register_rig`), or a new one made from the query and registered. Used
for deterministic tests, and by tests that want to look inside the rig they drive.
"""
from __future__ import annotations

import threading
from typing import Sequence

import numpy as np

from ipcosim.fmus.hil.api import Card, ErrorCode, HILError, RigStatus, StepResult
from ipcosim.fmus.hil.rig import VirtualRig
from ipcosim.fmus.hil.rig_config import NS, RigConfig, to_ns


def _process_registry() -> tuple[dict, dict, threading.Lock]:
    """The one registry of in-process rigs of this process, whatever copy of this module asks.

    Every FMU carries its own private copy of this module (``ipcosim.fmus.pybuild``), so a
    module-level dict would give each FMU, and the host, a registry of its own. The registry
    lives on the ``threading`` module instead: a standard-library module every copy shares.
    Its layout (rigs by name, controlling card by rig id, a lock) is versioned by the name.
    """
    key = "_ipcosim_inproc_registry_v1"
    registry = getattr(threading, key, None)
    if registry is None:
        registry = ({}, {}, threading.Lock())
        setattr(threading, key, registry)
    return registry


_RIGS, _OWNERS, _LOCK = _process_registry()


def register_rig(name: str, rig: VirtualRig) -> VirtualRig:
    """Make ``rig`` reachable as ``0@inproc://NAME``; returns it."""
    with _LOCK:
        _RIGS[name] = rig
    return rig


def unregister_rig(name: str) -> None:
    """Forget the rig registered under ``name`` (if any)."""
    with _LOCK:
        _RIGS.pop(name, None)


def get_rig(name: str, config: RigConfig | None = None) -> VirtualRig:
    """The rig registered under ``name``, created from ``config`` if there is none."""
    with _LOCK:
        rig = _RIGS.get(name)
        if rig is None:
            rig = _RIGS[name] = VirtualRig(config or RigConfig())
        return rig


class _SameErrors:
    """Calls into a rig, with its ``HILError`` made this module's own.

    A rig registered by the host (or another FMU) raises the ``HILError`` of its own copy of
    the HIL package, which this copy's ``except HILError`` would not catch; the error is
    re-raised as this copy's class with the same code and message.
    """

    def __init__(self, rig: VirtualRig) -> None:
        self._rig = rig

    def __getattr__(self, name: str):  # noqa: ANN204 -- forwards any rig method
        method = getattr(self._rig, name)

        def call(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            try:
                return method(*args, **kwargs)
            except HILError:
                raise
            except Exception as exc:
                if type(exc).__name__ == "HILError" and hasattr(exc, "code") and hasattr(exc, "message"):
                    raise HILError(exc.code, exc.message) from None
                raise
        return call


class VirtualCard(Card):
    """A card on an in-process :class:`VirtualRig` (one controlling card per rig)."""

    def __init__(self, rig: VirtualRig, card_type: str = "q4", card_id: str = "0@inproc://rig",
                 who: str = "in-process client") -> None:
        with _LOCK:
            holder = _OWNERS.get(id(rig))
            if holder is not None and not holder._closed:
                raise HILError(ErrorCode.BUSY, f"rig busy: {card_id} is already controlled by another card in "
                                               f"this process; one controlling client at a time")
            _OWNERS[id(rig)] = self
        self.rig = rig
        self.info = rig.info(card_type, card_id)
        self._closed = False
        #: How long the last :meth:`step` waited for its sample instant [ns].
        self.last_wait_ns = 0
        #: As :attr:`TcpipCard.defer_wait <ipcosim.fmus.hil.tcpip.TcpipCard.defer_wait>`: with it, a wall-clock
        #: :meth:`step` returns with its reading at once and the next one waits for its sample instant.
        self.defer_wait = False
        self._deferred_ns: int | None = None
        rig.start_clock()
        rig.new_session(who)

    def _check(self) -> VirtualRig:
        if self._closed:
            raise HILError(ErrorCode.NOT_OPEN, f"card {self.info.card_id} is closed")
        return _SameErrors(self.rig)  # type: ignore[return-value]

    def write_analog(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        self._check().write_analog(channels, volts)

    def read_encoder(self, channels: Sequence[int]) -> np.ndarray:
        return self._check().read_encoder(channels)

    def set_encoder_counts(self, channels: Sequence[int], counts: Sequence[int]) -> None:
        self._check().set_encoder_counts(channels, counts)

    def watchdog_set_analog_expiration_state(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        self._check().watchdog_set_analog_expiration_state(channels, volts)

    def watchdog_start(self, timeout: float) -> None:
        self._check().watchdog_start(timeout)

    def watchdog_reload(self) -> bool:
        return self._check().watchdog_reload()

    def watchdog_is_expired(self) -> bool:
        return self._check().watchdog_is_expired()

    def watchdog_clear(self) -> None:
        self._check().watchdog_clear()

    def watchdog_stop(self) -> None:
        self._check().watchdog_stop()

    def time(self) -> float:
        return self._check().time()

    def rig_now_ns(self) -> int:
        """The rig's clock [ns] as it reads now (nothing computed for it, unlike :meth:`time`)."""
        return self._check().now_ns()

    def status(self) -> RigStatus:
        return self._check().status()

    def step(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
             until: float, reload: bool = True) -> StepResult:
        rig = self._check()
        self.last_wait_ns = 0
        if self._deferred_ns is not None:    # not before the last step's sample instant
            self.last_wait_ns, self._deferred_ns = rig.wait_for(self._deferred_ns), None
        if not self.defer_wait or self.rig.lockstep:
            res = rig.step(analog_channels, volts, encoder_channels, to_ns(until), reload)
            self.last_wait_ns += self.rig.last_wait_ns
            return res
        self._deferred_ns = to_ns(until)
        reloaded, late, counts = rig.exchange(analog_channels, volts, encoder_channels, self._deferred_ns, reload)
        return StepResult(counts=np.array(counts, dtype=np.int32), reloaded=reloaded, time=rig.now_ns() / NS,
                          late=late / NS, status=rig.status())

    def advance(self, dt: float) -> None:
        """Lockstep: advance the rig by ``dt`` seconds."""
        self._check().advance(dt)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.rig.end_session("card closed")
        with _LOCK:
            if _OWNERS.get(id(self.rig)) is self:
                del _OWNERS[id(self.rig)]


__all__ = ["VirtualCard", "register_rig", "unregister_rig", "get_rig", "NS"]
