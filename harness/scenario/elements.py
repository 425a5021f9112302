"""SSP elements read into the scenario's description: values of the SSP types, parameter sets with
their ``prefix`` and parameter mapping, connectors, units, transformations, connections and the
``DefaultExperiment``. What the master does not run (arrays, clocks) is refused here in one line
naming the file, the element and the feature.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Sequence

from lxml import etree

from ipcosim.harness.scenario.errors import ScenarioError
from ipcosim.harness.scenario.files import NS, OSP_ANNOTATION
from ipcosim.harness.scenario.structure import (
    BASE_UNITS,
    Connection,
    Connector,
    Experiment,
    Parameter,
    ParameterSet,
    Transform,
    Unit,
)

# --------------------------------------------------------------------------- parsing
#: SSP value and connector types: 1.0's and those SSP 2.0 adds for FMI 3.0 (sized types).
REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
CONNECTOR_TYPES = REAL_TYPES + INTEGER_TYPES + ("Boolean", "String", "Enumeration", "Binary", "Clock")
#: FMU causalities whose values flow through the run (recorded); parameters are set before it.
SIGNAL_KINDS = ("input", "output", "inout")


def parse_value(type_: str, text: str | None, display: str, name: str) -> Any:
    """A value of an SSV parameter as Python (float, int, bool, str); Enumeration (an item name)
    and Binary (hex) stay text, for the binding to apply or refuse."""
    if text is None:
        raise ScenarioError(f"{display}: parameter {name!r} has no value")
    if type_ in REAL_TYPES + INTEGER_TYPES and len(text.split()) > 1:
        raise ScenarioError(f"{display}: parameter {name!r}: array values ({text!r}) are not supported "
                            f"(SSP 2.0 arrays; the master carries scalars)")
    try:
        if type_ in REAL_TYPES:
            return float(text)
        if type_ in INTEGER_TYPES:
            return int(text)
        if type_ == "Boolean":
            if text.strip() in ("true", "1"):
                return True
            if text.strip() in ("false", "0"):
                return False
            raise ValueError(text)
    except ValueError:
        raise ScenarioError(f"{display}: parameter {name!r}: {text!r} is not a valid {type_}") from None
    return text


def parse_parameter_set(element: etree._Element, display: str, source: str | None,
                   mapping: Sequence[tuple[str, str, Transform | None, bool]] | None = None,
                   prefix: str = "") -> ParameterSet:
    """Immutable copy of an ``ssv:ParameterSet`` with its unit definitions: ``prefix`` prepended to
    every name, then a parameter mapping (``mapping``: source name, target name, transformation,
    suppressUnitConversion) renames and selects its values (only mapped values are applied), as
    SSP 1.0 section 5.2.3 orders them."""
    params = []
    for xml in element.findall("ssv:Parameters/ssv:Parameter", NS):
        name = xml.get("name")
        value = next((c for c in xml if isinstance(c.tag, str) and etree.QName(c).namespace == NS["ssv"]), None)
        if value is None:
            raise ScenarioError(f"{display}:{xml.sourceline}: parameter {name!r} has no value element")
        type_ = etree.QName(value).localname
        text = value.get("value")
        params.append(Parameter(name, type_, parse_value(type_, text, f"{display}:{xml.sourceline}", name),
                                value.get("unit") if type_ in REAL_TYPES else None))
    if prefix:  # "prepended to all names in the parameter source prior to ... name mapping"
        params = [replace(p, name=prefix + p.name) for p in params]
    if mapping is not None:
        by_name = {p.name: p for p in params}
        params = [replace(by_name[src], name=target, transform=transform, suppress_unit_conversion=suppress)
                  for src, target, transform, suppress in mapping if src in by_name]
    units = {u.get("name"): parse_unit(u) for u in element.findall("ssv:Units/ssc:Unit", NS)}
    return ParameterSet(name=element.get("name") or "", parameters=tuple(params), source=source, units=units)


def parse_connector(xml: etree._Element, display: str) -> Connector:
    """One ``ssd:Connector``: kind, SSP type, unit; SSP 2.0's arrays and clocks are refused by name."""
    name = xml.get("name")
    type_, unit = None, None
    for t in CONNECTOR_TYPES:
        el = xml.find(f"ssc:{t}", NS)
        if el is not None:
            type_ = t
            unit = el.get("unit") if t in REAL_TYPES else None
            break
    if xml.find("ssc:Dimension", NS) is not None:
        raise ScenarioError(f"{display}:{xml.sourceline}: connector {name!r} is an array (ssc:Dimension); array "
                            f"connectors (SSP 2.0) are not supported")
    if type_ == "Clock" or xml.find("ssd:Clock", NS) is not None:
        raise ScenarioError(f"{display}:{xml.sourceline}: connector {name!r} is a clock or clocked (ssc:Clock); "
                            f"clocks (SSP 2.0) are not supported")
    return Connector(name=name, kind=xml.get("kind"), type=type_, unit=unit)


