"""The ``hil`` swap alias: ``ipcosim run SCENARIO --swap plant=hil``.

The alias picks the adapter FMU for the scenario's plant kind (``IP02HILSingleMass`` or
``IP02HILDoubleMass``), found next to the scenario's plant FMU or in the FMU folders the
swap request names (``IPCOSIM_FMU_PATH``, ``build/fmus``); its ``card_uri`` is
``IPCOSIM_HIL_URI`` if set, else the virtual rig's default address
``q4:0@tcpip://127.0.0.1:18920`` (``--set plant.card_uri=...`` overrides it for one run).
The run is paced to wall-clock time unless the card is a ``lockstep`` virtual rig (asked
when the alias is resolved; an unreachable card counts as real time, and the run then fails
at start with the card's own message).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

from ipcosim.fmus.hil import DEFAULT_URI, HILError, parse_card_uri
from ipcosim.fmus.kinds import ByKind, plant_kind
from ipcosim.harness.scenario.swaps import SwapRequest, register_swap_alias

#: The HIL adapter FMU's model name of each plant kind.
ADAPTERS = ByKind(lambda k: k.hil_model)


class HilSwapError(HILError):
    """The ``hil`` alias cannot be resolved (unknown plant kind, adapter FMU not built)."""


def find_adapter(model: str, dirs: Sequence[Path | str]) -> Path:
    """The adapter FMU file ``<model>.fmu`` in the first of ``dirs`` that holds it."""
    for d in dirs:
        cand = Path(d) / f"{model}.fmu"
        if cand.is_file():
            return cand.resolve()
    searched = dict.fromkeys(str(d) for d in dirs)  # each folder once, in search order
    raise HilSwapError(9, f"--swap ...=hil: adapter FMU {model}.fmu not found in "
                          f"{', '.join(searched)} (run `ipcosim build`)")


def card_clock(uri: str) -> str:
    """``lockstep`` or ``wallclock`` for a card URI (real cards and unreachable rigs: ``wallclock``)."""
    try:
        card_type, card_id = parse_card_uri(uri)
    except HILError:
        return "wallclock"
    _, sep, rest = card_id.partition("@")
    if rest.startswith("inproc://"):
        from urllib.parse import parse_qsl

        from ipcosim.fmus.hil.inproc import _RIGS
        name, _, query = rest[len("inproc://"):].partition("?")
        rig = _RIGS.get(name)
        if rig is not None:
            return rig.config.clock
        return dict(parse_qsl(query)).get("clock", "lockstep")
    if rest.startswith("tcpip://"):
        from urllib.parse import urlsplit

        from ipcosim.fmus.hil.tcpip import TcpipCard
        where = urlsplit(f"tcp://{rest[len('tcpip://'):]}")
        try:
            card = TcpipCard(card_type, card_id, where.hostname or "", where.port or 0, timeout=1.0,
                             role="monitor", name="ipcosim swap (clock query)")
        except (HILError, ValueError):
            return "wallclock"
        clock = card.info.clock
        card.close()
        return clock
    return "wallclock"


def resolve_hil(request: SwapRequest) -> dict[str, Any]:
    """Resolver of the ``hil`` alias: a swap request -> the fields of its swap target.

    The answer holds the target's ``fmu``, ``parameters``, ``realtime`` and ``description``,
    which the binding turns into its ``SwapTarget``.
    """
    model = request.model
    connectors = {c.name for c in request.scenario.component(request.component).connectors} \
        if hasattr(request.scenario, "component") else set()
    kind = plant_kind(request.scenario.name, model.name if model is not None else None, connectors)
    if kind is None:
        raise HilSwapError(14, f"--swap ...=hil: cannot tell the plant kind of scenario {request.scenario.name!r} "
                               f"(expected an IP02SingleMass/IP02DoubleMass component)")
    near = model.path.parent if model is not None and getattr(model, "path", None) else None
    fmu = find_adapter(ADAPTERS[kind], ([near] if near is not None else []) + list(request.fmu_dirs))
    uri = os.environ.get("IPCOSIM_HIL_URI", DEFAULT_URI)
    clock = card_clock(uri)
    return {"fmu": fmu, "parameters": {"card_uri": uri}, "realtime": clock != "lockstep",
            "description": f"HIL adapter {ADAPTERS[kind]} on {uri} ({clock})"}


#: The swap aliases this module provides, registered with the binding when it is imported.
SWAP_ALIASES = {"hil": resolve_hil}
for _name, _resolver in SWAP_ALIASES.items():
    register_swap_alias(_name, _resolver)
