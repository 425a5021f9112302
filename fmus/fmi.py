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

pythonfmu 0.7.0 workarounds (bugs of its C wrapper, found by testing; ``_take_reference``):

* On every instantiation the wrapper evaluates the FMU module's file again, keeps every
  class that evaluation makes, and releases one reference to the module's ``__dict__``
  that it never took (without a reference taken for it, the second instance of an FMU in
  a process fails with "module has no attribute ..." and later ones corrupt memory). The
  build makes that file a stub that defines nothing when evaluated again and takes the
  reference with ``_take_reference`` (``ipcosim.fmus.wrapper``, section 3).
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
import math
import re
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, NoReturn, Sequence
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from ipcosim.errors import IpcosimError
from ipcosim.fmus.experiment import default_experiment

__all__ = ["FmuBase", "FmuError", "StepFailure", "VariableInfo", "parse_unit", "positive", "nonnegative"]



def _take_reference(obj: Any) -> None:
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
#: ``id`` of the last ``sys.path`` entry whose reference the wrapper kept was released (``_one_path_entry``).
_released_entry = [0]
#: The top package this module is imported under (the FMU's private package, e.g. ``_ipcosim_lqr_..._47392e74a6``),
#: interned and held for the module's life. Every instantiation interns that name (``pathlib`` interns the parts
#: of a path; compiling the FMU's module file interns its identifier constants): with no live copy the interned
#: string was made and freed each time, and each made a new entry in the interpreter's table of interned strings,
#: whose deleted slots are reclaimed only when the table is resized (a host instantiating again and again
#: reallocated that table, 0.5-1 MB, every few thousand instantiations and doubled it once).
_PACKAGE = sys.intern(__name__.split(".", 1)[0])


class FmuError(IpcosimError, RuntimeError):
    """An FMU cannot continue (bad parameter, call in the wrong state); reported as fmi2Fatal.

    Its ``repr`` is the bare message: pythonfmu's wrapper logs ``repr(exception)``.
    """

    def __repr__(self) -> str:
        return str(self)


class StepFailure(IpcosimError, ArithmeticError):
    """A communication step that cannot be completed; reported as fmi2Discard, state kept at ``t``."""


def positive(value: float) -> str | None:
    """Parameter check: ``None`` if ``value > 0`` else the reason."""
    return None if value > 0 else "must be > 0"


def nonnegative(value: float) -> str | None:
    """Parameter check: ``None`` if ``value >= 0`` else the reason."""
    return None if value >= 0 else "must be >= 0"


# --- units ---------------------------------------------------------------------------------

