"""Hand-written SSP documents for the conformance suite: an SSD, SSV or SSM as text, in SSP 1.0 or 2.0,
and a scenario folder holding them with the FMUs it references."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Iterable, Mapping

NS = ('xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
      'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
      'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
      'xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping" '
      'xmlns:ssb="http://ssp-standard.org/SSP1/SystemStructureSignalDictionary"')


def real(version: str) -> str:
    """The connector type of a double: SSP 1.0's Real, SSP 2.0's Float64 (for the FMI 3.0 adder)."""
    return "Real" if version == "1.0" else "Float64"


def connector(name: str, kind: str, version: str, unit: str | None = None, type_: str | None = None) -> str:
    t = type_ or real(version)
    u = f' unit="{unit}"' if unit else ""
    return f'<ssd:Connector name="{name}" kind="{kind}"><ssc:{t}{u}/></ssd:Connector>'


def adder_connectors(version: str, parameters: bool = False) -> str:
    """The adder's connectors: u1, u2 in, y out, and (``parameters``) k1, k2 as ``parameter`` and
    k_sum as ``calculatedParameter`` connectors, as OMSimulator and easySSP declare them."""
    c = [connector("u1", "input", version), connector("u2", "input", version), connector("y", "output", version)]
    if parameters:
        c += [connector("k1", "parameter", version), connector("k2", "parameter", version),
              connector("k_sum", "calculatedParameter", version)]
    return "<ssd:Connectors>" + "".join(c) + "</ssd:Connectors>"


def value(name: str, v: object, version: str = "1.0", unit: str | None = None) -> str:
    if isinstance(v, bool):
        body = f'<ssv:Boolean value="{str(v).lower()}"/>'
    elif isinstance(v, int):
        body = f'<ssv:Integer value="{v}"/>'
    else:
        u = f' unit="{unit}"' if unit else ""
        body = f'<ssv:{real(version)} value="{v!r}"{u}/>'
    return f'<ssv:Parameter name="{name}">{body}</ssv:Parameter>'


def parameter_set(values: Mapping[str, object], version: str, units: str = "", standalone: bool = False) -> str:
    """An ``ssv:ParameterSet`` of ``values`` (name -> value, or (value, unit) for a Real with a unit)."""
    params = "".join(value(k, *(v if isinstance(v, tuple) else (v,)), version=version) if not isinstance(v, tuple)
                     else value(k, v[0], version, v[1]) for k, v in values.items())
    head = '<?xml version="1.0" encoding="UTF-8"?>\n' if standalone else ""
    return (f'{head}<ssv:ParameterSet {NS} version="{version}" name="values"><ssv:Parameters>{params}'
            f'</ssv:Parameters>{units}</ssv:ParameterSet>')


def bindings(*items: str) -> str:
    """``ssd:ParameterBindings`` of the given ``ssd:ParameterBinding`` elements, in that order."""
    return "<ssd:ParameterBindings>" + "".join(items) + "</ssd:ParameterBindings>"


def inline(values: Mapping[str, object], version: str, prefix: str | None = None, mapping: str = "") -> str:
    p = f' prefix="{prefix}"' if prefix else ""
    return (f"<ssd:ParameterBinding{p}><ssd:ParameterValues>{parameter_set(values, version)}</ssd:ParameterValues>"
            f"{mapping}</ssd:ParameterBinding>")


def from_file(source: str, prefix: str | None = None, mapping: str = "") -> str:
    p = f' prefix="{prefix}"' if prefix else ""
    return f'<ssd:ParameterBinding source="{source}"{p}>{mapping}</ssd:ParameterBinding>'


def component(name: str, fmu: str, connectors: str, binding: str = "", extra: str = "") -> str:
    return (f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="resources/{fmu}.fmu"'
            f'{extra}>{connectors}{binding}</ssd:Component>')


def connection(start: str, end: str, inner: str = "") -> str:
    """A connection ``element.connector`` -> ``element.connector`` (``.connector`` alone: the system's own)."""
    (se, sc), (ee, ec) = start.rsplit(".", 1), end.rsplit(".", 1)
    return (f'<ssd:Connection startElement="{se}" startConnector="{sc}" endElement="{ee}" endConnector="{ec}">'
            f"{inner}</ssd:Connection>")


def system(name: str, elements: Iterable[str], connections: Iterable[str] = (), connectors: str = "",
           binding: str = "") -> str:
    conns = "".join(connections)
    return (f'<ssd:System name="{name}">{connectors}{binding}<ssd:Elements>{"".join(elements)}</ssd:Elements>'
            + (f"<ssd:Connections>{conns}</ssd:Connections>" if conns else "") + "</ssd:System>")


def document(system_xml: str, version: str, units: str = "", stop: float = 0.2) -> str:
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription {NS} version="{version}" '
            f'name="conformance">{system_xml}{units}<ssd:DefaultExperiment startTime="0.0" stopTime="{stop!r}"/>'
            f"</ssd:SystemStructureDescription>\n")


def write(folder: Path, ssd_text: str, fmus: Mapping[str, Path], files: Mapping[str, str] | None = None) -> Path:
    """A scenario folder: SystemStructure.ssd, the FMUs under resources/, further files by path."""
    (folder / "resources").mkdir(parents=True, exist_ok=True)
    (folder / "SystemStructure.ssd").write_text(ssd_text)
    for name, path in fmus.items():
        shutil.copyfile(path, folder / "resources" / f"{name}.fmu")
    for name, text in (files or {}).items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    return folder
