"""Loading SSP scenarios: ``SystemStructure.ssd`` and ``.ssv`` parameter sets, from a scenario
folder or an ``.ssp`` archive, into an immutable :class:`Scenario`.

Parse first, then run: this module only reads and checks files; nothing is instantiated. The
object model and the SSV reader come from :mod:`fmpy.ssp.ssd` (``read_ssd``); this module
extends it with what a master needs and FMPy leaves out -- schema validation that names the
file and line of every problem, folders as well as archives, connector types and units, the
``ssc:LinearTransformation`` of connections, ``suppressUnitConversion``, unit definitions, the
``DefaultExperiment`` (start, stop and the OSP ``FixedStepAlgorithm`` step used by libcosim),
component step-size hints and the scenario's named parameter sets.

Scenario names resolve to ``ssp/<name>/`` of the project (the committed sources); FMUs that a
folder's SSD references as ``resources/<Model>.fmu`` are looked up in the folder's
``resources/`` first, then in the directories of ``IPCOSIM_FMU_PATH`` and ``build/fmus/``.
"""
from __future__ import annotations

import io
import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Iterable, Mapping, Sequence

from lxml import etree

from ipcosim.errors import IpcosimError, UsageError, closest
from ipcosim.harness.paths import BUILD_FMU_DIR, SCENARIO_DIR

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


class ScenarioError(IpcosimError, ValueError):
    """An SSD, SSV or SSP archive that cannot be read, fails its schema or is inconsistent."""


class UnknownParameterSetError(UsageError, ScenarioError):
    """A parameter set the scenario does not have (``--parameter-set``)."""


class ScenarioNotFoundError(UsageError, FileNotFoundError):
    """A scenario name or path that does not exist."""


# --------------------------------------------------------------------------- description
@dataclass(frozen=True)
class Connector:
    """A connector of a component as the SSD declares it."""

    name: str
    kind: str  # input | output | parameter | calculatedParameter | inout
    type: str | None  # Real | Integer | Boolean | String | Enumeration | Binary | None (undeclared)
    unit: str | None = None


@dataclass(frozen=True)
class Parameter:
    """One value of a parameter set (``ssv:Parameter``)."""

    name: str
    type: str  # Real | Integer | Boolean | String
    value: Any
    unit: str | None = None


@dataclass(frozen=True)
class ParameterSet:
    """A named parameter set, inline in the SSD or from an ``.ssv`` file (``source``)."""

    name: str
    parameters: tuple[Parameter, ...]
    source: str | None = None


@dataclass(frozen=True)
class Component:
    """A component of the system: an FMU and its SSD connectors and parameter bindings."""

    name: str
    source: str
    fmu: Path | None  # resolved FMU file (None: not found; reported when bound to its FMU)
    connectors: tuple[Connector, ...]
    bindings: tuple[ParameterSet, ...] = ()
    step_size_hint: float | None = None

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

    def as_zip(self, names: Iterable[str]) -> io.BytesIO | Path:
        """The scenario as a zip (what fmpy's ``read_ssd`` reads): the archive itself, or an
        in-memory archive of the given files of a folder."""
        if self.is_archive:
            return self.location
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            for name in names:
                zf.writestr(name, self.read(name))
        buf.seek(0)
        return buf


def _display(path: Path) -> str:
    """A path as short as possible for messages (relative to the working directory)."""
    try:
        return os.path.relpath(path)
    except ValueError:
        return str(path)


# --------------------------------------------------------------------------- validation
_SCHEMAS: dict[str, etree.XMLSchema] = {}


def _schema(file_name: str) -> etree.XMLSchema:
    """SSP 1.0 schema from FMPy's copy of the standard's XSD files."""
    if file_name not in _SCHEMAS:
        import fmpy.ssp.ssd as fssd

        _SCHEMAS[file_name] = etree.XMLSchema(file=str(Path(fssd.__file__).parent / "schema" / file_name))
    return _SCHEMAS[file_name]


