"""ipcosim's co-simulation master, command line, results and studies.

Public API (imported lazily, so that ``import harness`` stays cheap)::

    ipcosim.harness.run(scenario_or_path, stop_time=None, step=None, overrides=None, swaps=None, ...) -> Result
    ipcosim.harness.prepare(scenario_or_path, ...) -> Prepared      # .run(overrides=...) many times
    harness.Result, harness.SimulationError
    ipcosim.harness.swap_aliases                                     # --swap alias registry
    harness.Observer, harness.Manipulator                    # extension points
"""
from __future__ import annotations

from typing import Any

_EXPORTS = {
    "run": "ipcosim.harness.api", "prepare": "ipcosim.harness.api", "Prepared": "ipcosim.harness.api",
    "Result": "ipcosim.harness.master.results", "SimulationError": "ipcosim.harness.master.results",
    "swap_aliases": "ipcosim.harness.scenario.system", "register_swap_alias": "ipcosim.harness.scenario.system",
    "SwapTarget": "ipcosim.harness.scenario.system",
    "SwapRequest": "ipcosim.harness.scenario.system",
    "Observer": "ipcosim.harness.master.observers", "Manipulator": "ipcosim.harness.master.manipulators",
    "load_scenario": "ipcosim.harness.scenario.ssp",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'harness' has no attribute {name!r}")
