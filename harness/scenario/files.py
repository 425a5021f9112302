"""Access to an SSP scenario's files: a folder or an ``.ssp`` archive addressed by archive-style
paths (:class:`ScenarioFiles`), and every XML file parsed and validated against the schema of the SSP
version it declares (1.0: FMPy's copy of the standard's XSD files; 2.0: the copy in ``schema/ssp2``),
naming the file and line of a problem.
"""
from __future__ import annotations

import os
import zipfile
from pathlib import Path

from lxml import etree

from ipcosim.harness.scenario.errors import ScenarioError

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



# --------------------------------------------------------------------------- sources
class ScenarioFiles:
    """Files of a scenario: a folder or a zip archive, addressed by archive-style paths."""

    def __init__(self, location: Path) -> None:
        self.location = location
        self.is_archive = location.is_file()
        self._zip: zipfile.ZipFile | None = None
        if self.is_archive:
            try:
                self._zip = zipfile.ZipFile(location)
            except (zipfile.BadZipFile, OSError) as exc:
                raise ScenarioError(f"{display_path(location)}: not an SSP archive (not a zip file: {exc})") from None

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()

    def display(self, name: str) -> str:
        if self.is_archive:
            return f"{display_path(self.location)}:{name}"
        return display_path(self.location / name)

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


def display_path(path: Path) -> str:
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


