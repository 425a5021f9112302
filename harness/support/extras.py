"""The missing-extra check for optional dependencies (the base error classes are
:mod:`ipcosim.errors`)."""
from __future__ import annotations

from typing import Callable, TypeVar

from ipcosim.errors import IpcosimError

T = TypeVar("T")

__all__ = ["MissingExtraError", "EXTRAS", "require", "optional_figure"]


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


_said: set[str] = set()


def optional_figure(draw: Callable[[], T], what: str) -> T | None:
    """``draw()``, or None with one line on stderr (once per figure kind) when the plotting
    library it needs is not installed: a command that draws prints its numbers and skips the figure.

    Examples
    --------
    >>> optional_figure(lambda: "drawn", "the figure")
    'drawn'
    """
    import sys

    try:
        return draw()
    except MissingExtraError as exc:
        key = f"{what}: {exc}"
        if key not in _said:
            _said.add(key)
            print(f"ipcosim: warning: {what} skipped: {exc}", file=sys.stderr)
        return None
