"""Component swaps (``--swap plant=hil``): what a swap puts in place of a component, the aliases
that name one (registered by the rooms that provide them), and a ``--swap`` value resolved to an
FMU file or an alias's target."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from ipcosim.errors import closest
from ipcosim.harness.master.system import Model
from ipcosim.harness.scenario.errors import BindingError, SwapFileNotFoundError
from ipcosim.harness.scenario.locations import fmu_search_path
from ipcosim.harness.scenario.structure import Scenario


@dataclass(frozen=True)
class SwapTarget:
    """What a swap puts in place of a component.

    Attributes
    ----------
    fmu : Path
        The replacement FMU.
    parameters : mapping of str to value
        Start values for the replacement (e.g. the HIL adapter's card URI).
    realtime : bool
        Run the scenario paced to wall-clock time when this component is present.
    description : str
        One line for messages and metadata.
    """

    fmu: Path
    parameters: Mapping[str, Any] = field(default_factory=dict)
    realtime: bool = False
    description: str = ""


@dataclass(frozen=True)
class SwapRequest:
    """The context an alias resolver gets: which component of which scenario is swapped."""

    scenario: Scenario
    component: str
    model: Model | None  # the original FMU's interface (None if its FMU is missing)
    fmu_dirs: tuple[Path, ...] = ()  # the folders FMUs are looked for in (``ssp.fmu_search_path``)


#: Swap aliases: ``--swap plant=hil`` looks up ``hil`` here. A resolver takes a SwapRequest and
#: returns a SwapTarget (or a mapping of its fields). The modules listed in
#: ``SWAP_ALIAS_PROVIDERS`` are imported on first use and their ``SWAP_ALIASES`` (name ->
#: resolver) registered; :func:`register_swap_alias` adds one from anywhere.
swap_aliases: dict[str, Callable[[SwapRequest], SwapTarget]] = {}
SWAP_ALIAS_PROVIDERS: tuple[str, ...] = ()  # ``hil``: ipcosim.harness.hil registers it on import
_providers_loaded = False


def register_swap_alias(name: str, resolver: Callable[[SwapRequest], SwapTarget]) -> None:
    """Make ``--swap COMPONENT=name`` resolve through ``resolver``."""
    swap_aliases[name] = resolver


def _load_alias_providers() -> None:
    global _providers_loaded
    if _providers_loaded:
        return
    _providers_loaded = True
    import importlib

    for module in SWAP_ALIAS_PROVIDERS:
        for name, resolver in importlib.import_module(module).SWAP_ALIASES.items():
            register_swap_alias(name, resolver)


def resolve_swap(scenario: Scenario, component: str, target: str | os.PathLike[str] | SwapTarget,
                 model: Model | None) -> SwapTarget:
    """A SwapTarget for ``--swap component=target`` (an FMU path or a registered alias)."""
    if isinstance(target, SwapTarget):
        return target
    text = os.fspath(target)
    if text.endswith(".fmu") or os.sep in text or "/" in text:
        path = Path(text)
        if not path.is_file():
            raise SwapFileNotFoundError(f"--swap {component}={text}: FMU file does not exist")
        return SwapTarget(fmu=path.resolve(), description=f"FMU {text}")
    _load_alias_providers()
    if text not in swap_aliases:
        raise BindingError(f"--swap {component}={text}: not an .fmu file and not a known alias; "
                           f"{closest(text, swap_aliases)}")
    target = swap_aliases[text](SwapRequest(scenario, component, model, tuple(fmu_search_path())))
    return target if isinstance(target, SwapTarget) else SwapTarget(**target)
