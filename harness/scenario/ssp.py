"""Loading SSP scenarios: ``SystemStructure.ssd`` and ``.ssv`` parameter sets, from a scenario
folder or an ``.ssp`` archive, into an immutable :class:`Scenario`.

Parse first, then run: this module only reads and checks files; nothing is instantiated. Every
file is validated against the schema of the SSP version it declares (1.0: FMPy's copy of the
standard's XSD files; 2.0: the copy in ``schema/ssp2``), naming the file and line of a problem;
folders are read as well as archives. It reads connector kinds, types and units, the
transformations of connections and ``suppressUnitConversion``, unit definitions, the
``DefaultExperiment`` (start, stop and the OSP ``FixedStepAlgorithm`` step used by libcosim),
component step-size hints, parameter bindings at every level (inline, ``.ssv``, ``prefix``,
parameter mappings from ``.ssm`` or inline) and the scenario's named parameter sets. Nested
systems are flattened into hierarchical component names, and connections through system connectors
and signal dictionaries joined end to end. What the master does not run (an SSP as a component,
arrays, clocks...) is refused here in one line naming the file, the element and the feature.

Scenario names resolve to ``ssp/<name>/`` of the project (the committed sources); FMUs that a
folder's SSD references as ``resources/<Model>.fmu`` are looked up in the folder's
``resources/`` first, then in the directories of ``IPCOSIM_FMU_PATH`` and ``build/fmus/``.
"""
from __future__ import annotations

import math
import os
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePosixPath
from typing import Any, Mapping, Sequence
from xml.sax.saxutils import quoteattr

from lxml import etree

from ipcosim.errors import closest
from ipcosim.harness.paths import BUILD_FMU_DIR, SCENARIO_DIR
from ipcosim.harness.scenario.errors import ScenarioError, ScenarioNotFoundError, UnknownParameterSetError

