"""The immutable description of an SSP scenario: the system flattened into components, their
connectors and parameter bindings, the connections with their transformations, units and the default
experiment (what :func:`ipcosim.harness.scenario.ssp.load_scenario` returns), and the one operation
on it, binding another of its parameter sets (:func:`select_parameter_set`).

Parse first, then run: nothing here is changed by a run; runtime values live in the execution.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

from ipcosim.errors import closest
from ipcosim.harness.scenario.errors import ScenarioError, UnknownParameterSetError

#: The SI base units, in the order of :attr:`Unit.exponents`.
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# --------------------------------------------------------------------------- description
@dataclass(frozen=True)
class Connector:
    """A connector of a component as the SSD declares it."""

    name: str
    kind: str  # input | output | parameter | calculatedParameter | inout
    type: str | None  # Real | Integer | Boolean | String | Enumeration | Binary | None (undeclared)
    unit: str | None = None


@dataclass(frozen=True)
class Transform:
    """A transformation of a value on its way to its target (``ssc:GTransformationChoice``):
    ``LinearTransformation`` (``factor * x + offset``, after any unit conversion) or an Integer or
    Boolean mapping (``mapping``: (source, target) pairs; values not in it pass unchanged)."""

    type: str  # its SSP element: LinearTransformation, IntegerMappingTransformation...
    factor: float = 1.0
    offset: float = 0.0
    mapping: tuple[tuple[Any, Any], ...] = ()


@dataclass(frozen=True)
class Parameter:
    """One value of a parameter set (``ssv:Parameter``), with the transformation and unit handling
    a parameter mapping (``ssm:MappingEntry``) gives it."""

    name: str
    type: str  # Real | Integer | Boolean | String (SSP 2.0's Float64, Int32... as given)
    value: Any
    unit: str | None = None
    transform: Transform | None = None
    suppress_unit_conversion: bool = False


@dataclass(frozen=True)
class ParameterSet:
    """A named parameter set, inline in the SSD or from an ``.ssv`` file (``source``)."""

    name: str
    parameters: tuple[Parameter, ...]
    source: str | None = None
    #: The set's own unit definitions (``ssv:Units``): what its values' ``unit`` names.
    units: Mapping[str, Unit] = field(default_factory=dict)


@dataclass(frozen=True)
class SystemBinding:
    """A parameter binding of a system (the top-level one or a nested one): its values address
    variables by hierarchical name (``component.variable``, ``prefix`` already prepended).

    ``system`` is the system's hierarchical name ("" for the top level), ``depth`` its nesting
    level (0 for the top level): a binding of a higher level (smaller depth) wins."""

    system: str
    depth: int
    pset: ParameterSet
    origin: str

    def full_name(self, name: str) -> str:
        """The hierarchical name of ``name`` seen from the top-level system."""
        return f"{self.system}.{name}" if self.system else name


@dataclass(frozen=True)
class ParameterLink:
    """A connection from a system's ``parameter`` or ``input`` connector (hierarchical name
    ``node``) to a component's connector: the value a binding gives the system connector is
    the component variable's start value (the system parameter is set before initialization)."""

    node: str
    component: str
    connector: str
    origin: str
    transform: Transform | None = None


@dataclass(frozen=True)
class Component:
    """A component of the system: an FMU and its SSD connectors and parameter bindings."""

    name: str
    source: str
    fmu: Path | None  # resolved FMU file (None: not found; reported when bound to its FMU)
    connectors: tuple[Connector, ...]
    bindings: tuple[ParameterSet, ...] = ()
    step_size_hint: float | None = None
    #: Nesting level of the component's system (0: the top-level system).
    depth: int = 0
    #: The SSD's ``implementation`` attribute (``any``, ``CoSimulation``, ``ModelExchange``; None: not given).
    implementation: str | None = None

    def connector(self, name: str) -> Connector | None:
        """The connector called ``name``, or None."""
        for c in self.connectors:
            if c.name == name:
                return c
        return None


@dataclass(frozen=True)
class Connection:
    """A connection ``start -> end`` with an optional linear transformation."""

    start_element: str
    start_connector: str
    end_element: str
    end_connector: str
    factor: float = 1.0
    offset: float = 0.0
    suppress_unit_conversion: bool = False
    #: ``LinearTransformation``, ``IntegerMappingTransformation``, ``BooleanMappingTransformation``,
    #: ``EnumerationMappingTransformation`` or None: which SSP transformation the connection declares.
    transformation: str | None = None
    #: The MapEntry pairs (source, target) of a mapping transformation.
    mapping: tuple[tuple[Any, Any], ...] = ()

    @property
    def start(self) -> str:
        return f"{self.start_element}.{self.start_connector}"

    @property
    def end(self) -> str:
        return f"{self.end_element}.{self.end_connector}"


