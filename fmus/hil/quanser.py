"""``quanser`` backend: a real card through Quanser's own Python HIL package.

Quanser ships the package ``quanser`` (module ``quanser.hardware``) with the Quanser SDK
and with QUARC; it is not on PyPI and not a dependency of ipcosim. Install the SDK for
your platform, then ``pip install`` the wheels it provides into the same environment
(see ``docs/hil.md``). When the package is missing, opening a card raises
``HILError(BACKEND_MISSING)`` with instructions, never an ImportError traceback.

This class only translates: Python sequences to the typed arrays the Quanser functions
take, ``quanser.hardware.HILError`` to :class:`ipcosim.fmus.hil.api.HILError` (same numeric
code, Quanser's message). Card time is the host's monotonic clock, so
:meth:`Card.step` waits for each sample instant on the host (sleep, then spin).
"""
from __future__ import annotations

import importlib
from typing import Any, Sequence

import numpy as np

from ipcosim.fmus.hil.api import Card, CardInfo, ErrorCode, HILError, as_channels, as_finite

INSTALL_HINT = ("Quanser's Python HIL package (module quanser.hardware) is not installed; it comes with the "
                "Quanser SDK or QUARC (pip install the wheels they ship). To run against the virtual rig instead, "
                "use a card id like 0@tcpip://127.0.0.1:18920 with `ipcosim rig serve`")


def load_quanser_hil() -> tuple[Any, type]:
    """``(HIL class, quanser HILError class)``; raises HILError(BACKEND_MISSING) if absent."""
    try:
        hardware = importlib.import_module("quanser.hardware")
    except ImportError as exc:
        raise HILError(ErrorCode.BACKEND_MISSING, INSTALL_HINT) from exc
    return hardware.HIL, hardware.HILError


class QuanserCard(Card):
    """A Quanser data-acquisition card (e.g. ``q4``, ``q8_usb``) opened with ``quanser.hardware.HIL``."""

    def __init__(self, card_type: str, card_id: str) -> None:
        hil_class, self._qerror = load_quanser_hil()
        self._card = None
        try:
            card = hil_class()
            card.open(card_type, card_id)
        except self._qerror as exc:
            raise self._translate(exc, f"cannot open Quanser card {card_type!r} id {card_id!r}") from exc
        self._card = card
        self.info = CardInfo(card_type=card_type, card_id=card_id, analog_outputs=-1, encoder_inputs=-1,
                             clock="wallclock")

    def _translate(self, exc: Exception, what: str) -> HILError:
        code = getattr(exc, "error_code", ErrorCode.INTERNAL)
        getter = getattr(exc, "get_error_message", None)
        message = getter() if callable(getter) else str(exc)
        return HILError(int(code), f"{what}: {message}")

    def _call(self, what: str, fn_name: str, *args: Any) -> Any:
        if self._card is None:
            raise HILError(ErrorCode.NOT_OPEN, f"Quanser card {self.info.card_id} is closed")
        try:
            return getattr(self._card, fn_name)(*args)
        except self._qerror as exc:
            raise self._translate(exc, what) from exc

    def write_analog(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        ch = np.array(as_channels(channels, "analog output"), dtype=np.uint32)
        v = np.array(as_finite(volts, len(ch), "write_analog"), dtype=np.float64)
        self._call("write_analog", "write_analog", ch, len(ch), v)

    def read_encoder(self, channels: Sequence[int]) -> np.ndarray:
        ch = np.array(as_channels(channels, "encoder"), dtype=np.uint32)
        buf = np.zeros(len(ch), dtype=np.int32)
        self._call("read_encoder", "read_encoder", ch, len(ch), buf)
        return buf

    def set_encoder_counts(self, channels: Sequence[int], counts: Sequence[int]) -> None:
        ch = np.array(as_channels(channels, "encoder"), dtype=np.uint32)
        if isinstance(counts, (int, np.integer)):
            counts = [int(counts)] * len(ch)
        buf = np.array(counts, dtype=np.int32)
        self._call("set_encoder_counts", "set_encoder_counts", ch, len(ch), buf)

    def watchdog_set_analog_expiration_state(self, channels: Sequence[int], volts: Sequence[float]) -> None:
        ch = np.array(as_channels(channels, "analog output"), dtype=np.uint32)
        v = np.array(as_finite(volts, len(ch), "expiration state"), dtype=np.float64)
        self._call("watchdog_set_analog_expiration_state", "watchdog_set_analog_expiration_state", ch, len(ch), v)

    def watchdog_start(self, timeout: float) -> None:
        self._call("watchdog_start", "watchdog_start", float(timeout))

    def watchdog_reload(self) -> bool:
        return bool(self._call("watchdog_reload", "watchdog_reload"))

    def watchdog_is_expired(self) -> bool:
        return bool(self._call("watchdog_is_expired", "watchdog_is_expired"))

    def watchdog_clear(self) -> None:
        self._call("watchdog_clear", "watchdog_clear")

    def watchdog_stop(self) -> None:
        self._call("watchdog_stop", "watchdog_stop")

    def close(self) -> None:
        if self._card is None:
            return
        card, self._card = self._card, None
        try:
            card.close()
        except self._qerror:
            pass