def parse_unit(xml: etree._Element) -> Unit:
    base = xml.find("ssc:BaseUnit", NS)
    attrs = dict(base.attrib) if base is not None else {}
    return Unit(name=xml.get("name"), exponents=tuple(int(attrs.get(k, 0)) for k in BASE_UNITS),
                factor=float(attrs.get("factor", 1.0)), offset=float(attrs.get("offset", 0.0)))


def osp_annotation(parent: etree._Element) -> etree._Element | None:
    for ann in parent.findall("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") == OSP_ANNOTATION:
            return ann
    return None



def parse_transform(xml: etree._Element, line: str) -> Transform | None:
    """The transformation of a connection or mapping entry (``ssc:GTransformationChoice``), or None."""
    lt = xml.find("ssc:LinearTransformation", NS)
    if lt is not None:
        factor, offset = float(lt.get("factor", 1.0)), float(lt.get("offset", 0.0))
        if not (math.isfinite(factor) and math.isfinite(offset)):
            raise ScenarioError(f"{line}: linear transformation factor/offset must be finite")
        return Transform("LinearTransformation", factor, offset)
    for other in ("IntegerMappingTransformation", "BooleanMappingTransformation"):
        mt = xml.find(f"ssc:{other}", NS)
        if mt is not None:
            return Transform(other, mapping=_map_entries(mt, other, line))
    em = xml.find("ssc:EnumerationMappingTransformation", NS)
    if em is not None:  # item names, resolved against the FMUs' enumeration types when bound
        entries = tuple((e.get("source"), e.get("target")) for e in em.findall("ssc:MapEntry", NS))
        if len({a for a, _ in entries}) != len(entries):
            raise ScenarioError(f"{line}: ssc:EnumerationMappingTransformation maps a source item twice")
        return Transform("EnumerationMappingTransformation", mapping=entries)
    return None


def parse_connection(cxml: etree._Element, line: str, se: str, sc: str, ee: str, ec: str) -> Connection:
    """One connection between components' connectors (source first), with its transformation
    (linear, or an integer or boolean mapping) and ``suppressUnitConversion``."""
    t = parse_transform(cxml, line)
    suppress = cxml.get("suppressUnitConversion", "false") in ("true", "1")
    if t is None:
        return Connection(se, sc, ee, ec, suppress_unit_conversion=suppress)
    return Connection(se, sc, ee, ec, t.factor, t.offset, suppress, t.type, t.mapping)


def parse_experiment(root: etree._Element, ssd_display: str) -> Experiment:
    """The SSD's ``DefaultExperiment``: start and stop time, and the step of an
    ``osp:FixedStepAlgorithm`` annotation (None where not given)."""
    start, stop, step = 0.0, None, None
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        start = float(exp.get("startTime", 0.0))
        stop = float(exp.get("stopTime")) if exp.get("stopTime") is not None else None
        ann = osp_annotation(exp)
        if ann is not None:
            alg = ann.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
            if alg is not None:
                step = parse_positive(alg.get("baseStepSize"),
                                 f"{ssd_display}:{alg.sourceline}: osp:FixedStepAlgorithm baseStepSize")
        if stop is not None and not stop > start:
            raise ScenarioError(f"{ssd_display}:{exp.sourceline}: DefaultExperiment stopTime {stop:g} s must be "
                                f"after startTime {start:g} s")
    return Experiment(start, stop, step, _relative_tolerance(root, ssd_display))


def _relative_tolerance(root: etree._Element, ssd_display: str) -> float | None:
    """The ``relativeTolerance`` of an OMSimulator ``VariableStepSolver`` annotation (type
    ``org.openmodelica``) of the top-level system or of the DefaultExperiment, or None."""
    for parent in (root.find("ssd:System", NS), root.find("ssd:DefaultExperiment", NS)):
        if parent is None:
            continue
        for ann in parent.findall("ssd:Annotations/ssc:Annotation", NS):
            if ann.get("type") != "org.openmodelica":
                continue
            for solver in ann.iter("{*}VariableStepSolver"):
                if solver.get("relativeTolerance") is not None:
                    return parse_positive(solver.get("relativeTolerance"),
                                          f"{ssd_display}:{solver.sourceline}: VariableStepSolver relativeTolerance")
    return None


def _map_entries(xml: etree._Element, type_: str, line: str) -> tuple[tuple[Any, Any], ...]:
    """The (source, target) pairs of a mapping transformation (Boolean values as 0/1)."""
    def value(text: str | None) -> int:
        if type_ == "BooleanMappingTransformation":
            return 1 if text in ("true", "1") else 0
        return int(text)  # schema-validated xs:int

    entries = tuple((value(e.get("source")), value(e.get("target"))) for e in xml.findall("ssc:MapEntry", NS))
    sources = [a for a, _ in entries]
    if len(set(sources)) != len(sources):
        raise ScenarioError(f"{line}: ssc:{type_} maps a source value twice")
    return entries


def parse_positive(text: str | None, what: str) -> float:
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ScenarioError(f"{what} {text!r} is not a number") from None
    if not (value > 0 and math.isfinite(value)):
        raise ScenarioError(f"{what} {value:g} must be positive")
    return value


