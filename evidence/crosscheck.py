"""Other importers of the same ``.ssp``, for cross-checks and benchmarks: libcosim (through
``libcosimpy``, Jacobi fixed-step) and FMPy's ``simulate_ssp``.

:func:`run_libcosim` returns the trajectories of chosen variables on libcosim's time grid,
so that tests can compare them with :func:`ipcosim.run` (``algorithm="jacobi"``, same step).
"""
from __future__ import annotations

import os
import time
from typing import Any, Sequence

import numpy as np

from ipcosim.errors import IpcosimError


class CrossCheckError(IpcosimError, RuntimeError):
    """Another importer could not load or run the scenario."""


def run_libcosim(ssp: str | os.PathLike[str], stop_time: float, step: float,
                 variables: Sequence[str], quiet: bool = True) -> tuple[np.ndarray, float]:
    """Run an ``.ssp`` (or a scenario folder) in libcosim and record ``variables``.

    Parameters
    ----------
    ssp : path
        The archive (or folder holding SystemStructure.ssd).
    stop_time, step : float
        [s]; the step is passed as integer nanoseconds.
    variables : sequence of str
        ``component.variable`` names of Real variables to record.

    Returns
    -------
    data : numpy structured array
        ``time`` (libcosim's own time points, from t = step on) and the variables.
    wall : float
        Seconds spent in ``simulate_until`` (the simulation proper, including initialization).
    """
    from ipcosim.harness.support.extras import require

    require("libcosimpy")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    if quiet:
        log_output_level(CosimLogLevel.ERROR)
    step_ns = round(step * 1e9)
    n = round(stop_time / step)
    try:
        execution = CosimExecution.from_ssp_file(str(ssp), step_ns)
    except AssertionError as exc:
        raise CrossCheckError(f"libcosim cannot load {ssp}: {exc}") from None
    refs = _libcosim_refs(execution, ssp, variables)
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    execution.add_observer(observer)
    for s, vr in refs:
        observer.start_time_series(s, vr, CosimVariableType.REAL)
    t0 = time.perf_counter()
    ok = execution.simulate_until(round(stop_time * 1e9))
    wall = time.perf_counter() - t0
    if not ok:
        raise CrossCheckError(f"libcosim: simulation of {ssp} failed")
    data = _libcosim_table(observer, refs, variables, n)
    execution.stop()
    return data, wall


def _libcosim_refs(execution: Any, ssp: str | os.PathLike[str],
                   variables: Sequence[str]) -> list[tuple[int, int]]:
    """(slave index, value reference) in libcosim of each ``component.variable``."""
    slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
    refs = []
    for name in variables:
        comp, var = name.split(".", 1)
        if comp not in slaves:
            raise CrossCheckError(f"libcosim: no slave {comp!r} in {ssp}")
        vr = next((v.reference for v in execution.slave_variables(slaves[comp]) if v.name.decode() == var), None)
        if vr is None:
            raise CrossCheckError(f"libcosim: slave {comp!r} has no variable {var!r}")
        refs.append((slaves[comp], vr))
    return refs


def _libcosim_table(observer: Any, refs: Sequence[tuple[int, int]], variables: Sequence[str],
                    n: int) -> np.ndarray:
    """The time series libcosim's observer recorded (from step 1), as one structured array:
    ``time`` [s] (libcosim's own time points) and the variables."""
    columns: dict[str, np.ndarray] = {}
    times = None
    for name, (s, vr) in zip(variables, refs):
        tp, steps, values = observer.time_series_real_samples(s, vr, from_step=1, sample_count=n + 5)
        columns[name] = np.asarray(values, dtype=float)
        if times is None:
            times = np.asarray(tp, dtype=np.int64)
    assert times is not None
    data = np.zeros(len(times), dtype=[("time", "f8")] + [(v, "f8") for v in variables])
    data["time"] = times / 1e9
    for name in variables:
        data[name] = columns[name][:len(times)]
    return data


def run_fmpy_ssp(ssp: str | os.PathLike[str], stop_time: float, step: float) -> tuple[np.ndarray | None, float, str]:
    """FMPy's ``simulate_ssp`` on the same archive: (result or None, wall seconds, note)."""
    from fmpy.ssp.simulation import simulate_ssp

    t0 = time.perf_counter()
    try:
        result = simulate_ssp(str(ssp), stop_time=stop_time, step_size=step)
    except Exception as exc:  # noqa: BLE001 -- reported, not raised: fmpy's SSP support is partial
        return None, time.perf_counter() - t0, f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    return result, time.perf_counter() - t0, "ok"