_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_DERIVED: dict[str, dict[str, int]] = {
    "N": {"kg": 1, "m": 1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "Hz": {"s": -1},
}
_TOKEN = re.compile(r"^([A-Za-z]+)(-?\d+)?$")


def parse_unit(unit: str) -> dict[str, int]:
    """SI base-unit exponents of a unit string such as ``"N.m.s/rad"`` or ``"m/s2"``.

    Parameters
    ----------
    unit : str
        Factors joined by ``.``; everything after a ``/`` is in the denominator; a factor
        may carry an integer exponent (``m2``, ``s-1``). ``"1"`` is dimensionless.

    Returns
    -------
    dict
        Exponent per base unit (``kg m s A K mol cd rad``), zero exponents omitted.

    Raises
    ------
    ValueError
        For a factor that is not a known unit symbol.
    """
    exps: dict[str, int] = {}
    parts = unit.split("/")
    for k, part in enumerate(parts):
        sign = 1 if k == 0 else -1
        for tok in part.split("."):
            if tok in ("", "1"):
                continue
            m = _TOKEN.match(tok)
            if not m:
                raise ValueError(f"unit {unit!r}: cannot parse factor {tok!r}")
            sym, power = m.group(1), int(m.group(2) or 1)
            if sym in _BASE:
                base = {sym: 1}
            elif sym in _DERIVED:
                base = _DERIVED[sym]
            else:
                raise ValueError(f"unit {unit!r}: unknown unit symbol {sym!r}")
            for b, e in base.items():
                exps[b] = exps.get(b, 0) + sign * power * e
    return {b: e for b, e in exps.items() if e}


# --- variable metadata -----------------------------------------------------------------------

_CAUSALITY = {c.name: c for c in Fmi2Causality}
_VARIABILITY = {v.name: v for v in Fmi2Variability}
_INITIAL = {i.name: i for i in Fmi2Initial}
_TYPES: dict[type, type] = {float: Real, int: Integer, bool: Boolean, str: String}


@dataclass
class VariableInfo:
    """What :class:`FmuBase` knows about one declared variable beyond pythonfmu's ScalarVariable."""

    name: str
    causality: str
    variability: str
    type_: type
    unit: str | None = None
    initial: str | None = None
    depends_on: tuple[str, ...] | None = None
    depends_kind: str | None = None
    initial_depends_on: tuple[str, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    value_reference: int = -1
    extra: dict[str, Any] = field(default_factory=dict)


def _one_path_entry(folder: str | None, from_wrapper: bool) -> None:
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


class FmuBase(Fmi2Slave):
    """Base class of every ipcosim FMU (a pythonfmu ``Fmi2Slave``); see the module docstring.

    Subclasses declare their variables in ``__init__`` and implement ``setup()`` and
    ``step(t, h)``; optionally ``parameters_changed()`` (tunable parameters) and
    ``teardown()``.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        _one_path_entry(self.resources, "logger" in kwargs)  # only the wrapper passes its logger
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

    # --- declaring variables -----------------------------------------------------------------

    def add_variable(self, name: str, causality: str, *, start: Any = None, unit: str | None = None,
                     description: str | None = None, variability: str | None = None,
                     type_: type = float, initial: str | None = None,
                     getter: Callable[[], Any] | None = None, setter: Callable[[Any], None] | None = None,
                     depends_on: Sequence[str] | None = None, depends_kind: str | None = None,
                     initial_depends_on: Sequence[str] | None = None,
                     check: Callable[[Any], str | None] | None = None) -> VariableInfo:
        """Declare one FMI scalar variable; see the module docstring.

        Parameters
        ----------
        name : str
            FMI variable name; also the instance attribute holding the value unless
            ``getter``/``setter`` are given.
        causality : str
            ``"input"``, ``"output"``, ``"parameter"``, ``"calculatedParameter"`` or ``"local"``.
        start : optional
            Initial attribute value (and the XML start value where FMI requires one).
        unit : str, optional
            Unit string (``parse_unit``); Real variables only.
        description : str, optional
            Text for the modelDescription.
        variability : str, optional
            Default: ``fixed`` for parameters, ``continuous`` for other Reals, ``discrete``
            for other types.
        type_ : type
            ``float``, ``int``, ``bool`` or ``str``.
        initial : str, optional
            Override of the ``initial`` attribute (outputs: see the module docstring).
        getter, setter : callable, optional
            Value access instead of the attribute ``name``.
        depends_on : sequence of str, optional
            Outputs: the inputs the output depends on directly (default: none).
        depends_kind : str, optional
            Outputs: FMI ``dependenciesKind`` applied to every entry of ``depends_on``.
        initial_depends_on : sequence of str, optional
            Outputs: inputs and parameters that determine the output at initialization.
            ``None`` (default) = every input and parameter.
        check : callable, optional
            Parameters: ``check(value) -> None | reason`` run on leaving initialization.

        Returns
        -------
        VariableInfo
        """
        self._check_declaration(name, causality, type_, unit)
        variability, initial = _attributes(causality, type_, variability, initial, initial_depends_on)
        if causality == "output":
            depends_on = depends_on or ()   # an output depends on no input unless told
        getter, setter = self._accessors(name, causality, variability, type_, start, getter, setter)
        vr = self._register(_TYPES[type_](name, causality=_CAUSALITY[causality],
                                          variability=_VARIABILITY[variability],
                                          initial=_INITIAL[initial] if initial else None, description=description,
                                          getter=getter, setter=setter), type_)
        self.info[name] = VariableInfo(
            name=name, causality=causality, variability=variability, type_=type_, unit=unit, initial=initial,
            depends_on=_tuple_or_none(depends_on), depends_kind=depends_kind,
            initial_depends_on=_tuple_or_none(initial_depends_on), check=check, value_reference=vr)
        return self.info[name]

    def _register(self, var: Any, type_: type) -> int:
        """Register a pythonfmu variable and index its getter and setter by value reference; returns the reference."""
        self.register_variable(var, nested=False)
        self._getters[type_][var.value_reference] = var.getter
        if var.setter is not None:
            self._setters[type_][var.value_reference] = var.setter
        return var.value_reference

    def _check_declaration(self, name: str, causality: str, type_: type, unit: str | None) -> None:
        """A new name, a known causality and type, and a unit only on a Real (one that parses)."""
        if name in self.info:
            raise FmuError(f"{type(self).__name__}: variable {name!r} declared twice")
        if causality not in _CAUSALITY:
            raise FmuError(f"{type(self).__name__}.{name}: unknown causality {causality!r}")
        if type_ not in _TYPES:
            raise FmuError(f"{type(self).__name__}.{name}: unsupported type {type_!r}")
        if unit is not None:
            if type_ is not float:
                raise FmuError(f"{type(self).__name__}.{name}: only Real variables carry a unit")
            parse_unit(unit)

    def _accessors(self, name: str, causality: str, variability: str, type_: type, start: Any,
                   getter: Callable[[], Any] | None,
                   setter: Callable[[Any], None] | None) -> tuple[Callable[[], Any], Callable[[Any], None] | None]:
        """The value's getter and setter: the given ones, else the instance attribute ``name``
        (set to ``start``); none for a calculated parameter or a constant; a parameter's setter
        marks the parameters changed (:meth:`_parameter_setter`)."""
        if getter is None and setter is None and name in _RESERVED:
            raise FmuError(f"{type(self).__name__}: variable name {name!r} clashes with an FmuBase attribute; "
                           "pass getter/setter or rename it")
        if getter is None and setter is None and start is not None and not hasattr(self, name):
            setattr(self, name, type_(start))
        if getter is None:
            getter = (lambda n=name: getattr(self, n))
        if setter is None and causality != "calculatedParameter" and variability != "constant":
            setter = (lambda v, n=name: setattr(self, n, v))
        if causality == "parameter" and setter is not None:
            setter = self._parameter_setter(name, variability, setter)
        return getter, setter

    def add_input(self, name: str, *, start: Any = 0.0, **kwargs: Any) -> VariableInfo:
        """Declare an input (``start`` required by FMI; default 0)."""
        return self.add_variable(name, "input", start=start, **kwargs)

    def add_output(self, name: str, *, start: Any = 0.0, **kwargs: Any) -> VariableInfo:
        """Declare an output (``depends_on``: direct input dependencies, default none)."""
        return self.add_variable(name, "output", start=start, **kwargs)

    def add_parameter(self, name: str, *, start: Any, tunable: bool = False, **kwargs: Any) -> VariableInfo:
        """Declare a parameter (``fixed`` unless ``tunable``; non-finite Reals are rejected)."""
        return self.add_variable(name, "parameter", start=start,
                                 variability="tunable" if tunable else "fixed", **kwargs)

    def add_local(self, name: str, *, start: Any = 0.0, **kwargs: Any) -> VariableInfo:
        """Declare a local (observable internal) variable."""
        return self.add_variable(name, "local", start=start, **kwargs)

    def _parameter_setter(self, name: str, variability: str,
                          setter: Callable[[Any], None]) -> Callable[[Any], None]:
        def set_parameter(value: Any) -> None:
            if self.initialized:
                if variability != "tunable":
                    raise FmuError(f"parameter {name} is fixed: it cannot be set to {value!r} after initialization")
                self._parameters_dirty = True
            setter(value)
        return set_parameter

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
        """Make this instance's ``resources/`` the first place its private package imports from.

        A process that loads one FMU build twice from two extraction folders (a master that
        extracts per run) shares one copy of the private package, imported from the first
        folder, which may be gone by now; a module imported lazily (off the default path, e.g.
        the design stack) must then come from this instance's folder (same build, same files).
        """
        top = _PACKAGE
        if not top.startswith("_ipcosim_") or not self.resources:
            return
        root = Path(self.resources) / top
        for name, module in list(sys.modules.items()):
            path = getattr(module, "__path__", None)
            if path is None or not (name == top or name.startswith(top + ".")):
                continue
            folder = str(root.joinpath(*name.split(".")[1:]))
            if folder not in path and Path(folder).is_dir():
                path.insert(0, folder)

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

    # --- FMI 2.0 call order -------------------------------------------------------------------
    # States of FMI 2.0 co-simulation (standard, section 4.2.4): instantiated ->
    # (fmi2EnterInitializationMode) initialization -> (fmi2ExitInitializationMode) stepping ->
    # (fmi2Terminate) terminated. fmi2Reset returns to instantiated (pythonfmu creates a new
    # instance). The FMUs declare canGetAndSetFMUstate="false", so every fmi2DoStep must start
    # where the last completed one ended (the start time for the first; a discarded step may be
    # retried from the same point).
    #
    # What pythonfmu 0.7.0's wrapper lets a Python FMU return decides how a refused call is
    # reported: fmi2DoStep returns fmi2Discard when ``do_step`` returns False, and every Python
    # exception becomes fmi2Fatal; no entry point can return fmi2Error. So an out-of-order
    # fmi2DoStep is logged with status fmi2Error (naming the call, its arguments and the state),
    # returns fmi2Discard and changes nothing (the instance stays usable); a set call in a state
    # that forbids it (a fixed parameter after initialization, anything after terminate) is
    # fmi2Fatal with the same kind of message, because its only other outcome would be fmi2OK.

    #: Relative tolerance on a communication point continuing the last step.
    TIME_TOLERANCE = 1e-9

    def enter_initialization_mode(self) -> None:
        if self.fmi_state != "instantiated":
            self._fail(f"fmi2EnterInitializationMode in state {self.fmi_state}: allowed only once, after "
                       f"fmi2Instantiate (or fmi2Reset)")
        self.fmi_state = "initialization"

    def _order_initialized(self) -> None:
        """fmi2ExitInitializationMode succeeded: stepping starts at the experiment's start time."""
        self.fmi_state = "stepping"
        self._next_time = self.start_time

    def _step_order_error(self, t: float, h: float) -> str | None:
        """Why ``fmi2DoStep(t, h)`` is refused in the current state, or None (the message is built
        only for a refusal: this runs on every step)."""
        expected = self._next_time
        if (self.fmi_state == "stepping" and math.isfinite(h) and h > 0 and math.isfinite(t)
                and abs(t - expected) <= self.TIME_TOLERANCE * max(1.0, abs(expected), h)):
            return None
        call = f"fmi2DoStep(currentCommunicationPoint = {t!r}, communicationStepSize = {h!r})"
        if self.fmi_state != "stepping":
            return (f"{call} in state {self.fmi_state}: allowed only after fmi2ExitInitializationMode and "
                    f"before fmi2Terminate")
        if not (math.isfinite(h) and h > 0):
            return f"{call} in state stepping: the step size must be a positive finite number"
        return (f"{call} in state stepping: the communication point does not continue the last step, "
                f"which ended at t = {expected!r} (this FMU cannot go back or skip time)")

    def _set_order_error(self, type_: type) -> str | None:
        """Why a set call is refused in the current state, or None."""
        if self.fmi_state == "terminated":
            return f"fmi2Set{_TYPES[type_].__name__} in state terminated: no value can be set after fmi2Terminate"
        return None

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
            _take_reference(obj)
        raise FmuError("\n".join([*pending, message]))

    # --- modelDescription.xml ----------------------------------------------------------------

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:  # noqa: B006 -- pythonfmu's signature
        """pythonfmu's model description plus units, unit definitions and the true model structure."""
        root = super().to_xml(model_options)
        self._add_default_experiment(root)
        self._add_units(root)
        old = root.find("ModelStructure")
        if old is not None:
            root.remove(old)
        ms = SubElement(root, "ModelStructure")
        index = {info.name: info.value_reference + 1 for info in self.info.values()}
        self._add_outputs(ms, index)
        self._add_initial_unknowns(ms, index)
        return root

    def _add_default_experiment(self, root: Element) -> None:
        """``DefaultExperiment`` (:func:`default_experiment`) before ``ModelVariables``, unless the
        class declares its own."""
        if root.find("DefaultExperiment") is not None:
            return
        period = None
        for sv in root.iter("ScalarVariable"):
            real = sv.find("Real")
            if sv.get("name") == "sample_period" and real is not None and real.get("start"):
                period = float(real.get("start"))
        at = list(root).index(root.find("ModelVariables"))
        root.insert(at, Element("DefaultExperiment", default_experiment(period)))

    def _add_units(self, root: Element) -> None:
        """Each Real variable's ``unit`` attribute, and the ``UnitDefinitions`` after ``CoSimulation``."""
        units: dict[str, dict[str, int]] = {}
        for sv in root.iter("ScalarVariable"):
            info = self.info.get(sv.get("name"))
            if info is None or info.unit is None:
                continue
            real = sv.find("Real")
            if real is not None:
                real.set("unit", info.unit)
                units[info.unit] = parse_unit(info.unit)
        if units:
            ud = Element("UnitDefinitions")
            for name in sorted(units):
                u = SubElement(ud, "Unit", {"name": name})
                SubElement(u, "BaseUnit", {b: str(e) for b, e in units[name].items()})
            children = list(root)
            pos = next(k for k, c in enumerate(children) if c.tag == "CoSimulation") + 1
            root.insert(pos, ud)

    def _add_outputs(self, ms: Element, index: dict[str, int]) -> None:
        """``ModelStructure/Outputs``: each output with the inputs it depends on directly (``depends_on``)."""
        inputs = [i.name for i in self.info.values() if i.causality == "input"]
        outputs = sorted((i for i in self.info.values() if i.causality == "output"), key=lambda i: index[i.name])
        if not outputs:
            return
        node = SubElement(ms, "Outputs")
        for info in outputs:
            deps = info.depends_on or ()
            for d in deps:
                if d not in inputs:
                    raise FmuError(f"{type(self).__name__}.{info.name}: depends_on {d!r} is not an input")
            attrib = {"index": str(index[info.name]), "dependencies": _indices(deps, index)}
            if deps and info.depends_kind:
                attrib["dependenciesKind"] = " ".join([info.depends_kind] * len(deps))
            SubElement(node, "Unknown", attrib)

    def _add_initial_unknowns(self, ms: Element, index: dict[str, int]) -> None:
        """``ModelStructure/InitialUnknowns``: calculated outputs and parameters with what determines them at
        initialization (``initial_depends_on``: inputs and exact parameters; absent = all of them)."""
        knowns = [i.name for i in self.info.values()
                  if i.causality == "input" or (i.causality == "parameter" and i.initial == "exact")]
        unknowns = sorted((i for i in self.info.values()
                           if (i.causality == "output" and i.initial in ("calculated", "approx"))
                           or i.causality == "calculatedParameter"), key=lambda i: index[i.name])
        if not unknowns:
            return
        node = SubElement(ms, "InitialUnknowns")
        for info in unknowns:
            attrib = {"index": str(index[info.name])}
            if info.initial_depends_on is not None:
                for d in info.initial_depends_on:
                    if d not in knowns:
                        raise FmuError(f"{type(self).__name__}.{info.name}: initial_depends_on {d!r} is "
                                       "not an input or an exact parameter")
                attrib["dependencies"] = _indices(info.initial_depends_on, index)
            SubElement(node, "Unknown", attrib)


#: Attribute names used by pythonfmu's Fmi2Slave and FmuBase (a variable stored as an attribute must avoid them).
_RESERVED = frozenset(dir(FmuBase)) | {
    "vars", "instance_name", "resources", "visible", "log_queue", "guid", "author", "license", "version",
    "copyright", "modelName", "description", "default_experiment", "info", "start_time", "initialized",
    "_parameters_dirty"}


def _indices(names: Iterable[str], index: dict[str, int]) -> str:
    return " ".join(str(i) for i in sorted(index[n] for n in names))


def _attributes(causality: str, type_: type, variability: str | None, initial: str | None,
                initial_depends_on: Sequence[str] | None) -> tuple[str, str | None]:
    """A variable's FMI ``variability`` and ``initial`` where not given: parameters ``fixed`` and
    ``exact``, other Reals ``continuous``, other types ``discrete`` (never continuous); outputs
    ``calculated``, or ``exact`` when they depend on nothing at initialization."""
    if variability is None:
        if causality in ("parameter", "calculatedParameter"):
            variability = "fixed"
        else:
            variability = "continuous" if type_ is float else "discrete"
    if variability == "continuous" and type_ is not float:
        variability = "discrete"
    if causality == "output":
        if initial is None:
            initial = "calculated" if initial_depends_on is None or len(initial_depends_on) else "exact"
    elif causality == "parameter" and initial is None:
        initial = "exact"
    return variability, initial


def _tuple_or_none(names: Sequence[str] | None) -> tuple[str, ...] | None:
    return tuple(names) if names is not None else None
