"""Thin FMI 2.0 co-simulation plumbing over pythonfmu 0.7.0, shared by every FMU script.

An FMU script is one file per FMU, ``fmus/fmu_<snake_model_name>.py`` or
``controllers/fmu_<snake_model_name>.py``, holding one subclass of :class:`FmuBase`.
The class only copies values in and out; the physics or the control law lives in a
pure module. Example::

    from ipcosim.fmus.fmi import FmuBase, StepFailure

    class Integrator(FmuBase):
        '''Integrates its input (first docstring line = modelDescription description).'''

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.add_input("u", start=0.0, unit="V", description="integrand")
            # depends_on: the inputs this output depends on *directly* (within the same
            # communication point); () = no direct feed-through (no algebraic loop).
            # initial_depends_on: what the output depends on at initialization.
            self.add_output("y", unit="V.s", description="integral", depends_on=(),
                            initial_depends_on=("y0",))
            self.add_parameter("y0", start=0.0, unit="V.s", description="initial value")
            self.add_parameter("gain", start=1.0, unit="1", description="gain",
                               check=lambda v: None if v > 0 else "must be > 0")

        def setup(self) -> None:
            # Called on leaving initialization mode, after every parameter passed its
            # checks: build the model and compute the outputs at the start time.
            self.y = self.y0

        def step(self, t: float, h: float) -> None:
            # Advance from t to t + h. Raise StepFailure for a step that cannot be done
            # (the FMU stays at t); any other exception is a bug.
            y = self.y + self.gain * self.u * h
            if not math.isfinite(y):
                raise StepFailure(f"y became {y} in the step from t = {t} s")
            self.y = y

Declaring variables: ``add_input``, ``add_output``, ``add_parameter``, ``add_local`` or
the general ``add_variable``; each takes ``name``, ``start``, ``unit``, ``description``
and optional ``getter``/``setter`` callables (default: the instance attribute of the
same name, created with ``start``). ``type_`` may be ``float`` (FMI Real, default),
``int``, ``bool`` or ``str``; non-Real inputs, outputs and locals are declared
``variability="discrete"`` as FMI requires. Parameters are ``fixed`` by default
(``tunable=True`` allows changes between steps; ``parameters_changed()`` is then called
before the next step). Units are plain strings over ``kg m s A K mol cd rad`` and the
derived ``N V Ohm H W J Hz``, combined with ``.``, ``/`` and integer exponents
(``m/s2``, ``N.m.s/rad``, ``kg.m2``, ``1``); the generated modelDescription.xml gets the
matching ``<UnitDefinitions>``.

What the generated modelDescription.xml holds (``to_xml``, which pythonfmu's builder
calls): ``unit`` attributes and ``<UnitDefinitions>``; outputs ``initial="calculated"``
when they depend on something at initialization (they are then computed in
``exit_initialization_mode`` and listed in ``<InitialUnknowns>`` with those
dependencies) and ``initial="exact"`` with their start value otherwise;
``<ModelStructure><Outputs>`` with the declared direct dependencies.

Error reporting, as pythonfmu 0.7.0's C wrapper allows (measured through fmpy with a
logger callback):

* ``step`` raising :class:`StepFailure` -> the message is logged with status
  fmi2Error (category ``logStatusError``) and ``fmi2DoStep`` returns **fmi2Discard**;
  the FMU state stays at the communication point ``t`` and the instance stays usable.
* A bad parameter (non-finite Real, a failed ``check``, an exception in ``setup``) ->
  ``fmi2ExitInitializationMode`` returns **fmi2Fatal** and the wrapper logs, with status
  fmi2Fatal and an empty category, the two-line text
  ``Fatal py exception encountered: [exitInitializationMode] PyObject_CallMethod`` /
  ``parameter NAME = VALUE UNIT: reason``. Any Python exception reaching the wrapper
  becomes fmi2Fatal (it has no path to fmi2Error); the instance may then only be freed.
  **The last line of the fmi2Fatal message is the one to report.**
* Any other exception in any entry point (``get_*``/``set_*`` included) -> the same, with
  ``ExceptionType: text at file.py:line`` as the last line.

The wrapper forwards log messages (including the fmi2Fatal one) **only to an instance
instantiated with loggingOn = fmi2True** (and, after ``fmi2SetDebugLogging`` with a
category list, only those categories): a master that wants the error text must
instantiate with logging on.

The base class is composed of one part per concern: the declaration API (:mod:`ipcosim.fmus.fmi_declare`),
the FMI 2.0 call order (:mod:`ipcosim.fmus.fmi_order`), the model description
(:mod:`ipcosim.fmus.fmi_xml`) and the run-time answers to pythonfmu 0.7.0's wrapper bugs
(:mod:`ipcosim.fmus.fmi_fixes`); this module holds the FMI entry points and the error reporting.
"""
from __future__ import annotations

