"""The ``hil`` swap alias: ``ipcosim run SCENARIO --swap plant=hil``.

The alias picks the adapter FMU for the scenario's plant kind (``IP02HILSingleMass`` or
``IP02HILDoubleMass``), found next to the scenario's plant FMU, in ``IPCOSIM_FMU_PATH``
or in ``build/fmus``; its ``card_uri`` is ``IPCOSIM_HIL_URI`` if set, else the virtual
rig's default address ``q4:0@tcpip://127.0.0.1:18920`` (``--set plant.card_uri=...``
overrides it for one run). The run is paced to wall-clock time unless the card is a
``lockstep`` virtual rig (asked when the alias is resolved; an unreachable card counts as
real time, and the run then fails at start with the card's own message).
"""
from __future__ import annotations

import os
from pathlib import Path

from ipcosim.fmus.hil import DEFAULT_URI, HILError, parse_card_uri

ADAPTERS = {"single-mass": "IP02HILSingleMass", "double-mass": "IP02HILDoubleMass"}
PLANT_MODELS = {"IP02SingleMass": "single-mass", "IP02DoubleMass": "double-mass"}


class HilSwapError(HILError):
    """The ``hil`` alias cannot be resolved (unknown plant kind, adapter FMU not built)."""


def plant_kind(scenario_name: str, model_name: str | None, connectors: set[str]) -> str:
    """Plant kind of the component being swapped, from its FMU, the scenario name or its connectors."""
    if model_name in PLANT_MODELS:
        return PLANT_MODELS[model_name]
    for kind in ADAPTERS:
        if scenario_name.startswith(kind):
            return kind
    if "active_cart_position" in connectors or "passive_cart_position" in connectors:
        return "double-mass"
    if "cart_position" in connectors:
        return "single-mass"
    raise HilSwapError(14, f"--swap ...=hil: cannot tell the plant kind of scenario {scenario_name!r} "
                           f"(expected an IP02SingleMass/IP02DoubleMass component)")


def find_adapter(model: str, near: Path | None = None) -> Path:
    """The adapter FMU file ``<model>.fmu``: next to ``near``, in IPCOSIM_FMU_PATH, in build/fmus."""
    from ipcosim.harness.scenario.ssp import fmu_search_path

    dirs = ([near] if near is not None else []) + [Path(d) for d in fmu_search_path()]
    for d in dirs:
        cand = Path(d) / f"{model}.fmu"
        if cand.is_file():
            return cand.resolve()
    raise HilSwapError(9, f"--swap ...=hil: adapter FMU {model}.fmu not found in "
                          f"{', '.join(str(d) for d in dirs)} (run `ipcosim build`)")


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


def resolve_hil(request):  # noqa: ANN001, ANN201 -- ipcosim.harness.scenario.binding.SwapRequest -> SwapTarget
    """Resolver of the ``hil`` alias (registered with :func:`ipcosim.harness.scenario.binding.register_swap_alias`)."""
    from ipcosim.harness.scenario.binding import SwapTarget

    model = request.model
    connectors = {c.name for c in request.scenario.component(request.component).connectors} \
        if hasattr(request.scenario, "component") else set()
    kind = plant_kind(request.scenario.name, model.name if model is not None else None, connectors)
    near = model.path.parent if model is not None and getattr(model, "path", None) else None
    fmu = find_adapter(ADAPTERS[kind], near)
    uri = os.environ.get("IPCOSIM_HIL_URI", DEFAULT_URI)
    clock = card_clock(uri)
    return SwapTarget(fmu=fmu, parameters={"card_uri": uri}, realtime=clock != "lockstep",
                      description=f"HIL adapter {ADAPTERS[kind]} on {uri} ({clock})")


def register() -> None:
    """Register the ``hil`` alias with the master."""
    from ipcosim.harness.scenario.binding import register_swap_alias

    register_swap_alias("hil", resolve_hil)


register()
