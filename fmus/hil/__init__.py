"""Hardware-in-the-loop layer: a card API at volts-and-counts level, mirroring the Quanser HIL API.

Open a card by type and id (the Quanser convention), or by one URI ``[TYPE:]ID``::

    from ipcosim.fmus.hil import open_card
    card = open_card("q4", "0@tcpip://127.0.0.1:18920")   # virtual rig over the network
    card = open_card("q4", "0@inproc://bench")              # virtual rig in this process
    card = open_card("q4", "0")                             # a real Q4 (Quanser package)

Backends: ``quanser`` (:mod:`.quanser`), ``tcpip`` (:mod:`.tcpip`, served by
``ipcosim rig serve``), in-process (:mod:`.inproc`). The virtual rig is :mod:`.rig`, its
wire protocol :mod:`.protocol`.

The HIL is this one room: the card side (the card API :mod:`.api`, its clients, the wire protocol,
the adapter FMU's glue :mod:`.adapter`) and the rig side (the virtual rig :mod:`.rig`, its network
server :mod:`.server` and the service behind ``ipcosim rig serve``, :mod:`.service`). The adapter FMU
carries only what its script imports (the build's test checks that no server is packed). Only
what plugs the room into the master sits above it, in :mod:`ipcosim.harness.hil`: the ``--swap
plant=hil`` alias and the observer of a run's cards. Nothing here imports the master or the
scenarios: they call in.
"""
from __future__ import annotations

import urllib.parse

from ipcosim.fmus.hil.api import (
    Card,
    CardInfo,
    ErrorCode,
    HILError,
    RigStatus,
    StepResult,
    count_difference,
    wrap_int32,
)

DEFAULT_CARD_TYPE = "q4"
DEFAULT_URI = "q4:0@tcpip://127.0.0.1:18920"


def parse_card_uri(uri: str) -> tuple[str, str]:
    """Split ``[TYPE:]ID`` into ``(card_type, card_id)``.

    ``ID`` is ``N`` (a local card), ``N@tcpip://HOST:PORT`` or ``N@inproc://NAME[?query]``.
    The type defaults to ``q4``.

    Raises
    ------
    HILError
        ``BAD_URI`` for an empty or malformed URI.
    """
    text = (uri or "").strip()
    if not text:
        raise HILError(ErrorCode.BAD_URI, "empty card URI; expected [TYPE:]ID such as q4:0@tcpip://127.0.0.1:18920")
    head, sep, tail = text.partition("@")
    if ":" in head:
        card_type, _, number = head.partition(":")
    else:
        card_type, number = DEFAULT_CARD_TYPE, head
    if not card_type or not number:
        raise HILError(ErrorCode.BAD_URI, f"card URI {uri!r}: expected [TYPE:]ID, e.g. q4:0@tcpip://127.0.0.1:18920")
    return card_type, number + sep + tail


def open_card(card_type: str, card_id: str, *, timeout: float = 1.0, plant: str | None = None,
              name: str = "ipcosim", token: str | None = None) -> Card:
    """Open a card; the id selects the backend (see the module docstring).

    Parameters
    ----------
    card_type : str
        Quanser card type (``q4``, ``q8_usb`` ...); informational for the virtual rig.
    card_id : str
        ``N``, ``N@tcpip://HOST:PORT`` or ``N@inproc://NAME[?plant=...&clock=...]``.
    timeout : float
        tcpip: seconds to wait for each reply.
    plant : str, optional
        inproc: plant kind of a rig created on first use (if the query does not say).
    name : str
        Client name for the rig's log.
    token : str, optional
        tcpip: the rig's shared access token (default: the ``IPCOSIM_RIG_TOKEN`` environment
        variable, or none).

    Raises
    ------
    HILError
        ``BAD_URI``, ``CONNECTION``, ``BUSY``, ``BACKEND_MISSING`` ... with a clear message.
    """
    number, sep, rest = card_id.partition("@")
    if not sep:
        from ipcosim.fmus.hil.quanser import QuanserCard
        return QuanserCard(card_type, card_id)
    scheme, sep2, where = rest.partition("://")
    if not sep2:
        raise HILError(ErrorCode.BAD_URI, f"card id {card_id!r}: expected N@tcpip://HOST:PORT or N@inproc://NAME")
    if scheme == "tcpip":
        parsed = urllib.parse.urlsplit(f"tcp://{where}")
        try:
            port = parsed.port
        except ValueError:
            port = None
        if not parsed.hostname or port is None:
            raise HILError(ErrorCode.BAD_URI, f"card id {card_id!r}: expected N@tcpip://HOST:PORT")
        from ipcosim.fmus.hil.tcpip import TcpipCard
        return TcpipCard(card_type, card_id, parsed.hostname, port, timeout=timeout, name=name, token=token)
    if scheme == "inproc":
        from ipcosim.fmus.hil.inproc import VirtualCard, get_rig
        from ipcosim.fmus.hil.rig_config import RigConfig
        rig_name, _, query = where.partition("?")
        opts = dict(urllib.parse.parse_qsl(query))
        unknown = set(opts) - {"plant", "clock"}
        if unknown or not rig_name:
            raise HILError(ErrorCode.BAD_URI, f"card id {card_id!r}: expected N@inproc://NAME[?plant=...&clock=...]")
        try:
            config = RigConfig(plant=opts.get("plant", plant or "single-mass"),
                               clock=opts.get("clock", "lockstep")).checked()
        except ValueError as exc:
            raise HILError(ErrorCode.BAD_URI, f"card id {card_id!r}: {exc}") from None
        return VirtualCard(get_rig(rig_name, config), card_type, card_id, who=name)
    raise HILError(ErrorCode.BAD_URI, f"card id {card_id!r}: unknown scheme {scheme!r} (tcpip or inproc)")


def open_uri(uri: str, **kwargs: object) -> Card:
    """``open_card(*parse_card_uri(uri), **kwargs)``."""
    return open_card(*parse_card_uri(uri), **kwargs)  # type: ignore[arg-type]


__all__ = ["Card", "CardInfo", "ErrorCode", "HILError", "RigStatus", "StepResult", "open_card", "open_uri",
           "parse_card_uri", "count_difference", "wrap_int32", "DEFAULT_URI"]
