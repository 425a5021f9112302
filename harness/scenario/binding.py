"""A scenario bound to its FMUs: every connector and connection checked against the FMUs'
model descriptions before anything is instantiated (parse first, then run).

:func:`bind` turns a :class:`ipcosim.harness.scenario.ssp.Scenario` into an immutable :class:`System`: one
:class:`Instance` per component (its FMU's interface as a :class:`Model`, its connectors as
FMU variables, its bound parameter values) and resolved :class:`Link` s (value references,
linear transformation and unit conversion folded into one factor and offset). Component
swaps (``--swap plant=hil``) are applied here, checked for compatible connectors.
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

from ipcosim.errors import IpcosimError, UsageError, closest
from ipcosim.harness.master import integers
from ipcosim.harness.master.system import (
    SSP_TYPE,
    TRANSFORMATION_TYPES,
    Instance,
    Link,
    Model,
    System,
    Variable,
    kind_of,
)
from ipcosim.harness.scenario.ssp import (
    BASE_UNITS,
    SIGNAL_KINDS,
    Component,
    Connection,
    Connector,
    Parameter,
    ParameterLink,
    ParameterSet,
    Scenario,
    Unit,
    fmu_search_path,
)


class BindingError(IpcosimError, ValueError):
    """A scenario that does not match its FMUs (missing FMU or variable, wrong kind, type or unit)."""


class FMUNotFoundError(BindingError, FileNotFoundError):
    """A component's FMU file does not exist."""


class SetError(UsageError, BindingError):
    """A ``--set`` that does not fit the scenario (a command-line mistake)."""


class SwapFileNotFoundError(UsageError, FMUNotFoundError):
    """A ``--swap`` naming an FMU file that does not exist (a command-line mistake)."""


class UnconnectedInputWarning(UserWarning):
    """An input connector that no connection feeds (it keeps its start value)."""


# --------------------------------------------------------------------------- FMU interface
_MODEL_CACHE: dict[tuple[str, float, int], Model] = {}


def read_model(path: Path, display: str | None = None) -> Model:
    """Read an FMU's model description into a :class:`Model` (cached per file version).

    Raises
    ------
    BindingError
        If the file is not a readable FMI 2.0 co-simulation FMU.
    """
    path = Path(path)
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime, stat.st_size)
    if key in _MODEL_CACHE:
        return _MODEL_CACHE[key]
    md = _model_description(path, display or os.fspath(path))
    variables = _variables(md)
    model = Model(name=md.modelName, variables=variables, feedthrough=_feedthrough(md, variables),
                  path=path.resolve(), guid=md.guid, model_identifier=md.coSimulation.modelIdentifier,
                  fmi_version=md.fmiVersion, units=_units(md),
                  can_handle_variable_step=bool(md.coSimulation.canHandleVariableCommunicationStepSize),
                  default_step=_positive_or_none(md.defaultExperiment, "stepSize"),
                  default_stop=_positive_or_none(md.defaultExperiment, "stopTime"),
                  enumerations={v.name: {i.name: int(i.value) for i in v.declaredType.items}
                                for v in md.modelVariables if v.type == "Enumeration" and v.declaredType})
    _MODEL_CACHE[key] = model
    return model


