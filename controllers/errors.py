"""Exception classes of the controller package (on the project base, :mod:`ipcosim.errors`)."""
from __future__ import annotations

from ipcosim.errors import IpcosimError


class ControllerParameterError(IpcosimError, ValueError):
    """A controller parameter or design input is invalid; ``parameter`` names it."""

    def __init__(self, parameter: str, message: str) -> None:
        super().__init__(message)
        self.parameter = parameter


class DesignError(ControllerParameterError):
    """A controller design input is invalid or the design is impossible.

    Attributes
    ----------
    parameter : str
        Name of the offending design input (e.g. ``Q``, ``R``, ``observer_poles``, ``sample_period``).
    """


__all__ = ["ControllerParameterError", "DesignError"]
