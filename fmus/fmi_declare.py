"""Declaring an FMU's variables (:class:`Declarations`, a part of :class:`ipcosim.fmus.fmi.FmuBase`):
each FMI scalar variable with its causality, variability, initial, unit, dependencies and parameter
check, and the unit strings (:func:`parse_unit`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Variability, Integer, Real, String

from ipcosim.fmus.fmi_errors import FmuError

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



class Declarations:
    """The declaration API of :class:`ipcosim.fmus.fmi.FmuBase` (its ``add_*`` methods)."""

    #: Attribute names a variable stored as an attribute must avoid (set by ``ipcosim.fmus.fmi``: those of
    #: pythonfmu's Fmi2Slave and FmuBase).
    RESERVED: frozenset[str] = frozenset()


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
        if getter is None and setter is None and name in self.RESERVED:
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
