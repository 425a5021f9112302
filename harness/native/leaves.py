"""The numbers inside a Python model object, by path: read them, or replace them by symbolic leaves.

A law object (``ipcosim.controllers.laws``) holds its gains, its design matrices and its state as
plain floats, tuples and lists (a design object also numpy arrays), in attributes of itself and of
the small project objects it owns (gain dataclasses, derivative filters, the LQR coefficients).
:func:`numbers` walks that tree and names each number by its path (``gains.k``, ``_d[1].value``,
``design.M[2][0]``); with ``replace=True`` it swaps every number for the tracer leaf ``L:<path>``
(numpy arrays become object arrays), so that one run of the law's own ``step`` traces its arithmetic.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ipcosim.harness.native.tracer import Node, leaf

#: Integer attributes that are state (counted by the law), not structure.
COUNTERS = ("ticks", "catches")
#: Boolean attributes that are state (a law's mode, switched by its step), carried as 0.0 / 1.0.
FLAGS = ("balancing",)


def numbers(obj: Any, replace: bool = False) -> dict[str, Any]:
    """``{path: number}`` of every float (and counter) reachable from ``obj``; see the module docstring."""
    out: dict[str, Any] = {}
    _walk(obj, "", out, replace, set())
    return out


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _walk(obj: Any, path: str, out: dict[str, Any], replace: bool, memo: set[int]) -> Any:
    if isinstance(obj, bool) and path.rsplit(".", 1)[-1] in FLAGS:
        out[path] = float(obj)
        return leaf("L:" + path) if replace else obj
    if obj is None or isinstance(obj, (bool, str, np.bool_)):
        return obj
    is_counter = isinstance(obj, int) and path.rsplit(".", 1)[-1] in COUNTERS
    if isinstance(obj, (float, np.floating, Node)) or is_counter:
        out[path] = obj if isinstance(obj, Node) else float(obj)
        return leaf("L:" + path) if replace else obj
    if isinstance(obj, (int, np.integer)):
        return obj
    if isinstance(obj, np.ndarray):
        return _walk_array(obj, path, out, replace)
    if type(obj) in (tuple, list):
        items = [_walk(x, f"{path}[{i}]", out, replace, memo) for i, x in enumerate(obj)]
        return type(obj)(items) if replace else obj
    if type(obj).__module__.startswith("ipcosim.") and hasattr(obj, "__dict__"):
        if id(obj) in memo:
            return obj
        memo.add(id(obj))
        for name, value in list(vars(obj).items()):
            new = _walk(value, _join(path, name), out, replace, memo)
            if replace and new is not value:
                object.__setattr__(obj, name, new)
        return obj
    return obj


def _walk_array(a: np.ndarray, path: str, out: dict[str, Any], replace: bool) -> np.ndarray:
    if a.dtype.kind not in "fiO":
        return a
    new = np.empty(a.shape, dtype=object)
    for idx in np.ndindex(a.shape):
        p = f"{path}[{','.join(map(str, idx))}]"
        value = a[idx]
        out[p] = value if isinstance(value, Node) else float(value)
        new[idx] = leaf("L:" + p) if replace else value
    return new if replace else a


def c_name(path: str) -> str:
    """A variable name for a path: ``design.M[2,0]`` -> ``design_M_2_0``, ``_alpha[1]`` -> ``alpha_1``."""
    text = path.replace("[", "_").replace("]", "").replace(",", "_").replace(".", "_")
    parts = [p for p in text.split("_") if p]
    return "_".join(parts)
