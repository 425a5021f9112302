"""The missing-extra check for optional dependencies (the base error classes are
:mod:`ipcosim.errors`)."""
from __future__ import annotations

from ipcosim.errors import IpcosimError

__all__ = ["MissingExtraError", "EXTRAS", "require"]


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
