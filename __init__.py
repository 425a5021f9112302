"""ipcosim: FMI co-simulation of the Quanser IP02 inverted pendulum (single and double mass).

This file is the top of the one import package, ``ipcosim``; its subpackages are the
top-level folders of the source tree (``pyproject.toml``, ``package-dir``)::

    ipcosim.fmus         fmus/         plant physics, plant FMUs, the HIL adapter FMU
    ipcosim.controllers  controllers/  control-law design, discrete laws, controller FMUs
    ipcosim.harness      harness/      master, scenario loader, HIL rig, studies, CLI
    ipcosim/ssp          ssp/          the shipped SSP scenarios (package data)

The public Python API is re-exported here lazily, so ``import ipcosim`` stays cheap::

    import ipcosim
    result = ipcosim.run("single-mass-lqr", stop_time=5.0, set={"plant.Mp": "1.1*nominal"})
    result.metrics["settling_time_s"], result.data["plant.cart_position"]
    ipcosim.assert_settles(result, within_s=3.0)

See docs/api.md; the pytest plugin (fixtures ``cosim``, ``ipcosim_fmus``) is
``ipcosim.harness.testing.pytest_plugin``.
"""
from __future__ import annotations

from typing import Any

__version__ = "0.2.0"

_EXPORTS = {
    "run": "ipcosim.harness.api.public", "scenarios": "ipcosim.harness.api.public",
    "build": "ipcosim.harness.api.public", "build_fmu": "ipcosim.harness.api.public",
    "ScenarioInfo": "ipcosim.harness.api.public",
    "FMUBuildError": "ipcosim.harness.api.public", "linearize": "ipcosim.harness.api.public",
    "RunOptions": "ipcosim.harness.api.options",
    "prepare": "ipcosim.harness.api.engine", "Prepared": "ipcosim.harness.api.engine",
    "Result": "ipcosim.harness.master.results", "SimulationError": "ipcosim.harness.master.results",
    "load_scenario": "ipcosim.harness.scenario.ssp", "scenario_names": "ipcosim.harness.scenario.locations",
    "IpcosimError": "ipcosim.errors", "UsageError": "ipcosim.errors",
    "assert_upright": "ipcosim.harness.testing", "assert_settles": "ipcosim.harness.testing",
    "assert_steady_state": "ipcosim.harness.testing", "assert_close_to": "ipcosim.harness.testing",
    "assert_succeeds": "ipcosim.harness.testing",
    "settling_time": "ipcosim.harness.testing", "cases": "ipcosim.harness.testing", "Case": "ipcosim.harness.testing",
    "CheckFailed": "ipcosim.harness.testing", "save_baseline": "ipcosim.harness.testing.baseline",
    "load_baseline": "ipcosim.harness.testing.baseline",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'ipcosim' has no attribute {name!r}")