#: XML namespaces of SSP 1.0 (as in fmpy.ssp.ssd) plus the OSP annotations libcosim reads.
NS = {
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
#: Annotation type under which libcosim reads its algorithm and step-size hints.
OSP_ANNOTATION = "com.opensimulationplatform"
SSD_NAME = "SystemStructure.ssd"
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


# --------------------------------------------------------------------------- sources
class _Source:
    """Files of a scenario: a folder or a zip archive, addressed by archive-style paths."""

    def __init__(self, location: Path) -> None:
        self.location = location
        self.is_archive = location.is_file()
        self._zip: zipfile.ZipFile | None = None
        if self.is_archive:
            try:
                self._zip = zipfile.ZipFile(location)
            except (zipfile.BadZipFile, OSError) as exc:
                raise ScenarioError(f"{_display(location)}: not an SSP archive (not a zip file: {exc})") from None

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()

    def display(self, name: str) -> str:
        if self.is_archive:
            return f"{_display(self.location)}:{name}"
        return _display(self.location / name)

    def exists(self, name: str) -> bool:
        if self._zip is not None:
            return name in self._zip.namelist()
        return (self.location / name).is_file()

    def read(self, name: str) -> bytes:
        if self._zip is not None:
            try:
                return self._zip.read(name)
            except KeyError:
                raise ScenarioError(f"{self.display(name)}: no such file in the archive") from None
        try:
            return (self.location / name).read_bytes()
        except OSError as exc:
            raise ScenarioError(f"{self.display(name)}: cannot read ({exc.strerror})") from None

    def top_level(self, suffix: str) -> list[str]:
        if self._zip is not None:
            return sorted(n for n in self._zip.namelist() if "/" not in n and n.endswith(suffix))
        return sorted(p.name for p in self.location.iterdir() if p.is_file() and p.name.endswith(suffix))


def _display(path: Path) -> str:
    """A path as short as possible for messages (relative to the working directory)."""
    try:
        return os.path.relpath(path)
    except ValueError:
        return str(path)


# --------------------------------------------------------------------------- validation
_SCHEMAS: dict[str, etree.XMLSchema] = {}


def _schema(file_name: str, version: str = "1.0") -> etree.XMLSchema:
    """The standard's XSD ``file_name`` of SSP ``version``: 1.0 from FMPy's copy, 2.0 from the copy
    this package ships (``schema/ssp2``, the Modelica Association's files of release 2.0)."""
    key = f"{version}/{file_name}"
    if key not in _SCHEMAS:
        if version == "2.0":
            folder = Path(__file__).parent / "schema" / "ssp2"
        else:
            import fmpy.ssp.ssd as fssd

            folder = Path(fssd.__file__).parent / "schema"
        _SCHEMAS[key] = etree.XMLSchema(file=str(folder / file_name))
    return _SCHEMAS[key]


def ssp_version(root: etree._Element) -> str:
    """The SSP version a document declares: ``2.0`` for 2.x, else ``1.0`` (validated by that schema)."""
    return "2.0" if (root.get("version") or "").startswith("2.") else "1.0"


def parse_xml(data: bytes, display: str, schema_file: str) -> etree._Element:
    """Parse and schema-validate an SSP XML file against the schema of the SSP version it declares
    (1.0 or 2.0); one-line ScenarioError naming file and line.

    Parameters
    ----------
    data : bytes
        The file's content.
    display : str
        File name used in messages.
    schema_file : str
        ``SystemStructureDescription.xsd``, ``SystemStructureParameterValues.xsd`` or
        ``SystemStructureParameterMapping.xsd``.
    """
    try:
        root = etree.fromstring(data)
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"{display}: not well-formed XML: {exc}") from None
    version = ssp_version(root)
    schema = _schema(schema_file, version)
    if not schema.validate(root):
        err = schema.error_log[0]
        message = err.message
        for prefix in ("ssd", "ssc", "ssv", "ssm", "ssb"):
            message = message.replace("{" + NS[prefix] + "}", f"{prefix}:")
        more = f" (and {len(schema.error_log) - 1} more)" if len(schema.error_log) > 1 else ""
        raise ScenarioError(f"{display}:{err.line}: fails the SSP {version} schema: {message}{more}")
    return root


# --------------------------------------------------------------------------- resolution
def scenario_names(root: Path = SCENARIO_DIR) -> list[str]:
    """Names of the project's scenarios (folders of ``ssp/`` holding a SystemStructure.ssd)."""
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / SSD_NAME).is_file())


def resolve_location(scenario_or_path: str | os.PathLike[str]) -> Path:
    """The scenario folder or ``.ssp`` archive that a scenario name or path refers to.

    A path (anything with a separator, an ``.ssp``/``.ssd`` suffix, or an existing file or
    folder) is taken as is; a bare name is looked up in the project's ``ssp/`` folder.

    Raises
    ------
    ScenarioNotFoundError
        Naming what was looked for, and the known scenarios.
    """
    text = os.fspath(scenario_or_path)
    path = Path(text)
    looks_like_path = (os.sep in text or "/" in text or path.suffix in (".ssp", ".ssd") or path.exists())
    if looks_like_path:
        if path.is_file() and path.suffix == ".ssd":
            return path.parent
        if path.exists():
            if path.is_dir() and not (path / SSD_NAME).is_file():
                raise ScenarioNotFoundError(f"{text}: folder has no {SSD_NAME}")
            return path
        raise ScenarioNotFoundError(f"scenario path {text!r} does not exist")
    candidate = SCENARIO_DIR / text
    if (candidate / SSD_NAME).is_file():
        return candidate
    raise ScenarioNotFoundError(f"unknown scenario {text!r}; {closest(text, scenario_names(), listing=20)} "
                                f"(`ipcosim list` describes them)")


