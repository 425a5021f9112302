"""What the master runs: a system of FMU instances and the links between them.

These immutable descriptions are the master's input. The scenario room builds them
(:func:`ipcosim.harness.scenario.binding.bind` checks an SSP scenario against its FMUs); the
master never reads an SSD itself, and knows nothing of what the FMUs model.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:  # type-only: a System remembers the scenario it was bound from
    from ipcosim.harness.scenario.structure import Scenario, Unit

#: SSP 1.0 connector type of every FMI 2.0 / 3.0 variable type the master carries.
SSP_TYPE = {"Real": "Real", "Float64": "Real", "Float32": "Real",
            "Integer": "Integer", "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer", "UInt16": "Integer",
            "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer",
            "Enumeration": "Enumeration", "Boolean": "Boolean", "String": "String"}
_VALUE_TYPE = {"Real": "real", "Integer": "integer", "Enumeration": "integer", "Boolean": "boolean", "String": "string"}
#: Which SSP transformation is valid for which connector types (SSP 1.0, ssc:GTransformationChoice).
TRANSFORMATION_TYPES = {"LinearTransformation": ("Real",),
                        "IntegerMappingTransformation": ("Integer", "Enumeration"),
                        "BooleanMappingTransformation": ("Boolean",),
                        "EnumerationMappingTransformation": ("Enumeration",)}
SUPPORTED_CONNECTION_TYPES = tuple(_VALUE_TYPE)


def value_type_of(type_: str) -> str | None:
    """The master's value type (``real``, ``integer``, ``boolean``, ``string``) of an FMU
    variable type; None for a type the master does not carry (Binary, Clock)."""
    return _VALUE_TYPE.get(SSP_TYPE.get(type_, ""))


@dataclass(frozen=True)
class Variable:
    """One FMU variable (what the master needs of a ``ScalarVariable``)."""

    name: str
    vr: int
    type: str  # Real | Integer | Boolean | String | Enumeration
    causality: str = "local"
    variability: str = "continuous"
    initial: str | None = None
    unit: str | None = None
    start: Any = None
    description: str = ""

    @property
    def settable(self) -> bool:
        """Whether a start value may be set before initialization (FMI 2.0 rules)."""
        if self.variability == "constant":
            return False
        if self.causality == "input":
            return True
        return self.causality == "parameter" or self.initial in ("exact", "approx")


@dataclass(frozen=True)
class Model:
    """The interface of one FMU (from its modelDescription.xml).

    Attributes
    ----------
    feedthrough : mapping of str to frozenset of str
        For each output, the inputs it depends on directly (ModelStructure; an output with
        no ``dependencies`` attribute depends on every input, as FMI 2.0 says).
    """

    name: str
    variables: Mapping[str, Variable]
    feedthrough: Mapping[str, frozenset[str]]
    path: Path | None = None
    guid: str = ""
    model_identifier: str = ""
    fmi_version: str = "2.0"
    units: Mapping[str, Unit] = field(default_factory=dict)
    can_handle_variable_step: bool = True
    #: The FMU's DefaultExperiment stepSize and stopTime [s], and tolerance (None when it gives none).
    default_step: float | None = None
    default_stop: float | None = None
    default_tolerance: float | None = None
    #: The items (name -> value) of each Enumeration variable's type, by variable name.
    enumerations: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    #: Whether the FMU offers co-simulation, and its model-exchange model identifier (None: no
    #: model exchange).
    co_simulation: bool = True
    model_exchange_identifier: str | None = None

    def inputs(self) -> list[Variable]:
        return [v for v in self.variables.values() if v.causality == "input"]

    def outputs(self) -> list[Variable]:
        return [v for v in self.variables.values() if v.causality == "output"]


@dataclass(frozen=True)
class Instance:
    """A component bound to its FMU.

    Attributes
    ----------
    connectors : tuple of Variable
        The SSD connectors of the component, as FMU variables, in SSD order.
    parameters : tuple of (Variable, value)
        Start values from the parameter bindings, in the order they are applied.
    swapped_from : str or None
        The original FMU when ``--swap`` replaced this component.
    realtime : bool
        The component asks for real-time pacing (hardware in the loop).
    """

    name: str
    model: Model
    connectors: tuple[Variable, ...]
    parameters: tuple[tuple[Variable, Any], ...] = ()
    step_size_hint: float | None = None
    swapped_from: str | None = None
    realtime: bool = False
    #: The FMU interface the component runs: ``CoSimulation``, or ``ModelExchange`` (integrated
    #: by the master, :mod:`~ipcosim.harness.master.me_slave`) with the solver's relative tolerance.
    interface: str = "CoSimulation"
    tolerance: float | None = None

    @property
    def inputs(self) -> tuple[Variable, ...]:
        return tuple(v for v in self.connectors if v.causality == "input")

    @property
    def outputs(self) -> tuple[Variable, ...]:
        return tuple(v for v in self.connectors if v.causality == "output")

    def start_value(self, name: str) -> Any:
        """The value a variable starts with: the last binding that sets it, else the FMU's start."""
        value = self.model.variables[name].start
        for var, v in self.parameters:
            if var.name == name:
                value = v
        return value


@dataclass(frozen=True)
class Link:
    """A resolved connection: ``dst = factor * src + offset`` (transformation and unit conversion)."""

    src: str
    src_var: Variable
    dst: str
    dst_var: Variable
    factor: float = 1.0
    offset: float = 0.0
    #: (source, target) pairs of an Integer or Boolean mapping transformation (Booleans as 0/1);
    #: values not in the table pass unchanged.
    mapping: tuple[tuple[int, int], ...] = ()

    @property
    def value_type(self) -> str:
        """The value type the link carries (``real``, ``integer``, ``boolean``, ``string``)."""
        return value_type_of(self.src_var.type) or "real"

    @property
    def src_name(self) -> str:
        return f"{self.src}.{self.src_var.name}"

    @property
    def dst_name(self) -> str:
        return f"{self.dst}.{self.dst_var.name}"


@dataclass(frozen=True)
class System:
    """A scenario bound to its FMUs; immutable, ready to be prepared and run."""

    scenario: Scenario
    instances: tuple[Instance, ...]
    links: tuple[Link, ...]
    #: Connections from a calculated parameter into a parameter or input: carried once, in
    #: initialization mode, before the fixed point of the links (SSP 1.0 section 5.3.2.1).
    parameter_links: tuple[Link, ...] = ()
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()  # informational (swaps), not warnings

    def instance(self, name: str) -> Instance:
        for inst in self.instances:
            if inst.name == name:
                return inst
        raise KeyError(name)

    def link_into(self, component: str, variable: str) -> Link | None:
        for link in self.links:
            if link.dst == component and link.dst_var.name == variable:
                return link
        return None

    @property
    def realtime(self) -> bool:
        return any(i.realtime for i in self.instances)
