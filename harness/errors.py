"""Project exception classes. Each subclasses the built-in it refines, so callers that do
not know ipcosim can still catch ValueError, OSError or RuntimeError."""
from __future__ import annotations


class IpcosimError(Exception):
    """Base of every error ipcosim reports as one line to the user."""


class UsageError(IpcosimError, ValueError):
    """A bad command-line value (unknown scenario, malformed --set, non-positive step...)."""
