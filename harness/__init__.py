"""ipcosim's co-simulation master, command line, results and studies.

The public API (``ipcosim.run``, ``ipcosim.prepare``, ``ipcosim.Result``, ``ipcosim.load_scenario``...)
is exported once, at the top of the package (``ipcosim/__init__.py``). This package adds, lazily
(so that ``import ipcosim.harness`` stays cheap), what only code plugging into the master needs::

    ipcosim.harness.swap_aliases, register_swap_alias, SwapTarget, SwapRequest   # --swap alias registry
    ipcosim.harness.Observer, ipcosim.harness.Manipulator                         # extension points
"""
from __future__ import annotations

from typing import Any

_EXPORTS = {
    "swap_aliases": "ipcosim.harness.scenario.swaps", "register_swap_alias": "ipcosim.harness.scenario.swaps",
    "SwapTarget": "ipcosim.harness.scenario.swaps",
    "SwapRequest": "ipcosim.harness.scenario.swaps",
    "Observer": "ipcosim.harness.master.observers", "Manipulator": "ipcosim.harness.master.manipulators",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'ipcosim.harness' has no attribute {name!r}")
