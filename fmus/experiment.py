"""The default experiment every ipcosim FMU declares (Python and native flavours, FMI 2.0 and
3.0, the exported loops), so that a tool that imports one runs it meaningfully with its own
defaults (``fmpy simulate X.fmu``). Standard library only: the native generator uses it too."""
from __future__ import annotations

#: The longest stop time [s] an ipcosim FMU declares in its ``DefaultExperiment`` (the scenarios' run).
DEFAULT_STOP_TIME = 10.0
#: Steps in a default experiment at most: an importer that samples its output at the declared step
#: (fmpy doubles its output interval, and with it a co-simulation's communication step, until at
#: most 1000 intervals) then steps a controller at its sample period, never across a sample instant.
MAX_DEFAULT_STEPS = 1000
#: The step [s] an FMU without a ``sample_period`` declares (the scenarios' communication step).
DEFAULT_STEP_SIZE = 1e-3


def default_experiment(sample_period: float | None = None) -> dict[str, str]:
    """The ``DefaultExperiment`` attributes of an ipcosim FMU (Python and native flavours, FMI 2.0
    and 3.0), so that a tool that imports it runs it meaningfully with its own defaults: at the
    FMU's ``sample_period`` (a controller: a step that never misses a sample instant), else at
    :data:`DEFAULT_STEP_SIZE`, from 0 for :data:`MAX_DEFAULT_STEPS` steps or
    :data:`DEFAULT_STOP_TIME`, whichever is shorter (1 s at 1 ms)."""
    step = float(sample_period) if sample_period else DEFAULT_STEP_SIZE
    stop = min(DEFAULT_STOP_TIME, MAX_DEFAULT_STEPS * step)
    return {"startTime": "0.0", "stopTime": repr(round(stop, 12)), "stepSize": repr(step)}
