"""Every exception class the package defines is an ``IpcosimError`` (``ipcosim.errors``), so a caller
catches anything ipcosim reports with one ``except``; each keeps its built-in base too, so ``except
ValueError`` and the like still work."""
from __future__ import annotations

import importlib
import inspect
import pkgutil

import ipcosim
from ipcosim.errors import IpcosimError


def _exception_classes() -> dict[str, type]:
    """Every class a module of the package defines that is an ``Exception`` (a warning is a category, not
    an error; a ``BaseException`` that is no ``Exception``, such as an interrupt, must stay out of
    ``except Exception``)."""
    found = {}
    for info in pkgutil.walk_packages(ipcosim.__path__, "ipcosim."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, cls in vars(module).items():
            if inspect.isclass(cls) and cls.__module__ == module.__name__ and issubclass(cls, Exception) \
                    and not issubclass(cls, Warning):
                found[f"{info.name}.{name}"] = cls
    return found


def test_every_exception_is_an_ipcosim_error() -> None:
    classes = _exception_classes()
    assert len(classes) > 40  # the walk reached the whole package, not one room
    outside = sorted(name for name, cls in classes.items() if not issubclass(cls, IpcosimError))
    assert not outside, f"exception classes outside the IpcosimError tree: {outside}"


def test_the_built_in_bases_are_kept() -> None:
    """A refined error is still the built-in it refines, as code that predates the tree catches it."""
    from ipcosim.fmus.expm import SingularMatrixError
    from ipcosim.fmus.params import ParameterError, UnknownPresetError
    from ipcosim.harness.native.redesign import NativeParameterError

    assert issubclass(ParameterError, ValueError) and issubclass(UnknownPresetError, KeyError)
    assert issubclass(SingularMatrixError, ArithmeticError) and issubclass(NativeParameterError, KeyError)
