"""Exception classes of the controller package.

Inside a controller FMU only the ``fmus`` and ``controllers`` packages are packed (see
``ipcosim.fmus.build``), so the project base class is imported when available and replaced by a
plain ``Exception`` subclass otherwise; every error still subclasses the fitting built-in.
"""
from __future__ import annotations

try:
    from ipcosim.harness.errors import IpcosimError
except ImportError:  # pragma: no cover - inside an FMU
    class IpcosimError(Exception):  # type: ignore[no-redef]
        """Base of every error ipcosim reports as one line to the user."""


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


__all__ = ["IpcosimError", "ControllerParameterError", "DesignError"]