def fmu_search_path(extra: Sequence[str | os.PathLike[str]] | None = None) -> list[Path]:
    """Directories searched for an FMU a folder scenario does not carry itself: ``extra``, then
    ``IPCOSIM_FMU_PATH`` (os.pathsep-separated), then ``build/fmus`` and ``build/fmus-clocked``."""
    dirs = [Path(d) for d in (extra or [])]
    env = os.environ.get("IPCOSIM_FMU_PATH", "")
    dirs += [Path(d) for d in env.split(os.pathsep) if d]
    dirs.append(BUILD_FMU_DIR)
    dirs.append(BUILD_FMU_DIR.parent / "fmus-clocked")  # the clocked controllers (`ipcosim build --native --fmi 3`)
    return dirs


def _resolve_fmu(source: str, src: _Source, fmu_dirs: Sequence[Path]) -> Path | None:
    """File of a component's FMU, or None if it cannot be found."""
    if source.startswith("file:"):
        from urllib.parse import unquote, urlparse

        p = Path(unquote(urlparse(source).path))
        return p if p.is_file() else None
    rel = PurePosixPath(source)
    if src.is_archive:
        return None  # archive members are extracted on preparation (see ipcosim.prepare)
    direct = src.location / Path(*rel.parts)
    if direct.is_file():
        return direct.resolve()
    for d in fmu_dirs:
        cand = d / rel.name
        if cand.is_file():
            return cand.resolve()
    return None


# --------------------------------------------------------------------------- parsing
#: SSP value and connector types: 1.0's and those SSP 2.0 adds for FMI 3.0 (sized types).
REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
CONNECTOR_TYPES = REAL_TYPES + INTEGER_TYPES + ("Boolean", "String", "Enumeration", "Binary", "Clock")
#: FMU causalities whose values flow through the run (recorded); parameters are set before it.
SIGNAL_KINDS = ("input", "output", "inout")


def _parse_value(type_: str, text: str | None, display: str, name: str) -> Any:
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


