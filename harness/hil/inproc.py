"""In-process backend: a :class:`Card` calling a :class:`VirtualRig` directly (no network).

Card id ``N@inproc://NAME[?plant=double-mass&clock=lockstep]``: the rig registered under
``NAME`` (:func:`register_rig`), or a new one made from the query and registered. Used
for deterministic tests, and by tests that want to look inside the rig they drive.
"""
from __future__ import annotations

import threading
from typing import Sequence

import numpy as np

from .api import Card, ErrorCode, HILError, RigStatus, StepResult
from .rig import NS, RigConfig, VirtualRig, to_ns

_RIGS: dict[str, VirtualRig] = {}
_OWNERS: dict[int, "VirtualCard"] = {}
_LOCK = threading.Lock()


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
        rig.start_clock()
        rig.new_session(who)

    def _check(self) -> VirtualRig:
        if self._closed:
            raise HILError(ErrorCode.NOT_OPEN, f"card {self.info.card_id} is closed")
        return self.rig

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

    def status(self) -> RigStatus:
        return self._check().status()

    def step(self, analog_channels: Sequence[int], volts: Sequence[float], encoder_channels: Sequence[int],
             until: float, reload: bool = True) -> StepResult:
        return self._check().step(analog_channels, volts, encoder_channels, to_ns(until), reload)

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
