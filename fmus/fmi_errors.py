"""The exceptions of the FMU glue, by what the FMI host sees of them."""
from __future__ import annotations

from ipcosim.errors import IpcosimError


class FmuError(IpcosimError, RuntimeError):
    """An FMU cannot continue (bad parameter, call in the wrong state); reported as fmi2Fatal.

    Its ``repr`` is the bare message: pythonfmu's wrapper logs ``repr(exception)``.
    """

    def __repr__(self) -> str:
        return str(self)


class StepFailure(IpcosimError, ArithmeticError):
    """A communication step that cannot be completed; reported as fmi2Discard, state kept at ``t``."""
