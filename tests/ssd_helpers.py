"""Writing small SSP scenarios for tests: folders with SystemStructure.ssd, resources/ and .ssv files."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from ipcosim.harness.scenario.files import NS

HEAD = (f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription xmlns:ssd="{NS["ssd"]}" '
        f'xmlns:ssc="{NS["ssc"]}" xmlns:ssv="{NS["ssv"]}" xmlns:osp="{NS["osp"]}" version="1.0" name="{{name}}">\n')


def connector(name: str, kind: str, unit: str | None = "m", type_: str = "Real") -> str:
    inner = f'<ssc:{type_} unit="{unit}"/>' if (unit and type_ == "Real") else f"<ssc:{type_}/>"
    return f'<ssd:Connector name="{name}" kind="{kind}">{inner}</ssd:Connector>'


def component(name: str, fmu: str, connectors: Iterable[str], bindings: Sequence[str] = (),
              inline: Mapping[str, float] | None = None) -> str:
    parts = [f'<ssd:Component name="{name}" source="resources/{fmu}.fmu"><ssd:Connectors>',
             *connectors, "</ssd:Connectors>"]
    if bindings or inline:
        parts.append("<ssd:ParameterBindings>")
        for b in bindings:
            parts.append(f'<ssd:ParameterBinding source="{b}"/>')
        if inline:
            params = "".join(f'<ssv:Parameter name="{k}"><ssv:Real value="{v!r}"/></ssv:Parameter>'
                             for k, v in inline.items())
            parts.append(f'<ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0" name="inline">'
                         f'<ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues>'
                         f'</ssd:ParameterBinding>')
        parts.append("</ssd:ParameterBindings>")
    parts.append("</ssd:Component>")
    return "".join(parts)


def connection(start: str, end: str, factor: float | None = None, offset: float | None = None) -> str:
    (se, sc), (ee, ec) = start.split("."), end.split(".")
    attrs = f'startElement="{se}" startConnector="{sc}" endElement="{ee}" endConnector="{ec}"'
    if factor is None and offset is None:
        return f"<ssd:Connection {attrs}/>"
    lt = '<ssc:LinearTransformation' + (f' factor="{factor!r}"' if factor is not None else "") + \
         (f' offset="{offset!r}"' if offset is not None else "") + "/>"
    return f"<ssd:Connection {attrs}>{lt}</ssd:Connection>"


def ssd(name: str, components: Iterable[str], connections: Iterable[str], stop: float = 1.0, step: float = 0.01,
        units: str = "") -> str:
    conns = list(connections)
    body = [HEAD.format(name=name), f'<ssd:System name="{name}"><ssd:Elements>', *components, "</ssd:Elements>"]
    if conns:
        body += ["<ssd:Connections>", *conns, "</ssd:Connections>"]
    body.append("</ssd:System>")
    if units:
        body.append(f"<ssd:Units>{units}</ssd:Units>")
    body.append(f'<ssd:DefaultExperiment startTime="0.0" stopTime="{stop!r}"><ssd:Annotations>'
                f'<ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm>'
                f'<osp:FixedStepAlgorithm baseStepSize="{step!r}"/></osp:Algorithm></ssc:Annotation>'
                f"</ssd:Annotations></ssd:DefaultExperiment>")
    body.append("</ssd:SystemStructureDescription>\n")
    return "\n".join(body)


def ssv(name: str, values: Mapping[str, float]) -> str:
    params = "".join(f'<ssv:Parameter name="{k}"><ssv:Real value="{v!r}"/></ssv:Parameter>' for k, v in values.items())
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<ssv:ParameterSet xmlns:ssv="{NS["ssv"]}" version="1.0" '
            f'name="{name}"><ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet>\n')


def write_scenario(folder: Path, ssd_text: str, fmus: Mapping[str, Path] | None = None,
                   ssvs: Mapping[str, str] | None = None) -> Path:
    """A scenario folder: SystemStructure.ssd, resources/<Model>.fmu copies, .ssv files."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "SystemStructure.ssd").write_text(ssd_text)
    if fmus:
        (folder / "resources").mkdir(exist_ok=True)
        for name, path in fmus.items():
            shutil.copyfile(path, folder / "resources" / f"{name}.fmu")
    for fname, text in (ssvs or {}).items():
        (folder / fname).write_text(text)
    return folder
