"""What the FMU glue does at run time against the bugs of pythonfmu 0.7.0's C wrapper (its build-time
edits of the wrapper binary and module file are :mod:`ipcosim.fmus.wrapper`'s).

pythonfmu 0.7.0 workarounds (bugs of its C wrapper, found by testing; ``take_reference``):

* On every instantiation the wrapper evaluates the FMU module's file again, keeps every
  class that evaluation makes, and releases one reference to the module's ``__dict__``
  that it never took (without a reference taken for it, the second instance of an FMU in
  a process fails with "module has no attribute ..." and later ones corrupt memory). The
  build makes that file a stub that defines nothing when evaluated again and takes the
  reference with ``take_reference`` (``ipcosim.fmus.wrapper``, section 3).
* After a Python exception the wrapper releases the instance, its log queue and the class
  twice (in the failing call and again in fmi2FreeInstance); ``FmuBase._fail``, through
  which every exception leaves, adds one reference to each first (without this the
  process crashes in a later garbage collection).
* Messages still queued by ``log`` when an exception reaches the wrapper are flushed
  while the exception is pending, which loses the exception's text; ``_fail`` moves them
  into the exception's text instead, and raises outside any ``except`` block so that no
  chained exception or traceback travels with it.
"""
from __future__ import annotations

import ctypes
import sys
from pathlib import Path
from typing import Any


def take_reference(obj: Any) -> None:
    """Add one reference to ``obj`` that nothing owns: it compensates a reference that
    pythonfmu 0.7.0's wrapper releases without owning it (module docstring). A Python
    container would not do: the wrapper's extra release would leave it pointing at a
    possibly freed object."""
    _py_incref(obj)


_py_incref = ctypes.pythonapi.Py_IncRef
_py_incref.argtypes = [ctypes.py_object]
_py_incref.restype = None
_py_decref = ctypes.pythonapi.Py_DecRef
_py_decref.argtypes = [ctypes.py_object]
_py_decref.restype = None
#: ``id`` of the last ``sys.path`` entry whose reference the wrapper kept was released (``one_path_entry``).
_released_entry = [0]
#: The top package this module is imported under (the FMU's private package, e.g. ``_ipcosim_lqr_..._47392e74a6``),
#: interned and held for the module's life. Every instantiation interns that name (``pathlib`` interns the parts
#: of a path; compiling the FMU's module file interns its identifier constants): with no live copy the interned
#: string was made and freed each time, and each made a new entry in the interpreter's table of interned strings,
#: whose deleted slots are reclaimed only when the table is resized (a host instantiating again and again
#: reallocated that table, 0.5-1 MB, every few thousand instantiations and doubled it once).
_PACKAGE = sys.intern(__name__.split(".", 1)[0])


def one_path_entry(folder: str | None, from_wrapper: bool) -> None:
    """Keep one ``sys.path`` entry of an instance's resources folder: pythonfmu 0.7.0's wrapper inserts
    it at the front at every instantiation (``fmi2Instantiate``), and sys.path would grow by one
    entry a cycle in a process that instantiates and frees an FMU again and again.

    The wrapper also keeps a reference to the string it inserts, which no one releases: for an
    instance the wrapper makes (``from_wrapper``) that entry's extra reference is released once, so the
    string is freed when a later instantiation's entry replaces it. (``fmi2Reset`` makes the instance
    again without inserting: the entry at the front is then the one already released.)"""
    if folder and sys.path.count(folder) > 1:
        first = sys.path.index(folder)
        sys.path[first + 1:] = [p for p in sys.path[first + 1:] if p != folder]
    if from_wrapper and folder and sys.path and sys.path[0] == folder and id(sys.path[0]) != _released_entry[0]:
        _released_entry[0] = id(sys.path[0])
        _py_decref(sys.path[0])


def own_resources_first(resources: str | None) -> None:
    """Make an instance's ``resources`` folder the first place its private package imports from.

    A process that loads one FMU build twice from two extraction folders (a master that
    extracts per run) shares one copy of the private package, imported from the first
    folder, which may be gone by now; a module imported lazily (off the default path, e.g.
    the design stack) must then come from this instance's folder (same build, same files).
    """
    top = _PACKAGE
    if not top.startswith("_ipcosim_") or not resources:
        return
    root = Path(resources) / top
    for name, module in list(sys.modules.items()):
        path = getattr(module, "__path__", None)
        if path is None or not (name == top or name.startswith(top + ".")):
            continue
        folder = str(root.joinpath(*name.split(".")[1:]))
        if folder not in path and Path(folder).is_dir():
            path.insert(0, folder)