import math
import traceback
from typing import Any, Callable, NoReturn, Sequence

from pythonfmu import Fmi2Slave
from pythonfmu.enums import Fmi2Status

from ipcosim.fmus.fmi_declare import _TYPES, Declarations, VariableInfo, parse_unit
from ipcosim.fmus.fmi_errors import FmuError, StepFailure
from ipcosim.fmus.fmi_fixes import one_path_entry, own_resources_first, take_reference
from ipcosim.fmus.fmi_order import CallOrder
from ipcosim.fmus.fmi_xml import ModelDescriptionXml

__all__ = ["FmuBase", "FmuError", "StepFailure", "VariableInfo", "parse_unit", "positive", "nonnegative"]


def positive(value: float) -> str | None:
    """Parameter check: ``None`` if ``value > 0`` else the reason."""
    return None if value > 0 else "must be > 0"


def nonnegative(value: float) -> str | None:
    """Parameter check: ``None`` if ``value >= 0`` else the reason."""
    return None if value >= 0 else "must be >= 0"


class FmuBase(Declarations, CallOrder, ModelDescriptionXml, Fmi2Slave):
    """Base class of every ipcosim FMU (a pythonfmu ``Fmi2Slave``); see the module docstring.

    Subclasses declare their variables in ``__init__`` and implement ``setup()`` and
    ``step(t, h)``; optionally ``parameters_changed()`` (tunable parameters) and
    ``teardown()``.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        one_path_entry(self.resources, "logger" in kwargs)  # only the wrapper passes its logger
        doc = (type(self).__doc__ or "").strip().splitlines()
        if self.description is None and doc:
            self.description = doc[0].strip()
        self.info: dict[str, VariableInfo] = {}
        self.start_time = 0.0
        self.initialized = False
        self.fmi_state = "instantiated"   # FMI 2.0 call order: see "FMI 2.0 call order" below
        self._next_time = 0.0
        self._parameters_dirty = False
        self._getters: dict[type, dict[int, Callable[[], Any]]] = {t: {} for t in _TYPES}
        self._setters: dict[type, dict[int, Callable[[Any], None]]] = {t: {} for t in _TYPES}
        self._own_resources_first()

    # --- hooks for subclasses ----------------------------------------------------------------

    def setup(self) -> None:
        """Build the model from the (checked) parameters and compute the outputs at ``start_time``."""

    def step(self, t: float, h: float) -> None:
        """Advance from ``t`` to ``t + h``; raise :class:`StepFailure` if that is impossible."""
        raise NotImplementedError

    def parameters_changed(self) -> None:
        """Called before a step when a tunable parameter changed after initialization."""

    def teardown(self) -> None:
        """Called by ``terminate``."""

    @classmethod
    def build_files(cls) -> dict[str, str]:
        """``{file name: text}`` the build stores next to the FMU's private package's modules
        (e.g. data computed at build time with tools the FMU must not need at run time)."""
        return {}

    # --- FMI entry points (called by pythonfmu's C wrapper) ----------------------------------

    def setup_experiment(self, start_time: float, stop_time: float | None = None,
                         tolerance: float | None = None) -> None:
        self.start_time = float(start_time)

    def _get(self, type_: type, vrs: Sequence[int]) -> list[Any]:
        try:
            getters = self._getters[type_]
            return [type_(getters[vr]()) for vr in vrs]
        except Exception as exc:  # noqa: BLE001
            error = self._access_message("get", type_, vrs, exc)
        self._fail(error)

    def _set(self, type_: type, vrs: Sequence[int], values: Sequence[Any]) -> None:
        error = self._set_order_error(type_)
        if error is None:
            try:
                setters = self._setters[type_]
                for vr, value in zip(vrs, values):
                    setters[vr](value)
            except Exception as exc:  # noqa: BLE001
                error = (f"fmi2Set{_TYPES[type_].__name__} in state {self.fmi_state}: {exc}"
                         if isinstance(exc, FmuError) else self._access_message("set", type_, vrs, exc))
        if error is not None:
            self._fail(error)

    def _access_message(self, what: str, type_: type, vrs: Sequence[int], exc: BaseException) -> str:
        if isinstance(exc, KeyError):
            vr = exc.args[0] if exc.args else "?"
            name = self.vars[vr].name if isinstance(vr, int) and vr in self.vars else f"valueReference {vr}"
            kind = _TYPES[type_].__name__
            return f"cannot {what} {name} as {kind}" + (" (not settable)" if what == "set" and vr in self.vars else "")
        return self._message(exc)

    def get_real(self, vrs: Sequence[int]) -> list[float]:
        return self._get(float, vrs)

    def get_integer(self, vrs: Sequence[int]) -> list[int]:
        return self._get(int, vrs)

    def get_boolean(self, vrs: Sequence[int]) -> list[bool]:
        return self._get(bool, vrs)

    def get_string(self, vrs: Sequence[int]) -> list[str]:
        return self._get(str, vrs)

    def set_real(self, vrs: Sequence[int], values: Sequence[float]) -> None:
        self._set(float, vrs, values)

    def set_integer(self, vrs: Sequence[int], values: Sequence[int]) -> None:
        self._set(int, vrs, values)

    def set_boolean(self, vrs: Sequence[int], values: Sequence[bool]) -> None:
        self._set(bool, vrs, values)

    def set_string(self, vrs: Sequence[int], values: Sequence[str]) -> None:
        self._set(str, vrs, values)

    # Exceptions are turned into a message inside ``except`` and raised again (by ``_fail``)
    # only after the ``except`` block, so that nothing chains the original exception and its
    # traceback to what pythonfmu's wrapper receives (module docstring).

    def exit_initialization_mode(self) -> None:
        error = None
        try:
            self._own_resources_first()
            self.check_parameters()
            self.setup()
        except Exception as exc:  # noqa: BLE001 -- reported through the FMI logger
            error = self._message(exc)
        if error is not None:
            self._fail(error)
        self.initialized = True
        self._order_initialized()

    def _own_resources_first(self) -> None:
        """This instance's ``resources/`` first for its private package (:func:`own_resources_first`)."""
        own_resources_first(self.resources)

    def do_step(self, current_time: float, step_size: float) -> bool:
        refused = self._step_order_error(current_time, step_size)
        if refused is not None:
            self.log(refused, Fmi2Status.error)
            return False  # fmi2Discard: see "FMI 2.0 call order"
        try:
            if self._parameters_dirty:
                self.check_parameters()
                self.parameters_changed()
                self._parameters_dirty = False
            self.step(current_time, step_size)
            self._next_time = current_time + step_size
            return True
        except StepFailure as exc:
            self.log(str(exc), Fmi2Status.error)
            return False
        except Exception as exc:  # noqa: BLE001
            error = self._message(exc)
        self._fail(error)

    def terminate(self) -> None:
        self.fmi_state = "terminated"
        error = None
        try:
            self.teardown()
        except Exception as exc:  # noqa: BLE001
            error = self._message(exc)
        if error is not None:
            self._fail(error)

    def check_parameters(self) -> None:
        """Reject non-finite Real parameters and run every parameter's ``check``.

        Raises
        ------
        FmuError
            ``parameter NAME = VALUE UNIT: reason`` for the first offending parameter.
        """
        for info in self.info.values():
            if info.causality != "parameter":
                continue
            value = self.vars[info.value_reference].getter()
            unit = f" {info.unit}" if info.unit and info.unit != "1" else ""
            if info.type_ is float and not math.isfinite(value):
                raise FmuError(f"parameter {info.name} = {value}{unit}: not a finite number")
            if info.check is not None:
                reason = info.check(value)
                if reason:
                    raise FmuError(f"parameter {info.name} = {value}{unit}: {reason}")

    # --- error reporting ---------------------------------------------------------------------

    @staticmethod
    def _message(exc: BaseException) -> str:
        text = str(exc).strip()
        if isinstance(exc, (FmuError, StepFailure, ValueError, ArithmeticError)) and text:
            return text.splitlines()[0]
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        return f"{type(exc).__name__}: {text or 'no message'}{where}"

    def _fail(self, message: str) -> NoReturn:
        """Raise ``message`` to pythonfmu's wrapper, which logs it with status fmi2Fatal and returns fmi2Fatal.

        Two pythonfmu 0.7.0 bugs shape this (module docstring): messages still queued when an
        exception reaches the wrapper corrupt the interpreter's memory, so they are moved into
        the exception's text; and the wrapper releases the instance, its log queue and the
        class twice, so extra references are kept (leaked on purpose).
        """
        pending = [m.msg for m in self.log_queue]
        self.log_queue.clear()
        for obj in (self, self.log_queue, type(self)):
            take_reference(obj)
        raise FmuError("\n".join([*pending, message]))


#: Attribute names used by pythonfmu's Fmi2Slave and FmuBase (a variable stored as an attribute must avoid them).
FmuBase.RESERVED = frozenset(dir(FmuBase)) | {
    "vars", "instance_name", "resources", "visible", "log_queue", "guid", "author", "license", "version",
    "copyright", "modelName", "description", "default_experiment", "info", "start_time", "initialized",
    "_parameters_dirty"}