def _parameter_set(element: etree._Element, display: str, source: str | None,
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
        params.append(Parameter(name, type_, _parse_value(type_, text, f"{display}:{xml.sourceline}", name),
                                value.get("unit") if type_ in REAL_TYPES else None))
    if prefix:  # "prepended to all names in the parameter source prior to ... name mapping"
        params = [replace(p, name=prefix + p.name) for p in params]
    if mapping is not None:
        by_name = {p.name: p for p in params}
        params = [replace(by_name[src], name=target, transform=transform, suppress_unit_conversion=suppress)
                  for src, target, transform, suppress in mapping if src in by_name]
    units = {u.get("name"): _unit(u) for u in element.findall("ssv:Units/ssc:Unit", NS)}
    return ParameterSet(name=element.get("name") or "", parameters=tuple(params), source=source, units=units)


def _connector(xml: etree._Element, display: str) -> Connector:
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


def _unit(xml: etree._Element) -> Unit:
    base = xml.find("ssc:BaseUnit", NS)
    attrs = dict(base.attrib) if base is not None else {}
    return Unit(name=xml.get("name"), exponents=tuple(int(attrs.get(k, 0)) for k in BASE_UNITS),
                factor=float(attrs.get("factor", 1.0)), offset=float(attrs.get("offset", 0.0)))


def _osp_annotation(parent: etree._Element) -> etree._Element | None:
    for ann in parent.findall("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") == OSP_ANNOTATION:
            return ann
    return None


def load_scenario(scenario_or_path: str | os.PathLike[str],
                  fmu_dirs: Sequence[str | os.PathLike[str]] | None = None) -> Scenario:
    """Read, validate and check an SSP scenario; nothing is instantiated.

    Parameters
    ----------
    scenario_or_path : str or path
        A scenario name (``single-mass-lqr``), a scenario folder, its ``SystemStructure.ssd``,
        or an ``.ssp`` archive.
    fmu_dirs : sequence of path, optional
        Extra directories to look for FMUs in (see :func:`fmu_search_path`).

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioNotFoundError
        The name or path does not exist.
    ScenarioError
        Not a zip, no SystemStructure.ssd, not well-formed, fails the schema of its SSP version
        (1.0 or 2.0), an unreadable parameter file or mapping, a connection naming an undeclared
        element or connector, duplicate names, an input connected twice, a transformation on a
        non-Real connection, or a feature the master does not run (named with file and line).
    """
    location = resolve_location(scenario_or_path)
    src = _Source(location)
    try:
        return _load(src, [Path(d) for d in fmu_search_path(fmu_dirs)])
    finally:
        src.close()


def _load(src: _Source, fmu_dirs: Sequence[Path]) -> Scenario:
    """Parse a scenario: the SSD (schema-validated against its version), its parameter files and
    mappings, then the system, flattened (see :class:`_Flattener`), and the default experiment."""
    if not src.exists(SSD_NAME):
        where = _display(src.location)
        container = "archive" if src.is_archive else "folder"
        raise ScenarioError(f"{where}: no {SSD_NAME} at the top level of the {container}")
    ssd_display = src.display(SSD_NAME)
    root = parse_xml(src.read(SSD_NAME), ssd_display, "SystemStructureDescription.xsd")
    ssv_files = src.top_level(".ssv")
    set_elements = _parameter_files(src, root, ssv_files, ssd_display)
    system_xml = root.find("ssd:System", NS)
    flat = _Flattener(src, set_elements, fmu_dirs, ssd_display)
    flat.system(system_xml, "", 0)
    connections = flat.connections()
    units = {u.get("name"): _unit(u) for u in root.findall("ssd:Units/ssc:Unit", NS)}
    experiment = _experiment(root, ssd_display)
    sets = {}
    set_files = {}
    for fname in ssv_files:
        pset = _parameter_set(set_elements[fname], src.display(fname), fname)
        key = pset.name or PurePosixPath(fname).stem
        sets[key] = pset
        set_files[key] = fname
    return Scenario(name=system_xml.get("name"), origin=ssd_display, location=src.location,
                    description=system_xml.get("description") or "", components=tuple(flat.components),
                    connections=tuple(connections), units=units, experiment=experiment,
                    parameter_sets=sets, set_files=set_files, version=ssp_version(root),
                    system_bindings=tuple(sorted(flat.system_bindings, key=lambda b: -b.depth)),
                    parameter_links=tuple(flat.parameter_links), system_connectors=tuple(flat.system_connectors))


def _parameter_files(src: _Source, root: etree._Element, ssv_files: Sequence[str],
                     ssd_display: str) -> dict[str, etree._Element]:
    """Every parameter and mapping file of the scenario, validated, by its path: the top-level
    ``.ssv`` files (the selectable parameter sets) and those parameter bindings and parameter
    mappings name in sub-folders."""
    set_elements: dict[str, etree._Element] = {}
    for name in ssv_files:
        set_elements[name] = parse_xml(src.read(name), src.display(name), "SystemStructureParameterValues.xsd")
    for tag, schema in (("ParameterBinding", "SystemStructureParameterValues.xsd"),
                        ("ParameterMapping", "SystemStructureParameterMapping.xsd")):
        for b in root.iter(f"{{{NS['ssd']}}}{tag}"):
            source = b.get("source")
            if b.get("sourceBase") == "component":
                raise ScenarioError(f"{ssd_display}:{b.sourceline}: ssd:{tag} sourceBase=\"component\" (a file "
                                    f"inside the component's FMU) is not supported")
            if b.get("type") not in (None, "application/x-ssp-parameter-set", "application/x-ssp-parameter-mapping"):
                raise ScenarioError(f"{ssd_display}:{b.sourceline}: ssd:{tag} of type {b.get('type')!r} is not "
                                    f"supported (SSP's own formats only)")
            if source is not None and source not in set_elements:
                if not src.exists(source):
                    what = "parameter binding" if tag == "ParameterBinding" else "parameter mapping"
                    raise ScenarioError(f"{ssd_display}:{b.sourceline}: {what} source {source!r} does not exist")
                set_elements[source] = parse_xml(src.read(source), src.display(source), schema)
    return set_elements


class _Flattener:
    """Nested systems flattened into one level: a component ``C`` of a system ``B`` becomes the
    component ``B.C`` (its hierarchical name); system connectors and the signals of a signal
    dictionary become junctions that a connection through them joins end to end; system-level
    parameter bindings are kept with their system's name and level; connections from a system's
    parameter or input connector become :class:`ParameterLink` s."""

    def __init__(self, src: _Source, set_elements: Mapping[str, etree._Element], fmu_dirs: Sequence[Path],
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
            conn = _connector(c, self.display)
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
            c = _connector(e, self.display)
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
            conn = _connector(c, self.display)
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
                out.append(_parameter_set(self.set_elements[source], self.src.display(source), source, mapping, prefix))
            for inline in bxml.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
                out.append(_parameter_set(inline, display, None, mapping, prefix))
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
            entries.append((e.get("source"), e.get("target"), _transform(e, line), suppress))
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
        if xml.get("implementation") not in (None, "any", "CoSimulation"):
            raise ScenarioError(f"{where}: component {full!r} asks for implementation={xml.get('implementation')!r}; "
                                f"the master runs co-simulation FMUs only")
        connectors = tuple(_connector(c, self.display) for c in xml.findall("ssd:Connectors/ssd:Connector", NS))
        names = [c.name for c in connectors]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ScenarioError(f"{where}: component {full!r} declares connector {sorted(dup)[0]!r} twice")
        for c in connectors:
            self.nodes[f"{full}.{c.name}"] = ("component", full, c)
        hint = None
        ann = _osp_annotation(xml)
        if ann is not None:
            h = ann.find("osp:StepSizeHint", NS)
            if h is not None:
                hint = _positive(h.get("value"), f"{self.display}:{h.sourceline}: osp:StepSizeHint value")
        self.components.append(Component(name=full, source=source, fmu=_resolve_fmu(source, self.src, self.fmu_dirs),
                                         connectors=connectors, bindings=tuple(self.bindings(xml, self.display)),
                                         step_size_hint=hint, depth=depth))

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
            transforms = [x for _, x, _ in chain if _transform(x, line) is not None]
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
                                                          _transform(cxml, line)))
                continue
            if any(self.nodes[n][2].unit for n, _, _ in chain[:-1]) and transforms:
                raise ScenarioError(f"{line}: a transformed connection through system connectors that declare "
                                    f"units is not supported (give the units at the components)")
            o_owner, o_path, o_conn = self.nodes[origin]
            out.append(_connection(cxml, line, o_path, o_conn.name, path, conn.name))
        return out


