"""The base exception classes of ipcosim, below every room (``ipcosim.errors``).

Each subclasses the built-in it refines, so callers that do not know ipcosim can still
catch ``ValueError``, ``OSError`` or ``RuntimeError``. The FMUs carry this module in their
private runtime (``ipcosim.fmus.pybuild``), so an FMU's errors share the base with the host's
by name and by meaning.
"""
from __future__ import annotations


class IpcosimError(Exception):
    """Base of every error ipcosim reports as one line to the user."""


class UsageError(IpcosimError, ValueError):
    """A bad command-line or option value (unknown scenario, malformed --set, non-positive step...)."""


__all__ = ["IpcosimError", "UsageError"]