def parse_xml(data: bytes, display: str, schema_file: str) -> etree._Element:
    """Parse and schema-validate an SSP XML file; one-line ScenarioError naming file and line.

    Parameters
    ----------
    data : bytes
        The file's content.
    display : str
        File name used in messages.
    schema_file : str
        ``SystemStructureDescription.xsd`` or ``SystemStructureParameterValues.xsd``.
    """
    try:
        root = etree.fromstring(data)
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"{display}: not well-formed XML: {exc}") from None
    schema = _schema(schema_file)
    if not schema.validate(root):
        err = schema.error_log[0]
        message = err.message.replace("{" + NS["ssd"] + "}", "ssd:").replace("{" + NS["ssc"] + "}", "ssc:")
        message = message.replace("{" + NS["ssv"] + "}", "ssv:")
        more = f" (and {len(schema.error_log) - 1} more)" if len(schema.error_log) > 1 else ""
        raise ScenarioError(f"{display}:{err.line}: fails the SSP 1.0 schema: {message}{more}")
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
    ``IPCOSIM_FMU_PATH`` (os.pathsep-separated), then ``build/fmus``."""
    dirs = [Path(d) for d in (extra or [])]
    env = os.environ.get("IPCOSIM_FMU_PATH", "")
    dirs += [Path(d) for d in env.split(os.pathsep) if d]
    dirs.append(BUILD_FMU_DIR)
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
def _parse_value(type_: str, text: str | None, display: str, name: str) -> Any:
    if text is None:
        raise ScenarioError(f"{display}: parameter {name!r} has no value")
    try:
        if type_ == "Real":
            return float(text)
        if type_ in ("Integer", "Enumeration"):
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


def _parameter_set(element: etree._Element, display: str, source: str | None) -> ParameterSet:
    """Immutable copy of an ``ssv:ParameterSet`` (read through fmpy's SSV reader)."""
    from fmpy.ssp.ssd import _get_parameter_set  # the SSV reader of read_ssd

    fset = _get_parameter_set(element)
    params = []
    for p, xml in zip(fset.parameters, element.findall("ssv:Parameters/ssv:Parameter", NS)):
        if p.type is None:
            raise ScenarioError(f"{display}: parameter {p.name!r} has no value element")
        unit = p.unit
        if unit is None and p.type == "Real":
            real = xml.find("ssv:Real", NS)
            unit = real.get("unit") if real is not None else None
        params.append(Parameter(p.name, p.type, _parse_value(p.type, p.value, display, p.name), unit))
    return ParameterSet(name=fset.name or "", parameters=tuple(params), source=source)


def _connector(xml: etree._Element) -> Connector:
    type_, unit = None, None
    for t in ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary"):
        el = xml.find(f"ssc:{t}", NS)
        if el is not None:
            type_ = t
            unit = el.get("unit") if t == "Real" else None
            break
    return Connector(name=xml.get("name"), kind=xml.get("kind"), type=type_, unit=unit)


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
        Not a zip, no SystemStructure.ssd, not well-formed, fails the SSP 1.0 schema, an
        unreadable parameter file, a connection naming an undeclared element or connector,
        duplicate names, an input connected twice, a transformation on a non-Real connection.
    """
    location = resolve_location(scenario_or_path)
    src = _Source(location)
    try:
        return _load(src, [Path(d) for d in fmu_search_path(fmu_dirs)])
    finally:
        src.close()


def _load(src: _Source, fmu_dirs: Sequence[Path]) -> Scenario:
    """Parse a scenario: the SSD (schema-validated), its parameter files, FMPy's object model of
    the system, then what FMPy leaves out (connectors, bindings, step hints, transformations,
    units, the default experiment), each checked with file and line in the message."""
    if not src.exists(SSD_NAME):
        where = _display(src.location)
        container = "archive" if src.is_archive else "folder"
        raise ScenarioError(f"{where}: no {SSD_NAME} at the top level of the {container}")
    ssd_display = src.display(SSD_NAME)
    root = parse_xml(src.read(SSD_NAME), ssd_display, "SystemStructureDescription.xsd")
    ssv_files = src.top_level(".ssv")
    set_elements = _parameter_files(src, root, ssv_files, ssd_display)
    fssd, system_xml = _read_system(src, root, set_elements, ssd_display)
    components = []
    seen: set[str] = set()
    for fcomp, xml in zip(fssd.system.elements, system_xml.findall("ssd:Elements/ssd:Component", NS)):
        if fcomp.name in seen:
            raise ScenarioError(f"{ssd_display}:{xml.sourceline}: duplicate component name {fcomp.name!r}")
        seen.add(fcomp.name)
        components.append(_component(fcomp, xml, src, set_elements, fmu_dirs, ssd_display))
    by_name = {c.name: c for c in components}
    connections = [_connection(cxml, f"{ssd_display}:{cxml.sourceline}", by_name)
                   for cxml in system_xml.findall("ssd:Connections/ssd:Connection", NS)]
    units = {u.get("name"): _unit(u) for u in root.findall("ssd:Units/ssc:Unit", NS)}
    experiment = _experiment(root, ssd_display)
    sets = {}
    set_files = {}
    for fname in ssv_files:
        pset = _parameter_set(set_elements[fname], src.display(fname), fname)
        key = pset.name or PurePosixPath(fname).stem
        sets[key] = pset
        set_files[key] = fname
    return Scenario(name=fssd.name or system_xml.get("name"), origin=ssd_display, location=src.location,
                    description=system_xml.get("description") or "", components=tuple(components),
                    connections=tuple(connections), units=units, experiment=experiment,
                    parameter_sets=sets, set_files=set_files)


def _parameter_files(src: _Source, root: etree._Element, ssv_files: Sequence[str],
                     ssd_display: str) -> dict[str, etree._Element]:
    """Every parameter file of the scenario, validated, by its path: the top-level ``.ssv`` files
    (the selectable parameter sets) and those parameter bindings name in sub-folders."""
    set_elements: dict[str, etree._Element] = {}
    for name in ssv_files:
        set_elements[name] = parse_xml(src.read(name), src.display(name), "SystemStructureParameterValues.xsd")
    for b in root.iter(f"{{{NS['ssd']}}}ParameterBinding"):
        source = b.get("source")
        if source is not None and source not in set_elements:
            if not src.exists(source):
                raise ScenarioError(f"{ssd_display}:{b.sourceline}: parameter binding source {source!r} does not exist")
            set_elements[source] = parse_xml(src.read(source), src.display(source),
                                             "SystemStructureParameterValues.xsd")
    for b in root.iter(f"{{{NS['ssd']}}}ParameterMapping"):
        raise ScenarioError(f"{ssd_display}:{b.sourceline}: parameter mappings (.ssm) are not supported")
    return set_elements


def _read_system(src: _Source, root: etree._Element, set_elements: Mapping[str, etree._Element],
                 ssd_display: str) -> tuple[Any, etree._Element]:
    """FMPy's object model of the SSD (components, bindings, connections) and the SSD's
    ``ssd:System`` element; a system of anything but components is refused."""
    from fmpy.ssp.ssd import Component as FComponent
    from fmpy.ssp.ssd import read_ssd

    archive = src.as_zip([SSD_NAME, *set_elements])
    try:
        fssd = read_ssd(archive, validate=False)
    except Exception as exc:  # noqa: BLE001 -- fmpy raises bare exceptions
        raise ScenarioError(f"{ssd_display}: cannot be read: {exc}") from None
    if any(not isinstance(e, FComponent) for e in fssd.system.elements):
        raise ScenarioError(f"{ssd_display}: nested systems and signal dictionaries are not supported; "
                            f"the system must contain components only")
    return fssd, root.find("ssd:System", NS)


def _component(fcomp: Any, xml: etree._Element, src: _Source, set_elements: Mapping[str, etree._Element],
               fmu_dirs: Sequence[Path], ssd_display: str) -> Component:
    """One component: FMPy's name and source, with the connectors, parameter bindings (files and
    inline) and ``osp:StepSizeHint`` read from its XML, and its FMU file resolved."""
    connectors = tuple(_connector(c) for c in xml.findall("ssd:Connectors/ssd:Connector", NS))
    names = [c.name for c in connectors]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ScenarioError(f"{ssd_display}:{xml.sourceline}: component {fcomp.name!r} declares connector "
                            f"{sorted(dup)[0]!r} twice")
    bindings = []
    for bxml in xml.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        source = bxml.get("source")
        if source is not None:
            bindings.append(_parameter_set(set_elements[source], src.display(source), source))
        for inline in bxml.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
            bindings.append(_parameter_set(inline, ssd_display, None))
    hint = None
    ann = _osp_annotation(xml)
    if ann is not None:
        h = ann.find("osp:StepSizeHint", NS)
        if h is not None:
            hint = _positive(h.get("value"), f"{ssd_display}:{h.sourceline}: osp:StepSizeHint value")
    return Component(name=fcomp.name, source=fcomp.source, fmu=_resolve_fmu(fcomp.source, src, fmu_dirs),
                     connectors=connectors, bindings=tuple(bindings), step_size_hint=hint)


def _connection(cxml: etree._Element, line: str, by_name: Mapping[str, Component]) -> Connection:
    """One connection between declared connectors of declared components, with its
    transformation (linear, or an integer or boolean mapping) and ``suppressUnitConversion``."""
    se, sc, ee, ec = (cxml.get(k) for k in ("startElement", "startConnector", "endElement", "endConnector"))
    if se is None or ee is None:
        raise ScenarioError(f"{line}: connection {sc!r} -> {ec!r} to the system boundary is not supported "
                            f"(give startElement and endElement)")
    for elem, conn in ((se, sc), (ee, ec)):
        if elem not in by_name:
            raise ScenarioError(f"{line}: connection names component {elem!r}, which the system does not have")
        if by_name[elem].connector(conn) is None:
            raise ScenarioError(f"{line}: connection names {elem}.{conn}, but component {elem!r} declares "
                                f"no connector {conn!r}")
    factor, offset = 1.0, 0.0
    kind, mapping = None, ()
    lt = cxml.find("ssc:LinearTransformation", NS)
    if lt is not None:
        kind = "LinearTransformation"
        factor, offset = float(lt.get("factor", 1.0)), float(lt.get("offset", 0.0))
        if not (math.isfinite(factor) and math.isfinite(offset)):
            raise ScenarioError(f"{line}: linear transformation factor/offset must be finite")
    for other in ("IntegerMappingTransformation", "BooleanMappingTransformation"):
        mt = cxml.find(f"ssc:{other}", NS)
        if mt is not None:
            kind, mapping = other, _map_entries(mt, other, line)
    if cxml.find("ssc:EnumerationMappingTransformation", NS) is not None:
        raise ScenarioError(f"{line}: ssc:EnumerationMappingTransformation is not supported (it maps "
                            f"enumeration item names; map the values with ssc:IntegerMappingTransformation)")
    suppress = cxml.get("suppressUnitConversion", "false") in ("true", "1")
    return Connection(se, sc, ee, ec, factor, offset, suppress, kind, mapping)


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


def _map_entries(xml: etree._Element, kind: str, line: str) -> tuple[tuple[Any, Any], ...]:
    """The (source, target) pairs of a mapping transformation (Boolean values as 0/1)."""
    def value(text: str | None) -> int:
        if kind == "BooleanMappingTransformation":
            return 1 if text in ("true", "1") else 0
        return int(text)  # schema-validated xs:int

    entries = tuple((value(e.get("source")), value(e.get("target"))) for e in xml.findall("ssc:MapEntry", NS))
    sources = [a for a, _ in entries]
    if len(set(sources)) != len(sources):
        raise ScenarioError(f"{line}: ssc:{kind} maps a source value twice")
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
