"""A scenario bound to its FMUs: every connector and connection checked against the FMUs'
model descriptions before anything is instantiated (parse first, then run).

:func:`bind` turns a :class:`ipcosim.harness.scenario.ssp.Scenario` into an immutable :class:`System`: one
:class:`Instance` per component (its FMU's interface as a :class:`Model`, its connectors as
FMU variables, its bound parameter values) and resolved :class:`Link` s (value references,
linear transformation and unit conversion folded into one factor and offset). Component
swaps (``--swap plant=hil``) are applied here, checked for compatible connectors.

What it draws on, one module each: the FMUs' interfaces (``model_description``), the swaps
(``swaps``), units (``units``), a value as its variable's type (``values``), SSP's
transformations (``transformations``) and the checks SSP's rules make (``checks``).
"""
from __future__ import annotations

import os
import warnings
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from ipcosim.errors import closest
from ipcosim.harness.master.system import SSP_TYPE, Instance, Link, Model, System, Variable, value_type_of
from ipcosim.harness.scenario.checks import check_connector, check_types, unmatched_names
from ipcosim.harness.scenario.elements import SIGNAL_KINDS
from ipcosim.harness.scenario.errors import BindingError, FMUNotFoundError
from ipcosim.harness.scenario.model_description import read_model
from ipcosim.harness.scenario.rebuild import rebuild_hint
from ipcosim.harness.scenario.structure import Component, Connection, Parameter, ParameterLink, ParameterSet, Scenario
from ipcosim.harness.scenario.transformations import (
    after_unit_conversion,
    enumeration_mapping,
    enumeration_value,
    transformed,
)
from ipcosim.harness.scenario.units import connector_unit, unit_conversion, unit_table
from ipcosim.harness.scenario.values import convert_value

if TYPE_CHECKING:  # the swaps are loaded by a run that swaps a component
    from ipcosim.harness.scenario.swaps import SwapTarget


class UnconnectedInputWarning(UserWarning):
    """An input connector that no connection feeds (it keeps its start value)."""


def bind(scenario: Scenario, swap: Mapping[str, str | os.PathLike[str] | SwapTarget] | None = None,
         fmu_files: Mapping[str, Path] | None = None, models: Mapping[str, Model] | None = None,
         strict_parameters: bool = True, strict_swaps: bool = False) -> System:
    """Check a scenario against its FMUs and resolve it into a :class:`System`.

    Parameters
    ----------
    scenario : Scenario
    swap : mapping of component name to FMU path, alias or SwapTarget, optional
        Components to replace (``--swap``), each checked for compatible connectors.
    fmu_files : mapping of component name to Path, optional
        FMU files to use instead of the scenario's resolved ones (archive members extracted
        by the caller).
    models : mapping of component name to Model, optional
        Ready model interfaces (tests with mock slaves); bypasses reading FMU files.
    strict_parameters : bool
        An unknown parameter in a binding is an error (True) or a warning (False; SSP allows
        ignoring it).
    strict_swaps : bool
        The same for the bindings of swapped-in components (``--strict``); by default the
        parameters such an FMU does not have are ignored, named in one warning per component.

    Raises
    ------
    FMUNotFoundError, BindingError
        Naming the file, component and variable.
    """
    swap = dict(swap or {})
    for comp in swap:
        if comp not in {c.name for c in scenario.components}:
            raise BindingError(f"--swap {comp}=...: scenario {scenario.name!r} has no component {comp!r}; "
                               f"{closest(comp, (c.name for c in scenario.components))}")
    notes: list[str] = []   # warnings: what may be wrong (unconnected inputs, ignored parameters)
    infos: list[str] = []   # notes: what was done (swaps, connectors left out)
    instances = [_bind_component(scenario, comp, swap, dict(fmu_files or {}), dict(models or {}),
                                 (strict_parameters, strict_swaps), notes, infos) for comp in scenario.components]
    for line in unmatched_names(scenario, instances):
        if strict_parameters:
            raise BindingError(line)
        notes.append(line + "; ignored")
    by_name = {i.name: i for i in instances}
    fed: dict[str, str] = {}  # which output feeds each input: {"comp.input": "comp.output"}
    every = [_bind_connection(scenario, conn, by_name, fed) for conn in scenario.connections]
    links = [k for k in every if k.src_var.causality != "calculatedParameter"]
    carried = tuple(k for k in every if k.src_var.causality == "calculatedParameter")
    for k in carried:
        if not k.dst_var.settable:
            raise BindingError(f"{scenario.origin}: connection {k.src_name} -> {k.dst_name}: {k.dst_name} is "
                               f"{k.dst_var.causality}/{k.dst_var.variability} and cannot be set")
    for inst in instances:
        for v in inst.inputs:
            if f"{inst.name}.{v.name}" not in fed:
                start = inst.start_value(v.name)
                notes.append(f"{scenario.origin}: input {inst.name}.{v.name} is not connected; it keeps its start "
                             f"value {start!r}")
    return System(scenario=scenario, instances=tuple(instances), links=tuple(links), parameter_links=carried,
                  warnings=tuple(notes),
                  notes=tuple(infos))