@dataclass(frozen=True)
class Unit:
    """A unit definition: exponents of the SI base units, factor and offset to them."""

    name: str
    exponents: tuple[int, ...]  # in BASE_UNITS order
    factor: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Experiment:
    """The SSD's DefaultExperiment."""

    start_time: float = 0.0
    stop_time: float | None = None
    step_size: float | None = None
    #: Relative tolerance of the solver that integrates model-exchange components (OMSimulator's
    #: ``oms:VariableStepSolver relativeTolerance`` annotation; None: not given).
    relative_tolerance: float | None = None


@dataclass(frozen=True)
class Scenario:
    """An immutable, checked description of one SSP scenario.

    Attributes
    ----------
    name : str
        The system's name (the scenario name for the project's scenarios).
    origin : str
        Where it came from, for messages: the SSD path (``.../SystemStructure.ssd``), or
        ``archive.ssp:SystemStructure.ssd``.
    location : Path
        The scenario folder or the ``.ssp`` archive.
    description : str
        The system's description attribute.
    components : tuple of Component
        In SSD order.
    connections : tuple of Connection
    units : mapping of str to Unit
    experiment : Experiment
    parameter_sets : mapping of str to ParameterSet
        Every ``.ssv`` of the scenario by its set name (``thesis``, ``tuned``...): what
        ``parameter_set=`` can select.
    set_files : mapping of str to str
        Set name -> file name of those ``.ssv`` files.
    version : str
        The SSD's SSP version (``1.0`` or ``2.0``).
    system_bindings, parameter_links, system_connectors
        The system-level parameter bindings, the connections from system connectors to
        components and the system connectors' hierarchical names (nested systems are flattened:
        a component ``C`` of system ``B`` is the component ``B.C``).
    """

    name: str
    origin: str
    location: Path
    description: str
    components: tuple[Component, ...]
    connections: tuple[Connection, ...]
    units: Mapping[str, Unit]
    experiment: Experiment
    parameter_sets: Mapping[str, ParameterSet] = field(default_factory=dict)
    set_files: Mapping[str, str] = field(default_factory=dict)
    #: The SSD's ``version`` (``1.0`` or ``2.0``).
    version: str = "1.0"
    #: Parameter bindings of the top-level system and nested systems, lowest level first.
    system_bindings: tuple[SystemBinding, ...] = ()
    #: Values of system connectors that connections carry to components' connectors.
    parameter_links: tuple[ParameterLink, ...] = ()
    #: Hierarchical names of every system connector (what a system-level binding may address).
    system_connectors: tuple[str, ...] = ()

    def component(self, name: str) -> Component:
        """The component called ``name`` (KeyError naming the known ones otherwise)."""
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(f"{self.origin}: no component {name!r}; {closest(name, (c.name for c in self.components))}")

    @property
    def bound_sets(self) -> tuple[str, ...]:
        """Names of the parameter sets the SSD binds by default (from ``.ssv`` files)."""
        names = []
        for comp in self.components:
            for b in comp.bindings:
                if b.source is not None and b.name not in names:
                    names.append(b.name)
        return tuple(names)



def select_parameter_set(scenario: Scenario, name: str) -> Scenario:
    """The scenario with parameter set ``name`` bound instead of the SSD's default set.

    Every binding of the SSD that references one of the scenario's parameter-set files is
    replaced by ``name``'s file (e.g. ``controller``'s ``tuned.ssv`` by ``thesis.ssv``).

    Raises
    ------
    ScenarioError
        If the scenario has no such set, or binds no parameter-set file to replace.
    """

    if name not in scenario.parameter_sets:
        raise UnknownParameterSetError(f"{scenario.origin}: scenario {scenario.name!r} has no parameter set {name!r}; "
                            f"{closest(name, scenario.parameter_sets)}")
    new_set = scenario.parameter_sets[name]
    files = set(scenario.set_files.values())
    replaced = False
    components = []
    for comp in scenario.components:
        bindings = []
        for b in comp.bindings:
            if b.source in files:
                bindings.append(new_set)
                replaced = True
            else:
                bindings.append(b)
        components.append(replace(comp, bindings=tuple(bindings)))
    if not replaced:
        raise ScenarioError(f"{scenario.origin}: no component binds a parameter-set file, so set {name!r} "
                            f"has nothing to replace")
    return replace(scenario, components=tuple(components))