def _transform(xml: etree._Element, line: str) -> Transform | None:
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


def _connection(cxml: etree._Element, line: str, se: str, sc: str, ee: str, ec: str) -> Connection:
    """One connection between components' connectors (source first), with its transformation
    (linear, or an integer or boolean mapping) and ``suppressUnitConversion``."""
    t = _transform(cxml, line)
    suppress = cxml.get("suppressUnitConversion", "false") in ("true", "1")
    if t is None:
        return Connection(se, sc, ee, ec, suppress_unit_conversion=suppress)
    return Connection(se, sc, ee, ec, t.factor, t.offset, suppress, t.type, t.mapping)


def _experiment(root: etree._Element, ssd_display: str) -> Experiment:
    """The SSD's ``DefaultExperiment``: start and stop time, and the step of an
    ``osp:FixedStepAlgorithm`` annotation (None where not given)."""
    start, stop, step = 0.0, None, None
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        start = float(exp.get("startTime", 0.0))
        stop = float(exp.get("stopTime")) if exp.get("stopTime") is not None else None
        ann = _osp_annotation(exp)
        if ann is not None:
            alg = ann.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
            if alg is not None:
                step = _positive(alg.get("baseStepSize"),
                                 f"{ssd_display}:{alg.sourceline}: osp:FixedStepAlgorithm baseStepSize")
        if stop is not None and not stop > start:
            raise ScenarioError(f"{ssd_display}:{exp.sourceline}: DefaultExperiment stopTime {stop:g} s must be "
                                f"after startTime {start:g} s")
    return Experiment(start, stop, step)


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