def _component_model(scenario: Scenario, comp: Component, swapped: bool, fmu_files: Mapping[str, Path],
                     models: Mapping[str, Model]) -> Model | None:
    """The model interface of a component's own FMU (None for a missing FMU that is swapped out anyway)."""
    model = models.get(comp.name)
    if model is not None:
        return model
    fmu = fmu_files.get(comp.name, comp.fmu)
    if fmu is None or not Path(fmu).is_file():
        if swapped:
            return None
        raise FMUNotFoundError(f"{scenario.origin}: component {comp.name!r}: FMU {comp.source} not found "
                               "(run `ipcosim build`, or give its folder with --fmu-dir / IPCOSIM_FMU_PATH)")
    return read_model(Path(fmu), f"{scenario.origin}: component {comp.name!r} ({comp.source})")


def _bind_component(scenario: Scenario, comp: Component, swap: Mapping[str, Any], fmu_files: Mapping[str, Path],
                    models: Mapping[str, Model], strict: tuple[bool, bool], notes: list[str],
                    infos: list[str]) -> Instance:
    """One component as an :class:`Instance`: its FMU (or the one swapped in), connectors checked
    against the FMU's variables, and its parameter bindings converted (``strict``: for its own
    FMU, for one swapped in); appends to ``notes``/``infos``."""
    model = _component_model(scenario, comp, comp.name in swap, fmu_files, models)
    swapped_from, realtime, extra = None, False, {}
    if comp.name in swap:
        from ipcosim.harness.scenario.swaps import resolve_swap

        target = resolve_swap(scenario, comp.name, swap[comp.name], model)
        swapped_from = model.path.name if model is not None and model.path else comp.source
        realtime = target.realtime
        extra = dict(target.parameters)
        model = read_model(target.fmu, f"--swap {comp.name}={target.fmu}")
        infos.append(f"component {comp.name!r}: {swapped_from} swapped for "
                     f"{target.description or target.fmu.name}")
    assert model is not None
    where = f"{scenario.origin}: component {comp.name!r} ({model.path.name if model.path else comp.source})"
    connectors = _bind_connectors(scenario, comp, model, where, swapped_from, infos)
    params = _bind_parameters(scenario, comp, model, where, strict[0] if swapped_from is None else strict[1], notes)
    for name, value in extra.items():
        var = model.variables.get(name)
        if var is None or not var.settable:
            raise BindingError(f"--swap {comp.name}: the swapped-in FMU has no settable variable {name!r}; "
                               f"{closest(name, (n for n, v in model.variables.items() if v.settable))}")
        params.append((var, convert_value(var, value, f"--swap {comp.name}: {name}")))
    interface = _interface(comp, model, where)
    if interface == "ModelExchange":  # the master integrates it to any point: a shorter last step too
        model = replace(model, can_handle_variable_step=True)
    return Instance(name=comp.name, model=model, connectors=tuple(connectors), parameters=tuple(params),
                    step_size_hint=comp.step_size_hint, swapped_from=swapped_from, realtime=realtime,
                    interface=interface, tolerance=scenario.experiment.relative_tolerance or model.default_tolerance)


def _interface(comp: Component, model: Model, where: str) -> str:
    """The FMU interface a component runs: the one its SSD ``implementation`` asks for, else
    co-simulation where the FMU offers it, else model exchange."""
    has = {"CoSimulation": model.co_simulation, "ModelExchange": model.model_exchange_identifier is not None}
    asked = comp.implementation
    if asked in has:
        if not has[asked]:
            offered = "co-simulation" if has["CoSimulation"] else "model exchange"
            raise BindingError(f"{where}: implementation={asked!r}, but the FMU offers {offered} only")
        return asked
    return "CoSimulation" if has["CoSimulation"] else "ModelExchange"


