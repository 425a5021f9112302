"""What can be wrong with a scenario: files that cannot be read or are inconsistent
(``ScenarioError``), and a scenario that does not match its FMUs (``BindingError``), each
with the command-line mistakes among them (on :class:`ipcosim.errors.UsageError`)."""
from __future__ import annotations

from ipcosim.errors import IpcosimError, UsageError


class ScenarioError(IpcosimError, ValueError):
    """An SSD, SSV or SSP archive that cannot be read, fails its schema or is inconsistent."""


class UnknownParameterSetError(UsageError, ScenarioError):
    """A parameter set the scenario does not have (``--parameter-set``)."""


class ScenarioNotFoundError(UsageError, FileNotFoundError):
    """A scenario name or path that does not exist."""


class BindingError(IpcosimError, ValueError):
    """A scenario that does not match its FMUs (missing FMU or variable, wrong kind, type or unit)."""


class FMUNotFoundError(BindingError, FileNotFoundError):
    """A component's FMU file does not exist."""


class SetError(UsageError, BindingError):
    """A ``--set`` that does not fit the scenario (a command-line mistake)."""


class SwapFileNotFoundError(UsageError, FMUNotFoundError):
    """A ``--swap`` naming an FMU file that does not exist (a command-line mistake)."""
