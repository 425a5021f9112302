"""Project exception classes. Each subclasses the built-in it refines, so callers that do
not know ipcosim can still catch ValueError, OSError or RuntimeError."""
from __future__ import annotations


class IpcosimError(Exception):
    """Base of every error ipcosim reports as one line to the user."""


class UsageError(IpcosimError, ValueError):
    """A bad command-line value (unknown scenario, malformed --set, non-positive step...)."""


class MissingExtraError(IpcosimError, ImportError):
    """An optional dependency (an extra of the ipcosim distribution) is not installed."""


#: Optional dependencies: import name -> (extra that installs it, what needs it).
EXTRAS = {"matplotlib": ("plot", "plots"), "distributed": ("cluster", "a Dask cluster"),
          "libcosimpy": ("test", "the libcosim cross-check")}


def require(module: str) -> None:
    """Raise :class:`MissingExtraError` naming the extra to install if ``module`` is absent.

    Examples
    --------
    >>> require("json")  # a module that is there: nothing happens
    """
    import importlib.util

    if importlib.util.find_spec(module) is None:
        extra, what = EXTRAS.get(module, (None, module))
        hint = f"pip install 'ipcosim[{extra}]'" if extra else f"pip install {module}"
        raise MissingExtraError(f"{module} is not installed ({what} need it): {hint}")
