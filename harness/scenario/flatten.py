"""Nested systems flattened into one level (:class:`Flattener`): hierarchical component names,
connections through system connectors and signal dictionaries joined end to end, system-level
parameter bindings kept with their level, and the links from system connectors to components.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

from lxml import etree

from ipcosim.harness.scenario.elements import (
    osp_annotation,
    parse_connection,
    parse_connector,
    parse_parameter_set,
    parse_positive,
    parse_transform,
)
from ipcosim.harness.scenario.errors import ScenarioError
from ipcosim.harness.scenario.files import NS, ScenarioFiles, parse_xml
from ipcosim.harness.scenario.locations import resolve_fmu
from ipcosim.harness.scenario.structure import (
    Component,
    Connection,
    Connector,
    ParameterLink,
    ParameterSet,
    SystemBinding,
    Transform,
)


class Flattener:
    """Nested systems flattened into one level: a component ``C`` of a system ``B`` becomes the
    component ``B.C`` (its hierarchical name); system connectors and the signals of a signal
    dictionary become junctions that a connection through them joins end to end; system-level
    parameter bindings are kept with their system's name and level; connections from a system's
    parameter or input connector become :class:`ParameterLink` s."""

    def __init__(self, src: ScenarioFiles, set_elements: Mapping[str, etree._Element], fmu_dirs: Sequence[Path],
                 display: str) -> None:
        self.src, self.set_elements, self.fmu_dirs, self.display = src, set_elements, fmu_dirs, display
        self.components: list[Component] = []
        self.system_bindings: list[SystemBinding] = []
        self.system_connectors: list[str] = []
        self.parameter_links: list[ParameterLink] = []
        #: node -> (owner "system" | "component" | "signal", path, connector)
        self.nodes: dict[str, tuple[str, str, Connector]] = {}
        self.edges: list[tuple[str, str, etree._Element, str, str]] = []  # (node a, node b, xml, line, system)
        self.aliases: dict[str, str] = {}  # a signal dictionary reference's connector -> its signal's node
        self.dictionaries: list[dict[str, tuple[str, dict[str, Connector]]]] = []  # per enclosing system

    def where(self, xml: etree._Element) -> str:
        return f"{self.display}:{xml.sourceline}"

    def system(self, xml: etree._Element, path: str, depth: int) -> None:
        """Read system ``xml`` (hierarchical name ``path``) and, recursively, its sub-systems."""
        self.dictionaries.append({d.get("name"): (f"#{path}/{d.get('name')}", self.dictionary(d))
                                  for d in xml.findall("ssd:SignalDictionaries/ssd:SignalDictionary", NS)})
        for c in xml.findall("ssd:Connectors/ssd:Connector", NS):
            conn = parse_connector(c, self.display)
            node = f"{path}.{conn.name}" if path else conn.name
            self.nodes[node] = ("system", path, conn)
            self.system_connectors.append(node)
        for pset in self.bindings(xml, self.display):
            self.system_bindings.append(SystemBinding(path, depth, pset, self.where(xml)))
        seen: set[str] = set()
        for el in xml.findall("ssd:Elements/*", NS):
            tag = etree.QName(el).localname
            name = el.get("name")
            if name in seen:
                what = "component" if tag == "Component" else "element"
                raise ScenarioError(f"{self.where(el)}: duplicate {what} name {name!r}")
            seen.add(name)
            full = f"{path}.{name}" if path else name
            if tag == "System":
                self.system(el, full, depth + 1)
            elif tag == "Component":
                self.component(el, full, depth)
            else:
                self.reference(el, full)
        for cxml in xml.findall("ssd:Connections/ssd:Connection", NS):
            ends = []
            for side in ("start", "end"):
                element, connector = cxml.get(f"{side}Element") or "", cxml.get(f"{side}Connector")
                if cxml.get(f"{side}Indices") is not None:
                    raise ScenarioError(f"{self.where(cxml)}: connection with {side}Indices: array connections "
                                        f"(SSP 2.0) are not supported")
                scope = f"{path}.{element}" if (path and element) else (element or path)
                node = f"{scope}.{connector}" if scope else connector
                node = self.aliases.get(node, node)
                if node not in self.nodes:
                    owner = f"component {element!r}" if element else f"system {xml.get('name')!r}"
                    if element and element not in seen:
                        raise ScenarioError(f"{self.where(cxml)}: connection names component {element!r}, which "
                                            f"the system does not have")
                    raise ScenarioError(f"{self.where(cxml)}: connection names {element + '.' if element else ''}"
                                        f"{connector}, but {owner} declares no connector {connector!r}")
                ends.append(node)
            self.edges.append((ends[0], ends[1], cxml, self.where(cxml), path))
        self.dictionaries.pop()

    def dictionary(self, xml: etree._Element) -> dict[str, Connector]:
        """The entries of an ``ssd:SignalDictionary`` (inline ``ssb:SignalDictionary`` or an ``.ssb`` file,
        validated) as connectors by name."""
        source = xml.get("source")
        if source is not None:
            root = parse_xml(self.src.read(source), self.src.display(source), "SystemStructureSignalDictionary.xsd")
        else:
            root = xml.find("ssb:SignalDictionary", NS)
        entries = {}
        for e in (root.findall("ssb:DictionaryEntry", NS) if root is not None else ()):
            c = parse_connector(e, self.display)
            entries[e.get("name")] = Connector(e.get("name"), "inout", c.type, c.unit)
        return entries

    def reference(self, xml: etree._Element, full: str) -> None:
        """A signal dictionary reference: each of its connectors stands for its dictionary's signal of
        that name, one node for every reference to the dictionary (SSP 5.5: looked up from the
        innermost system outwards)."""
        name = xml.get("dictionary")
        found = next((d[name] for d in reversed(self.dictionaries) if name in d), None)
        if found is None:
            raise ScenarioError(f"{self.where(xml)}: ssd:SignalDictionaryReference {full!r} references signal "
                                f"dictionary {name!r}, which no enclosing system defines")
        key, entries = found
        for c in xml.findall("ssd:Connectors/ssd:Connector", NS):
            conn = parse_connector(c, self.display)
            if conn.name not in entries:
                raise ScenarioError(f"{self.where(c)}: ssd:SignalDictionaryReference {full!r}: connector "
                                    f"{conn.name!r} is not an entry of signal dictionary {name!r}")
            node = f"{key}.{conn.name}"
            self.nodes[node] = ("signal", key, entries[conn.name])
            self.aliases[f"{full}.{conn.name}"] = node
            self.nodes[f"{full}.{conn.name}"] = self.nodes[node]

    def bindings(self, xml: etree._Element, display: str) -> list[ParameterSet]:
        """The parameter sets of an element's ``ssd:ParameterBindings`` in element order (files and
        inline), each mapped by its ``ssd:ParameterMapping`` and prefixed by its ``prefix``."""
        out = []
        for bxml in xml.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            mapping = self.mapping(bxml)
            prefix = bxml.get("prefix") or ""
            source = bxml.get("source")
            if source is not None:
                out.append(parse_parameter_set(self.set_elements[source], self.src.display(source), source, mapping,
                                               prefix))
            for inline in bxml.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
                out.append(parse_parameter_set(inline, display, None, mapping, prefix))
        return out

    def mapping(self, bxml: etree._Element) -> list[tuple[str, str, Transform | None, bool]] | None:
        """A binding's parameter mapping (``.ssm`` file or inline ``ssm:ParameterMapping``), or None."""
        mxml = bxml.find("ssd:ParameterMapping", NS)
        if mxml is None:
            return None
        source = mxml.get("source")
        root = self.set_elements[source] if source is not None else mxml.find("ssm:ParameterMapping", NS)
        display = self.src.display(source) if source is not None else self.display
        if root is None:
            return []
        entries = []
        targets: set[str] = set()
        for e in root.findall("ssm:MappingEntry", NS):
            line = f"{display}:{e.sourceline}"
            if e.get("target") in targets:
                raise ScenarioError(f"{line}: ssm:MappingEntry maps a second parameter to {e.get('target')!r} "
                                    f"(SSP: implementations must not map multiple parameters to the same name)")
            targets.add(e.get("target"))
            suppress = e.get("suppressUnitConversion", "false") in ("true", "1")
            entries.append((e.get("source"), e.get("target"), parse_transform(e, line), suppress))
        return entries

    def component(self, xml: etree._Element, full: str, depth: int) -> None:
        """One component under its hierarchical name, with its connectors, parameter bindings and
        ``osp:StepSizeHint``, and its FMU file resolved."""
        where = self.where(xml)
        type_ = xml.get("type") or "application/x-fmu-sharedlibrary"
        source = xml.get("source")
        if type_ != "application/x-fmu-sharedlibrary" or (source or "").lower().split("#")[0].endswith((".ssp",
                                                                                                         ".ssd")):
            raise ScenarioError(f"{where}: component {full!r} (type {type_!r}, source {source!r}): an SSP or SSD used "
                                f"as a component is not supported (FMU components only)")
        if source is None:
            raise ScenarioError(f"{where}: component {full!r} has no source (SSP 2.0: no implementation); a "
                                f"component without an FMU cannot run")
        if source.startswith("#"):
            raise ScenarioError(f"{where}: component {full!r} references system {source!r} of this SSD; systems "
                                f"instantiated by reference are not supported")
        if xml.get("implementation") not in (None, "any", "CoSimulation", "ModelExchange"):
            raise ScenarioError(f"{where}: component {full!r} asks for implementation={xml.get('implementation')!r}; "
                                f"expected any, CoSimulation or ModelExchange")
        connectors = tuple(parse_connector(c, self.display) for c in xml.findall("ssd:Connectors/ssd:Connector", NS))
        names = [c.name for c in connectors]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ScenarioError(f"{where}: component {full!r} declares connector {sorted(dup)[0]!r} twice")
        for c in connectors:
            self.nodes[f"{full}.{c.name}"] = ("component", full, c)
        hint = None
        ann = osp_annotation(xml)
        if ann is not None:
            h = ann.find("osp:StepSizeHint", NS)
            if h is not None:
                hint = parse_positive(h.get("value"), f"{self.display}:{h.sourceline}: osp:StepSizeHint value")
        self.components.append(Component(name=full, source=source, fmu=resolve_fmu(source, self.src, self.fmu_dirs),
                                         connectors=connectors, bindings=tuple(self.bindings(xml, self.display)),
                                         step_size_hint=hint, depth=depth,
                                         implementation=xml.get("implementation")))

    # ------------------------------------------------------------------ connections
    def _role(self, node: str, other: str, scope: str, line: str) -> str:
        """``source`` or ``destination``: which way data flows through ``node`` on an edge to
        ``other`` declared in system ``scope`` (SSP's table of allowed connections: a system's own
        input or parameter connector is a source inside it, a destination seen from its parent; an
        element's is a destination; an inout, unspecified or signal dictionary connector takes the
        direction the other end gives)."""
        owner, path, conn = self.nodes[node]
        kind = conn.kind
        if kind in ("inout", "unspecified"):
            if self.nodes[other][2].kind in ("inout", "unspecified"):
                raise ScenarioError(f"{line}: connection {node} -> {other}: neither end gives the direction "
                                    f"(kinds {kind} and {self.nodes[other][2].kind})")
            return "destination" if self._role(other, node, scope, line) == "source" else "source"
        feeding = kind in ("input", "parameter", "structuralParameter")
        inside = owner == "system" and path == scope
        return ("source" if feeding else "destination") if inside else ("destination" if feeding else "source")

    def connections(self) -> list[Connection]:
        """The component-to-component connections, with chains through system connectors joined
        (at most one transformation on a chain), and the parameter links."""
        feeds: dict[str, tuple[str, etree._Element, str]] = {}  # destination node -> (source node, xml, line)
        for a, b, xml, line, scope in self.edges:
            ra, rb = self._role(a, b, scope, line), self._role(b, a, scope, line)
            if ra == rb:
                ka, kb = self.nodes[a][2].kind, self.nodes[b][2].kind
                if ka == kb and ka in ("input", "output"):
                    raise ScenarioError(f"{line}: connection {a} -> {b} connects two {ka}s; a connection must "
                                        f"join one output to one input")
                raise ScenarioError(f"{line}: connection {a} -> {b} joins two {ra}s of data (kinds {ka} and "
                                    f"{kb}); SSP's table of allowed connections has no such pair")
            src, dst = (a, b) if ra == "source" else (b, a)
            if dst in feeds:
                raise ScenarioError(f"{line}: {dst} is fed twice (from {feeds[dst][0]} and {src})")
            feeds[dst] = (src, xml, line)
        out = []
        for dst, (src, xml, line) in feeds.items():
            if self.nodes[dst][0] != "component":
                continue
            chain = [(src, xml, line)]
            while self.nodes[chain[-1][0]][0] in ("system", "signal") and chain[-1][0] in feeds:
                if len(chain) > len(feeds):
                    raise ScenarioError(f"{line}: the connections into {dst} loop through system connectors "
                                        f"({' <- '.join(n for n, _, _ in chain[:4])} ...)")
                chain.append(feeds[chain[-1][0]])
            origin, first_line = chain[-1][0], chain[-1][2]
            owner, path, conn = self.nodes[dst]
            transforms = [x for _, x, _ in chain if parse_transform(x, line) is not None]
            if len(transforms) > 1:
                raise ScenarioError(f"{line}: the connection to {dst} passes {len(transforms)} transformations "
                                    f"through system connectors; at most one per chain is supported")
            cxml = transforms[0] if transforms else xml
            if self.nodes[origin][0] == "signal":
                continue  # a signal nothing writes: the input stays unconnected (bind warns)
            if self.nodes[origin][0] == "system":
                if len(chain) > 1 and transforms and any(self.nodes[n][2].unit for n, _, _ in chain[:-1]):
                    raise ScenarioError(f"{line}: a transformed connection through system connectors with units")
                self.parameter_links.append(ParameterLink(origin, path, conn.name, first_line,
                                                          parse_transform(cxml, line)))
                continue
            if any(self.nodes[n][2].unit for n, _, _ in chain[:-1]) and transforms:
                raise ScenarioError(f"{line}: a transformed connection through system connectors that declare "
                                    f"units is not supported (give the units at the components)")
            o_owner, o_path, o_conn = self.nodes[origin]
            out.append(parse_connection(cxml, line, o_path, o_conn.name, path, conn.name))
        return out


