"""The checks of a scenario against its FMUs' variables that SSP's rules make: a connector's kind,
type and unit against its FMU variable's, a connection's typing (one type at both ends, a
transformation only where the standard defines it for that type), and the values of system-level
parameter sets that reach nothing."""
from __future__ import annotations

from typing import Any, Mapping

from ipcosim.harness.master.system import SSP_TYPE, TRANSFORMATION_TYPES, Instance, System, Variable
from ipcosim.harness.scenario.errors import BindingError
from ipcosim.harness.scenario.structure import Connector, Scenario, Unit
from ipcosim.harness.scenario.units import unit_conversion


def check_types(conn: Any, va: Variable, vb: Variable, where: str) -> None:
    """SSP 1.0 typing of a connection: one connector type at both ends (FMI 3.0's sized types
    count as their SSP type: Float32/Float64 as Real, Int8..UInt64 as Integer), and a
    transformation only where the standard defines it for that type."""
    ta, tb = SSP_TYPE.get(va.type), SSP_TYPE.get(vb.type)
    for t, v in ((ta, va), (tb, vb)):
        if t is None:
            raise BindingError(f"{where}: {v.type} variables cannot be connected (the master carries Real, "
                               f"Integer, Enumeration, Boolean and String)")
    if ta != tb:
        raise BindingError(f"{where}: connects {va.type} to {vb.type}; SSP 1.0 connects connectors of one type "
                           f"(ssd:Connection), and defines no transformation between types")
    kind = conn.transformation if conn is not None else None
    if kind is not None and ta not in TRANSFORMATION_TYPES[kind]:
        raise BindingError(f"{where}: ssc:{kind} on a {ta} connection; SSP 1.0 defines it for "
                           f"{' and '.join(TRANSFORMATION_TYPES[kind])} connectors only")


def check_connector(c: Connector, var: Variable, where: str, units: Mapping[str, Unit]) -> None:
    """A connector against its FMU variable: the variable's causality fits the connector's kind (no
    structural parameter), and its type and unit are the connector's."""
    kind_ok = {"input": ("input",), "output": ("output",), "parameter": ("parameter",),
               "calculatedParameter": ("calculatedParameter",), "inout": ("input", "output"),
               "structuralParameter": ("structuralParameter",), "local": ("local",),
               "constant": ("output", "local"), "unspecified": ("input", "output", "parameter", "local",
                                                                "calculatedParameter", "structuralParameter")}
    if var.causality not in kind_ok.get(c.kind, ()):
        raise BindingError(f"{where}: connector {c.name!r} is declared {c.kind} "
                           f"but the FMU variable is {var.causality}")
    if var.causality == "structuralParameter":
        raise BindingError(f"{where}: connector {c.name!r} is a structural parameter (FMI 3.0 configuration mode); "
                           f"structural parameters are not supported")
    if c.type is not None and not _same_type(c.type, var.type):
        raise BindingError(f"{where}: connector {c.name!r} is declared {c.type} but the FMU variable is {var.type}")
    if c.unit and var.unit and unit_conversion(c.unit, var.unit, units) != (1.0, 0.0):
        raise BindingError(f"{where}: connector {c.name!r} has unit {c.unit!r} but the FMU variable has {var.unit!r}")


def _same_type(declared: str, fmu_type: str) -> bool:
    """Whether a connector's SSP type fits an FMU variable's type: SSP 1.0's generic types (Real,
    Integer...) fit every FMI type of that kind; SSP 2.0's sized types fit only themselves (and
    FMI 2.0's Real and Integer the Float64 and Int32 they are)."""
    if declared in ("Real", "Integer", "Boolean", "String", "Enumeration"):
        return declared == SSP_TYPE.get(fmu_type, fmu_type)
    return declared == fmu_type or {declared, fmu_type} in ({"Float64", "Real"}, {"Int32", "Integer"})


def unmatched_names(scenario: System | Scenario, instances: list[Instance]) -> list[str]:
    """One line per system-level parameter set naming the values that reach no variable of any
    component and no system connector (SSP ignores them; a slip of a name otherwise goes unseen)."""
    sc = scenario if isinstance(scenario, Scenario) else scenario.scenario
    lines = []
    for binding in sc.system_bindings:
        missing = []
        for p in binding.pset.parameters:
            full = binding.full_name(p.name)
            if full in sc.system_connectors:
                continue
            if not any(full.startswith(i.name + ".") and full[len(i.name) + 1:] in i.model.variables
                       for i in instances):
                missing.append(full)
        if missing:
            src = binding.pset.source or "inline ParameterValues"
            lines.append(f"{binding.origin}: system-level parameter set {binding.pset.name!r} ({src}) sets "
                         f"{len(missing)} name(s) no component variable or system connector has: "
                         f"{', '.join(missing)}")
    return lines