def _bind_connectors(scenario: Scenario, comp: Component, model: Model, where: str, swapped_from: str | None,
                     infos: list[str]) -> list[Variable]:
    """The FMU variables of a component's input and output connectors, each checked (type,
    causality, unit); an unconnected connector a swapped-in FMU lacks is left out (noted in
    ``infos``). Connectors of the other kinds (``parameter``, ``calculatedParameter``...) are
    checked the same way but are not values of the run: a parameter is set before it."""
    connectors = []
    for c in comp.connectors:
        var = model.variables.get(c.name)
        if var is None:
            if swapped_from is not None and not _is_connected(scenario, comp.name, c.name):
                infos.append(f"component {comp.name!r}: unconnected connector {c.name!r} "
                             "is not in the swapped-in FMU and is left out")
                continue
            raise BindingError(f"{where}: connector {c.name!r} is not a variable of the FMU"
                               + (" (swapped-in FMU lacks a connected connector)" if swapped_from else ""))
        check_connector(c, var, where, unit_table(scenario, model))
        if var.causality in SIGNAL_KINDS:  # an input or output (also under SSP 2.0's kind "unspecified")
            connectors.append(var)
    return connectors


def _bind_parameters(scenario: Scenario, comp: Component, model: Model, where: str, strict: bool,
                     notes: list[str]) -> list[tuple[Variable, Any]]:
    """A component's start values from every parameter binding that reaches it, as (variable,
    converted value) in the order of SSP's precedence (a later one wins): the component's own
    bindings in element order, then those of the systems around it from the innermost to the
    top level (hierarchical names ``component.variable``, and a system connector's value where
    a connection carries it to the component). Names the FMU does not have in the component's
    own bindings are an error when ``strict``, else one note per parameter set in ``notes``; a
    variable that cannot be set is always an error."""
    params: list[tuple[Variable, Any]] = []
    for pset in comp.bindings:
        src = pset.source or "inline ParameterValues"
        missing = [p.name for p in pset.parameters if p.name not in model.variables]
        if missing:
            msg = (f"{where}: parameter set {pset.name!r} ({src}) sets {len(missing)} parameter(s) the FMU does "
                   f"not have: {', '.join(missing)}")
            if strict:
                raise BindingError(msg + rebuild_hint(model))
            notes.append(msg + "; ignored (--strict: an error)")
        for p in pset.parameters:
            var = model.variables.get(p.name)
            if var is not None:
                params.append((var, _parameter_value(scenario, comp, model, var, p, pset,
                                                     f"{where}: parameter set {pset.name!r} ({src})")))
    for binding in scenario.system_bindings:
        pset = binding.pset
        src = pset.source or "inline ParameterValues"
        for p in pset.parameters:
            for name, link in _targets(scenario, comp, binding.full_name(p.name)):
                var = model.variables.get(name)
                if var is None:
                    continue  # a name no component has: reported once for the system (_unmatched)
                what = (f"{binding.origin}: system-level parameter set {pset.name!r} ({src}) value "
                        f"{p.name!r} for {comp.name}.{name}")
                if link is not None and link.transform is not None:
                    p = replace(p, transform=link.transform)
                params.append((var, _parameter_value(scenario, comp, model, var, p, pset, what)))
    return params


def _targets(scenario: Scenario, comp: Component, full: str) -> list[tuple[str, ParameterLink | None]]:
    """The variables of ``comp`` that the hierarchical name ``full`` sets: ``comp.variable``, and
    the connectors a system connector called ``full`` is connected to (with that connection)."""
    out: list[tuple[str, ParameterLink | None]] = []
    if full.startswith(comp.name + "."):
        out.append((full[len(comp.name) + 1:], None))
    out += [(link.connector, link) for link in scenario.parameter_links
            if link.component == comp.name and link.node == full]
    return out


def _parameter_value(scenario: Scenario, comp: Component, model: Model, var: Variable, p: Parameter,
                     pset: ParameterSet, what: str) -> Any:
    """The value of parameter ``p`` for ``var``: converted from the value's unit to the variable's
    (through the parameter set's, the SSD's and the FMU's unit definitions), then transformed
    (a parameter mapping's or a connection's transformation), then as the variable's type."""
    if var.causality == "structuralParameter":
        raise BindingError(f"{what}: sets {var.name!r}, a structural parameter (FMI 3.0 configuration mode); "
                           f"structural parameters are not supported")
    if not var.settable:
        raise BindingError(f"{what}: sets {var.name!r}, which is {var.causality}/{var.variability} and cannot be set")
    if p.type == "Binary":
        raise BindingError(f"{what}: {p.name}: ssv:Binary values are not supported")
    value = p.value
    if p.type == "Enumeration":
        return enumeration_value(model, var, p, what)
    if p.unit is not None and value_type_of(var.type) == "real" and not p.suppress_unit_conversion:
        connector = comp.connector(var.name)
        target = var.unit or (connector.unit if connector is not None else None)
        table = {**unit_table(scenario, model), **pset.units}
        conv = unit_conversion(p.unit, target, table)
        if conv is None:
            known = [u for u in (p.unit, target) if u not in table]
            why = (f"unit {known[0]!r} is not defined" if known else "the units measure different quantities")
            raise BindingError(f"{what}: {p.name} = {value!r} {p.unit} cannot be converted to {var.name}'s unit "
                               f"{target!r} ({why}); SSP converts units before applying a value")
        value = conv[0] * float(value) + conv[1]
    if p.transform is not None:
        value = transformed(value, p.transform, var, what)
    return convert_value(var, value, f"{what}: {p.name}")


