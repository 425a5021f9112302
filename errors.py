"""The base exception classes of ipcosim, below every room (``ipcosim.errors``).

Each subclasses the built-in it refines, so callers that do not know ipcosim can still
catch ``ValueError``, ``OSError`` or ``RuntimeError``. The FMUs carry this module in their
private runtime (``ipcosim.fmus.pybuild``), so an FMU's errors share the base with the host's
by name and by meaning.
"""
from __future__ import annotations

from typing import Iterable


class IpcosimError(Exception):
    """Base of every error ipcosim reports as one line to the user."""


class UsageError(IpcosimError, ValueError):
    """A bad command-line or option value (unknown scenario, malformed --set, non-positive step...)."""


def closest(name: str, known: Iterable[str], *, listing: int = 12) -> str:
    """What to tell a user who gave an unknown ``name``: the closest known names, or all of them
    when none is close and they are few (the one phrasing of every "unknown name" message).

    Parameters
    ----------
    name : str
        The name as given.
    known : iterable of str
        The names that exist.
    listing : int
        Without a close name, list every known name when there are at most this many.

    Returns
    -------
    str
        ``"did you mean 'Mp'?"``; without a close name ``"known: Jm, Lp, Mp"`` (or, when there are
        more than ``listing``, how many there are).

    Examples
    --------
    >>> closest("Mpp", ["Mp", "Lp", "Jm"])
    "did you mean 'Mp'?"
    >>> closest("x", ["Mp", "Lp", "Jm"])
    'known: Jm, Lp, Mp'
    >>> closest("x", [])
    'none known'
    """
    names = sorted(dict.fromkeys(str(k) for k in known))
    if not names:
        return "none known"
    near = close_names(name, names)
    quoted = [repr(n) for n in near]
    guess = f"did you mean {' or '.join(filter(None, [', '.join(quoted[:-1]), quoted[-1]]))}?" if near else ""
    every = f"known: {', '.join(names)}" if len(names) <= listing else f"none close among {len(names)} names"
    return guess or every


def close_names(name: str, known: Iterable[str]) -> list[str]:
    """The (at most three) known names :func:`closest` suggests for ``name``, closest first. For a
    ``component.variable`` name of a known component, the variable is compared with that component's.

    >>> close_names("Mpp", ["Mp", "Lp", "Jm"])
    ['Mp']
    >>> close_names("controller.no_such_gain", ["controller.model_g", "plant.Mp"])
    []
    """
    names = sorted(dict.fromkeys(str(k) for k in known))
    owner, dot, rest = name.partition(".")
    mine = [n[len(owner) + 1:] for n in names if n.startswith(owner + ".")] if dot and rest else []
    if mine:  # "component.variable": the variable among that component's, so the shared prefix counts for nothing
        return [f"{owner}.{n}" for n in close_names(rest, mine)]
    case = [n for n in names if n.lower() == name.lower()]
    if case:  # a case slip (mp for Mp) is the answer
        return case[:3]
    import difflib  # loaded when a name is wrong, not by every command

    cutoff = 0.6 if len(name) > 3 else 0.5  # one wrong letter of two or three is a slip too (Mx for Mp)
    near = difflib.get_close_matches(name, names, n=3, cutoff=cutoff)
    if not near:  # prefixes (sample for sample_period) count too
        near = [n for n in names if n.lower().startswith(name.lower())][:3]
    return near


__all__ = ["IpcosimError", "UsageError", "close_names", "closest"]