def _model_description(path: Path, display: str) -> Any:
    """fmpy's model description of an FMI 2.0 or 3.0 co-simulation FMU; else one line naming ``display``."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # noqa: BLE001 -- fmpy raises assorted exceptions
        reason = str(exc).splitlines()[0] if str(exc) else exc
        raise BindingError(f"{display}: not a readable FMU ({reason!r})") from None
    if md.fmiVersion not in ("2.0", "3.0"):
        raise BindingError(f"{display}: FMI {md.fmiVersion} FMU; FMI 2.0 and 3.0 are supported")
    if md.coSimulation is None:
        raise BindingError(f"{display}: does not support co-simulation")
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
        kind = kind_of(type_)
        if kind == "real":
            return float(start)
        if kind == "integer":
            return int(start)
        if type_ == "Boolean":
            return str(start).strip().lower() in ("true", "1")
    except ValueError:
        return None
    return start


# --------------------------------------------------------------------------- bound system
# --------------------------------------------------------------------------- swaps
@dataclass(frozen=True)
class SwapTarget:
    """What a swap puts in place of a component.

    Attributes
    ----------
    fmu : Path
        The replacement FMU.
    parameters : mapping of str to value
        Start values for the replacement (e.g. the HIL adapter's card URI).
    realtime : bool
        Run the scenario paced to wall-clock time when this component is present.
    description : str
        One line for messages and metadata.
    """

    fmu: Path
    parameters: Mapping[str, Any] = field(default_factory=dict)
    realtime: bool = False
    description: str = ""


@dataclass(frozen=True)
class SwapRequest:
    """The context an alias resolver gets: which component of which scenario is swapped."""

    scenario: Scenario
    component: str
    model: Model | None  # the original FMU's interface (None if its FMU is missing)
    fmu_dirs: tuple[Path, ...] = ()  # the folders FMUs are looked for in (``ssp.fmu_search_path``)


#: Swap aliases: ``--swap plant=hil`` looks up ``hil`` here. A resolver takes a SwapRequest and
#: returns a SwapTarget (or a mapping of its fields). The modules listed in
#: ``SWAP_ALIAS_PROVIDERS`` are imported on first use and their ``SWAP_ALIASES`` (name ->
#: resolver) registered; :func:`register_swap_alias` adds one from anywhere.
swap_aliases: dict[str, Callable[[SwapRequest], SwapTarget]] = {}
SWAP_ALIAS_PROVIDERS: tuple[str, ...] = ()  # ``hil``: ipcosim.harness.hil registers it on import
_providers_loaded = False


def register_swap_alias(name: str, resolver: Callable[[SwapRequest], SwapTarget]) -> None:
    """Make ``--swap COMPONENT=name`` resolve through ``resolver``."""
    swap_aliases[name] = resolver


def _load_alias_providers() -> None:
    global _providers_loaded
    if _providers_loaded:
        return
    _providers_loaded = True
    import importlib

    for module in SWAP_ALIAS_PROVIDERS:
        for name, resolver in importlib.import_module(module).SWAP_ALIASES.items():
            register_swap_alias(name, resolver)


def resolve_swap(scenario: Scenario, component: str, target: str | os.PathLike[str] | SwapTarget,
                 model: Model | None) -> SwapTarget:
    """A SwapTarget for ``--swap component=target`` (an FMU path or a registered alias)."""
    if isinstance(target, SwapTarget):
        return target
    text = os.fspath(target)
    if text.endswith(".fmu") or os.sep in text or "/" in text:
        path = Path(text)
        if not path.is_file():
            raise SwapFileNotFoundError(f"--swap {component}={text}: FMU file does not exist")
        return SwapTarget(fmu=path.resolve(), description=f"FMU {text}")
    _load_alias_providers()
    if text not in swap_aliases:
        raise BindingError(f"--swap {component}={text}: not an .fmu file and not a known alias; "
                           f"{closest(text, swap_aliases)}")
    target = swap_aliases[text](SwapRequest(scenario, component, model, tuple(fmu_search_path())))
    return target if isinstance(target, SwapTarget) else SwapTarget(**target)


# --------------------------------------------------------------------------- units
def _unit_table(scenario: Scenario, *models: Model) -> dict[str, Unit]:
    table: dict[str, Unit] = {}
    for m in models:
        table.update(m.units)
    table.update(scenario.units)
    return table


def unit_conversion(src: str | None, dst: str | None, table: Mapping[str, Unit]) -> tuple[float, float] | None:
    """Factor and offset converting a value in unit ``src`` to unit ``dst``; None if incompatible.

    Equal names (or a missing unit on either side) convert with (1, 0). Different names convert
    when both are defined with the same base-unit exponents.
    """
    if src is None or dst is None or src == dst:
        return (1.0, 0.0)
    a, b = table.get(src), table.get(dst)
    if a is None or b is None or a.exponents != b.exponents:
        return None
    # value_SI = factor * v + offset
    return (a.factor / b.factor, (a.offset - b.offset) / b.factor)


# --------------------------------------------------------------------------- binding
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
    for line in _unmatched(scenario, instances):
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
    return Instance(name=comp.name, model=model, connectors=tuple(connectors), parameters=tuple(params),
                    step_size_hint=comp.step_size_hint, swapped_from=swapped_from, realtime=realtime)


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
        _check_connector(c, var, where, _unit_table(scenario, model))
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
        return _enumeration_value(model, var, p, what)
    if p.unit is not None and kind_of(var.type) == "real" and not p.suppress_unit_conversion:
        connector = comp.connector(var.name)
        target = var.unit or (connector.unit if connector is not None else None)
        table = {**_unit_table(scenario, model), **pset.units}
        conv = unit_conversion(p.unit, target, table)
        if conv is None:
            known = [u for u in (p.unit, target) if u not in table]
            why = (f"unit {known[0]!r} is not defined" if known else "the units measure different quantities")
            raise BindingError(f"{what}: {p.name} = {value!r} {p.unit} cannot be converted to {var.name}'s unit "
                               f"{target!r} ({why}); SSP converts units before applying a value")
        value = conv[0] * float(value) + conv[1]
    t = p.transform
    if t is not None:
        if t.kind == "LinearTransformation":
            if kind_of(var.type) != "real":
                raise BindingError(f"{what}: ssc:LinearTransformation on {var.name} ({var.type}); SSP defines it "
                                   f"for Real values only")
            value = t.factor * float(value) + t.offset
        else:
            table_map = dict(t.mapping)
            key = int(bool(value)) if t.kind == "BooleanMappingTransformation" else int(value)
            mapped = table_map.get(key, key)
            value = bool(mapped) if t.kind == "BooleanMappingTransformation" else mapped
    return convert_value(var, value, f"{what}: {p.name}")


def _enumeration_value(model: Model, var: Variable, p: Parameter, what: str) -> int:
    """An ``ssv:Enumeration`` value (an item name, through an ``EnumerationMappingTransformation``
    where a mapping gives one) as the value of that item in the variable's enumeration type."""
    items = model.enumerations.get(var.name)
    if items is None:
        raise BindingError(f"{what}: {p.name} = {p.value!r} is an enumeration item, but {var.name} is {var.type}, "
                           f"not an Enumeration")
    name = p.value
    if p.transform is not None:
        if p.transform.kind != "EnumerationMappingTransformation":
            raise BindingError(f"{what}: ssc:{p.transform.kind} on the enumeration value {p.name}; SSP maps "
                               f"enumeration items with ssc:EnumerationMappingTransformation")
        name = dict(p.transform.mapping).get(name, name)
    if name not in items:
        raise BindingError(f"{what}: {p.name} = {name!r} is not an item of {var.name}'s enumeration "
                           f"({', '.join(items)})")
    return items[name]


def _unmatched(scenario: System | Scenario, instances: list[Instance]) -> list[str]:
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


def rebuild_command(folder: Path) -> str | None:
    """The command that rebuilds ``folder`` if it is one of the project's build folders, else None."""
    from ipcosim.harness.native.cbuild import OUT_DIRS
    from ipcosim.harness.paths import BUILD_DIR

    folder = folder.resolve()
    if not folder.is_relative_to(Path(BUILD_DIR).resolve()):
        return None
    fmi = {d: v for v, d in OUT_DIRS.items()}.get(folder.name)
    return "ipcosim build" + ("" if fmi is None else " --native" + ("" if fmi == "2" else f" --fmi {fmi}"))


def rebuild_hint(model: Model) -> str:
    """How to rebuild an FMU of the project's own build folder that is older than the sources (a checkout
    updated since ``ipcosim build``), from the folder's build cache (``ipcosim.fmus.pybuild.is_stale``); where
    the cache does not say (the native folders), that it may be. "" for an FMU that is current or from
    anywhere else."""
    from ipcosim.fmus.pybuild import is_stale

    command = rebuild_command(model.path.parent) if model.path else None
    if command is None:
        return ""
    stale = is_stale(model.path)
    if stale is False:
        return ""
    verb = "is" if stale else "may be"
    return f"; {model.path.resolve().parent} {verb} older than the sources: `{command}` rebuilds it"


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
    kinds = (va.causality, vb.causality)
    if kinds in (("input", "output"), ("parameter", "calculatedParameter"), ("input", "calculatedParameter")):
        a, b, va, vb = b, a, vb, va
        src_name, dst_name = conn.end, conn.start
    elif kinds in (("output", "input"), ("calculatedParameter", "parameter"), ("calculatedParameter", "input")):
        src_name, dst_name = conn.start, conn.end
    elif kinds[0] == kinds[1] and kinds[0] in ("output", "input"):
        raise BindingError(f"{origin}: connection {conn.start} -> {conn.end} connects two {kinds[0]}s; "
                           f"a connection must join one output to one input")
    else:
        raise BindingError(f"{origin}: connection {conn.start} -> {conn.end}: {conn.start} is {kinds[0]}, "
                           f"{conn.end} is {kinds[1]}; the master carries output -> input and calculatedParameter "
                           f"-> parameter or input connections between components (SSP 1.0 section 5.3.2.1)")
    _check_types(conn, va, vb, f"{origin}: connection {src_name} -> {dst_name}")
    if dst_name in fed:
        raise BindingError(f"{origin}: input {dst_name} is connected twice (from {fed[dst_name]} and {src_name})")
    fed[dst_name] = src_name
    if conn.transformation == "EnumerationMappingTransformation":
        return Link(a.name, va, b.name, vb, mapping=_enumeration_mapping(conn, a.model, va, b.model, vb,
                                                                         f"{origin}: connection {src_name} -> "
                                                                         f"{dst_name}"))
    if SSP_TYPE[va.type] != "Real":
        return Link(a.name, va, b.name, vb, mapping=tuple(conn.mapping))
    factor, offset = conn.factor, conn.offset
    if not conn.suppress_unit_conversion:
        ua, ub = _connector_unit(scenario, a.name, va), _connector_unit(scenario, b.name, vb)
        conv = unit_conversion(ua, ub, _unit_table(scenario, a.model, b.model))
        if conv is None:
            raise BindingError(f"{origin}: connection {src_name} -> {dst_name}: unit {ua!r} does not match "
                               f"{ub!r} (mismatched units; define both in <ssd:Units> to convert, or set "
                               f"suppressUnitConversion)")
        # SSP 1.0 section 4.5.2: the unit conversion first, then the transformation:
        # factor * (c0 * x + c1) + offset
        factor, offset = factor * conv[0], factor * conv[1] + offset
    return Link(a.name, va, b.name, vb, factor, offset)


def _enumeration_mapping(conn: Connection, ma: Model, va: Variable, mb: Model, vb: Variable,
                         where: str) -> tuple[tuple[int, int], ...]:
    """An ``ssc:EnumerationMappingTransformation`` (pairs of item names) as pairs of the items' values
    in the source's and the target's enumeration types."""
    ia, ib = ma.enumerations.get(va.name, {}), mb.enumerations.get(vb.name, {})
    pairs = []
    for source, target in conn.mapping:
        for name, items, v in ((source, ia, va), (target, ib, vb)):
            if name not in items:
                raise BindingError(f"{where}: ssc:EnumerationMappingTransformation names {name!r}, which is not an "
                                   f"item of {v.name}'s enumeration ({', '.join(items)})")
        pairs.append((ia[source], ib[target]))
    return tuple(pairs)


def _check_types(conn: Any, va: Variable, vb: Variable, where: str) -> None:
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


def _is_connected(scenario: Scenario, comp: str, connector: str) -> bool:
    return any((c.start_element == comp and c.start_connector == connector)
               or (c.end_element == comp and c.end_connector == connector) for c in scenario.connections)


def _connector_unit(scenario: Scenario, comp: str, var: Variable) -> str | None:
    c = next((x for x in scenario.component(comp).connectors if x.name == var.name), None)
    return (c.unit if c is not None and c.unit else None) or var.unit


def _check_connector(c: Connector, var: Variable, where: str, units: Mapping[str, Unit]) -> None:
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


def convert_value(var: Variable, value: Any, what: str) -> Any:
    """``value`` (a string from the command line or a typed value) as the variable's type.

    Raises
    ------
    BindingError
        ``what`` is not a valid value of the variable's type.
    """
    t = var.type
    kind = kind_of(t)
    try:
        if kind == "real":
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        if kind == "integer":  # exactly (FMI 3.0: Int8 .. UInt64), in the type's range below
            x = integers.exact_integer(value)
            if t not in integers.RANGE or integers.in_range(x, t):
                return x
        if t == "Boolean":
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ("true", "1"):
                return True
            if text in ("false", "0"):
                return False
            raise ValueError
        if t == "String":
            return str(value)
    except (TypeError, ValueError):
        raise BindingError(f"{what}: {value!r} is not a valid {t} value") from None
    if kind == "integer":
        lo, hi = integers.RANGE[t]
        raise BindingError(f"{what}: {value!r} is out of the range of {t} ({lo} .. {hi})")
    raise BindingError(f"{what}: variables of type {t} cannot be set")


def with_set(system: System, set: Mapping[str, Any]) -> tuple[System, dict[tuple[str, str], Any]]:
    """Check a run's ``set`` (``--set comp.var=value``) against the system.

    Returns the system unchanged and the values keyed by (component, variable) with
    values converted to the variables' types.

    Raises
    ------
    SetError
        Unknown component or variable, a variable that cannot be set (output, local,
        constant), a connected input, or a value that does not parse.
    """
    out: dict[tuple[str, str], Any] = {}
    for key, value in set.items():
        comp, sep, var = _split_name(system, str(key))
        if not sep or not comp or not var:
            raise SetError(f"--set {key}={value}: expected COMPONENT.VARIABLE=VALUE")
        try:
            inst = system.instance(comp)
        except KeyError:
            raise SetError(f"--set {key}={value}: no component {comp!r}; "
                               f"{closest(comp, (i.name for i in system.instances))}") from None
        v = inst.model.variables.get(var)
        model_name = inst.model.path.name if inst.model.path else inst.model.name
        where = f"--set {key}={value}: component {comp!r} ({model_name})"
        if v is None:
            settable = (n for n, x in inst.model.variables.items() if x.settable)
            raise SetError(f"{where} has no variable {var!r}; {closest(var, settable)} "
                               f"(`ipcosim describe {system.scenario.name}` lists them){rebuild_hint(inst.model)}")
        if not v.settable:
            raise SetError(f"{where}: {var!r} is {v.causality}/{v.variability} and cannot be set")
        link = system.link_into(comp, var) or next((k for k in system.parameter_links
                                                     if k.dst == comp and k.dst_var.name == var), None)
        if link is not None:
            raise SetError(f"{where}: {v.causality} {var!r} is connected to {link.src_name}; set the source "
                           f"instead")
        try:
            out[(comp, var)] = convert_value(v, value, f"--set {key}")
        except BindingError as exc:
            raise SetError(str(exc)) from None
    return system, out


def _split_name(system: System, key: str) -> tuple[str, str, str]:
    """``component``, ``.``, ``variable`` of ``component.variable``: the longest component name that
    ``key`` starts with (a nested system's component is ``sub.component``), else split at the first dot."""
    names = sorted((i.name for i in system.instances if key.startswith(i.name + ".")), key=len, reverse=True)
    if names:
        return names[0], ".", key[len(names[0]) + 1:]
    return key.partition(".")


def default_step(system: System) -> tuple[float | None, str]:
    """The communication step when none is given, and where it comes from.

    The SSD's step (the OSP ``FixedStepAlgorithm`` annotation of its DefaultExperiment; SSP 1.0's
    DefaultExperiment has no step attribute), else the FMUs' common DefaultExperiment stepSize:
    the largest step that divides every FMU's (in whole nanoseconds), so each FMU's own step is a
    whole number of communication steps. ``(None, reason)`` when there is none.
    """
    sc = system.scenario
    if sc.experiment.step_size is not None:
        return sc.experiment.step_size, f"{sc.origin}: DefaultExperiment (osp:FixedStepAlgorithm baseStepSize)"
    steps = {i.name: i.model.default_step for i in system.instances if i.model.default_step is not None}
    if not steps:
        return None, f"{sc.origin}: no step in the SSD and no FMU gives a DefaultExperiment stepSize"
    ns = {k: round(v * 1e9) for k, v in steps.items()}
    if any(n < 1 or abs(n - steps[k] * 1e9) > 1e-6 * steps[k] * 1e9 for k, n in ns.items()):
        if len(set(steps.values())) == 1:
            return next(iter(steps.values())), "the FMUs' DefaultExperiment stepSize"
        return None, (f"{sc.origin}: the FMUs' DefaultExperiment steps ("
                      + ", ".join(f"{k} {v:g} s" for k, v in steps.items()) + ") have no common step")
    g = 0
    for n in ns.values():
        g = math.gcd(g, n)
    return g / 1e9, "the FMUs' DefaultExperiment stepSize (" + ", ".join(f"{k} {v:g} s" for k, v in steps.items()) + ")"


def default_stop_time(system: System) -> tuple[float | None, str]:
    """The stop time when none is given: the SSD's DefaultExperiment stopTime, else the FMUs'
    DefaultExperiment stopTime when those that give one agree; ``(None, reason)`` otherwise."""
    sc = system.scenario
    if sc.experiment.stop_time is not None:
        return sc.experiment.stop_time, f"{sc.origin}: DefaultExperiment stopTime"
    stops = {i.name: i.model.default_stop for i in system.instances if i.model.default_stop is not None}
    if len(set(stops.values())) == 1:
        return next(iter(stops.values())), "the FMUs' DefaultExperiment stopTime"
    if not stops:
        return None, f"{sc.origin}: no DefaultExperiment stopTime in the SSD or the FMUs"
    return None, (f"{sc.origin}: no stopTime in the SSD and the FMUs' differ ("
                  + ", ".join(f"{k} {v:g} s" for k, v in stops.items()) + ")")


def warn_all(system: System) -> None:
    """Issue the system's notes as UnconnectedInputWarning / UserWarning."""
    for note in system.warnings:
        category = UnconnectedInputWarning if "is not connected" in note else UserWarning
        warnings.warn(note, category, stacklevel=3)