def _bind_connection(scenario: Scenario, conn: Connection, by_name: Mapping[str, Instance],
                     fed: dict[str, str]) -> Link:
    """One connection as a :class:`Link` from the output to the input (SSP's start/end do not
    imply direction), with its types checked, its input recorded in ``fed`` (an input fed twice
    is an error) and the linear transformation and unit conversion folded into one factor and
    offset (the unit conversion first, then the transformation)."""
    origin = scenario.origin
    a, b = by_name[conn.start_element], by_name[conn.end_element]
    va, vb = a.model.variables.get(conn.start_connector), b.model.variables.get(conn.end_connector)
    for inst, v, cname in ((a, va, conn.start_connector), (b, vb, conn.end_connector)):
        if v is None:
            raise BindingError(f"{origin}: connection {conn.start} -> {conn.end}: FMU of component "
                               f"{inst.name!r} ({inst.model.path.name if inst.model.path else inst.model.name}) "
                               f"has no variable {cname!r}; {closest(cname, inst.model.variables)}"
                               f"{rebuild_hint(inst.model)}")
    causalities = (va.causality, vb.causality)
    if causalities in (("input", "output"), ("parameter", "calculatedParameter"), ("input", "calculatedParameter")):
        a, b, va, vb = b, a, vb, va
        src_name, dst_name = conn.end, conn.start
    elif causalities in (("output", "input"), ("calculatedParameter", "parameter"), ("calculatedParameter", "input")):
        src_name, dst_name = conn.start, conn.end
    elif causalities[0] == causalities[1] and causalities[0] in ("output", "input"):
        raise BindingError(f"{origin}: connection {conn.start} -> {conn.end} connects two {causalities[0]}s; "
                           f"a connection must join one output to one input")
    else:
        raise BindingError(f"{origin}: connection {conn.start} -> {conn.end}: {conn.start} is {causalities[0]}, "
                           f"{conn.end} is {causalities[1]}; the master carries output -> input and "
                           f"calculatedParameter -> parameter or input connections between components (SSP 1.0 "
                           f"section 5.3.2.1)")
    check_types(conn, va, vb, f"{origin}: connection {src_name} -> {dst_name}")
    if dst_name in fed:
        raise BindingError(f"{origin}: input {dst_name} is connected twice (from {fed[dst_name]} and {src_name})")
    fed[dst_name] = src_name
    if conn.transformation == "EnumerationMappingTransformation":
        return Link(a.name, va, b.name, vb, mapping=enumeration_mapping(conn, a.model, va, b.model, vb,
                                                                        f"{origin}: connection {src_name} -> "
                                                                        f"{dst_name}"))
    if SSP_TYPE[va.type] != "Real":
        return Link(a.name, va, b.name, vb, mapping=tuple(conn.mapping))
    factor, offset = conn.factor, conn.offset
    if not conn.suppress_unit_conversion:
        ua, ub = connector_unit(scenario, a.name, va), connector_unit(scenario, b.name, vb)
        conv = unit_conversion(ua, ub, unit_table(scenario, a.model, b.model))
        if conv is None:
            raise BindingError(f"{origin}: connection {src_name} -> {dst_name}: unit {ua!r} does not match "
                               f"{ub!r} (mismatched units; define both in <ssd:Units> to convert, or set "
                               f"suppressUnitConversion)")
        factor, offset = after_unit_conversion(factor, offset, conv)
    return Link(a.name, va, b.name, vb, factor, offset)


def _is_connected(scenario: Scenario, comp: str, connector: str) -> bool:
    return any((c.start_element == comp and c.start_connector == connector)
               or (c.end_element == comp and c.end_connector == connector) for c in scenario.connections)


def warn_all(system: System) -> None:
    """Issue the system's notes as UnconnectedInputWarning / UserWarning."""
    for note in system.warnings:
        category = UnconnectedInputWarning if "is not connected" in note else UserWarning
        warnings.warn(note, category, stacklevel=3)
