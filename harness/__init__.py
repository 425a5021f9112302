"""ipcosim's co-simulation master, command line, results and studies.

Public API (imported lazily, so that ``import harness`` stays cheap)::

    harness.run(scenario_or_path, stop_time=None, step=None, overrides=None, swaps=None, ...) -> Result
    harness.prepare(scenario_or_path, ...) -> Prepared      # .run(overrides=...) many times
    harness.Result, harness.SimulationError
    harness.swap_aliases                                     # --swap alias registry
    harness.Observer, harness.Manipulator                    # extension points
"""
from __future__ import annotations

from typing import Any

_EXPORTS = {
    "run": "harness.api", "prepare": "harness.api", "Prepared": "harness.api",
    "Result": "harness.results", "SimulationError": "harness.results",
    "swap_aliases": "harness.system", "register_swap_alias": "harness.system", "SwapTarget": "harness.system",
    "SwapRequest": "harness.system",
    "Observer": "harness.observers", "Manipulator": "harness.manipulators",
    "load_scenario": "harness.ssp",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'harness' has no attribute {name!r}")