def _positive(text: str | None, what: str) -> float:
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ScenarioError(f"{what} {text!r} is not a number") from None
    if not (value > 0 and math.isfinite(value)):
        raise ScenarioError(f"{what} {value:g} must be positive")
    return value


def select_parameter_set(scenario: Scenario, name: str) -> Scenario:
    """The scenario with parameter set ``name`` bound instead of the SSD's default set.

    Every binding of the SSD that references one of the scenario's parameter-set files is
    replaced by ``name``'s file (e.g. ``controller``'s ``tuned.ssv`` by ``thesis.ssv``).

    Raises
    ------
    ScenarioError
        If the scenario has no such set, or binds no parameter-set file to replace.
    """
    from dataclasses import replace

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


def read_ssv(path: str | os.PathLike[str], what: str = "parameter file") -> dict[str, Any]:
    """``{name: value}`` of an SSV file, checked against the SSP schema (Real -> float, Integer ->
    int, Boolean -> bool, String -> str).

    Raises
    ------
    ScenarioError
        A missing or invalid file, named with ``what`` (e.g. ``--parameter-file``).
    """
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{what} {p}: no such file")
    element = parse_xml(p.read_bytes(), str(p), "SystemStructureParameterValues.xsd")
    return {param.name: param.value for param in _parameter_set(element, str(p), str(p)).parameters}


def read_parameter_file(path: str | os.PathLike[str]) -> dict[str, Any]:
    """``{"component.variable": value}`` of an SSV file (``--parameter-file``): every parameter names
    the component it applies to (``plant.Mc``), as a system-level SSP binding does.

    Raises
    ------
    ScenarioError
        A missing or invalid file, or a parameter name without a component.
    """
    values = read_ssv(path, "--parameter-file")
    for name in values:
        component, dot, variable = name.partition(".")
        if not (dot and component and variable):
            raise ScenarioError(f"--parameter-file {path}: parameter {name!r} names no component "
                                f"(write it COMPONENT.VARIABLE, e.g. plant.{name})")
    return values


def ssv_text(values: Mapping[str, Any], name: str, description: str = "") -> str:
    """An SSP 1.0 parameter set (``.ssv``) named ``name``: bool -> Boolean, int -> Integer, else Real
    (written with ``repr``, so a value reads back exactly). The one SSV writer: the scenarios'
    parameter sets, ``ipcosim tune``'s ``autotuned.ssv`` and ``ipcosim identify``'s ``identified.ssv``."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssv:ParameterSet xmlns:ssv="{NS["ssv"]}" version="1.0" name={quoteattr(name)}'
             + (f" description={quoteattr(description)}" if description else "") + ">",
             "  <ssv:Parameters>"]
    for key, value in values.items():
        lines.append(f"    <ssv:Parameter name={quoteattr(key)}>{_ssv_value(value)}</ssv:Parameter>")
    lines += ["  </ssv:Parameters>", "</ssv:ParameterSet>", ""]
    return "\n".join(lines)


def _ssv_value(value: Any) -> str:
    if isinstance(value, bool):
        return f'<ssv:Boolean value="{str(value).lower()}"/>'
    if isinstance(value, int):
        return f'<ssv:Integer value="{value}"/>'
    return f'<ssv:Real value="{float(value)!r}"/>'
