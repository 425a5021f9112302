"""An FMU's model description read into the master's :class:`Model` (its interface: variables,
direct feedthrough, units, default experiment, enumerations), cached per file version; an FMU
that cannot be read is one line naming it."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

from ipcosim.harness.master.system import Model, Variable, value_type_of
from ipcosim.harness.scenario.errors import BindingError
from ipcosim.harness.scenario.structure import BASE_UNITS, Unit

_MODEL_CACHE: dict[tuple[str, float, int], Model] = {}


def read_model(path: Path, display: str | None = None) -> Model:
    """Read an FMU's model description into a :class:`Model` (cached per file version).

    Raises
    ------
    BindingError
        If the file is not a readable FMI 2.0 or 3.0 FMU with co-simulation or model exchange.
    """
    path = Path(path)
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime, stat.st_size)
    if key in _MODEL_CACHE:
        return _MODEL_CACHE[key]
    md = _model_description(path, display or os.fspath(path))
    variables = _variables(md)
    model = Model(name=md.modelName, variables=variables, feedthrough=_feedthrough(md, variables),
                  path=path.resolve(), guid=md.guid,
                  model_identifier=(md.coSimulation or md.modelExchange).modelIdentifier,
                  fmi_version=md.fmiVersion, units=_units(md),
                  can_handle_variable_step=md.coSimulation is None
                  or bool(md.coSimulation.canHandleVariableCommunicationStepSize),
                  default_step=_positive_or_none(md.defaultExperiment, "stepSize"),
                  default_stop=_positive_or_none(md.defaultExperiment, "stopTime"),
                  default_tolerance=_positive_or_none(md.defaultExperiment, "tolerance"),
                  enumerations={v.name: {i.name: int(i.value) for i in v.declaredType.items}
                                for v in md.modelVariables if v.type == "Enumeration" and v.declaredType},
                  co_simulation=md.coSimulation is not None,
                  model_exchange_identifier=md.modelExchange.modelIdentifier if md.modelExchange else None)
    _MODEL_CACHE[key] = model
    return model


def _model_description(path: Path, display: str) -> Any:
    """fmpy's model description of an FMI 2.0 or 3.0 FMU (co-simulation or model exchange); else one
    line naming ``display``."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # noqa: BLE001 -- fmpy raises assorted exceptions
        reason = str(exc).splitlines()[0] if str(exc) else exc
        raise BindingError(f"{display}: not a readable FMU ({reason!r})") from None
    if md.fmiVersion not in ("2.0", "3.0"):
        raise BindingError(f"{display}: FMI {md.fmiVersion} FMU; FMI 2.0 and 3.0 are supported")
    if md.coSimulation is None and md.modelExchange is None:
        raise BindingError(f"{display}: offers neither co-simulation nor model exchange")
    return md


def _variables(md: Any) -> dict[str, Variable]:
    """Every model variable by name, with its unit (its own or its declared type's) and start value."""
    variables = {}
    for v in md.modelVariables:
        unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
        type_ = f"{v.type}[]" if getattr(v, "dimensions", None) else v.type  # FMI 3.0 arrays: not carried
        variables[v.name] = Variable(name=v.name, vr=int(v.valueReference), type=type_,
                                     causality=v.causality or "local", variability=v.variability or "continuous",
                                     initial=v.initial, unit=unit, start=_start_value(v.type, v.start),
                                     description=v.description or "")
    return variables


def _feedthrough(md: Any, variables: Mapping[str, Variable]) -> dict[str, frozenset[str]]:
    """The inputs each output depends on directly (ModelStructure); every input where it says
    nothing (an output without dependencies, or missing from it: assume the worst)."""
    inputs = frozenset(n for n, v in variables.items() if v.causality == "input")
    feedthrough = {}
    for u in md.outputs:
        if u.dependencies is None:
            feedthrough[u.variable.name] = inputs
        else:
            feedthrough[u.variable.name] = frozenset(d.name for d in u.dependencies if d.name in inputs)
    for name, v in variables.items():
        if v.causality == "output" and name not in feedthrough:
            feedthrough[name] = inputs
    return feedthrough


def _units(md: Any) -> dict[str, Unit]:
    """The unit definitions by name (base-unit exponents, factor, offset)."""
    units = {}
    for u in md.unitDefinitions:
        b = u.baseUnit
        if b is None:
            units[u.name] = Unit(u.name, (0,) * len(BASE_UNITS))
        else:
            units[u.name] = Unit(u.name, tuple(int(getattr(b, k)) for k in BASE_UNITS), float(b.factor),
                                 float(b.offset))
    return units


def _positive_or_none(experiment: Any, name: str) -> float | None:
    try:
        value = float(getattr(experiment, name, None))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return value if value > 0 and value < float("inf") else None


def _start_value(type_: str, start: Any) -> Any:
    if start is None:
        return None
    try:
        value_type = value_type_of(type_)
        if value_type == "real":
            return float(start)
        if value_type == "integer":
            return int(start)
        if type_ == "Boolean":
            return str(start).strip().lower() in ("true", "1")
    except ValueError:
        return None
    return start
