"""The default experiment every ipcosim FMU declares (Python and native flavours, FMI 2.0 and
3.0, the exported loops), so that a tool that imports one runs it meaningfully with its own
defaults (``fmpy simulate X.fmu``). Standard library only: the native generator uses it too."""
from __future__ import annotations

#: The stop time [s] every ipcosim FMU declares in its ``DefaultExperiment`` (the scenarios' run).
DEFAULT_STOP_TIME = 10.0
#: The step [s] an FMU without a ``sample_period`` declares (the scenarios' communication step).
DEFAULT_STEP_SIZE = 1e-3


def default_experiment(sample_period: float | None = None) -> dict[str, str]:
    """The ``DefaultExperiment`` attributes of an ipcosim FMU (Python and native flavours, FMI 2.0
    and 3.0), so that a tool that imports it runs it meaningfully with its own defaults: from 0
    to :data:`DEFAULT_STOP_TIME` at the FMU's ``sample_period`` (a controller: a step that never
    misses a sample instant), else at :data:`DEFAULT_STEP_SIZE`."""
    step = float(sample_period) if sample_period else DEFAULT_STEP_SIZE
    return {"startTime": "0.0", "stopTime": repr(DEFAULT_STOP_TIME), "stepSize": repr(step)}
