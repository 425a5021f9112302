"""The FMI 3.0 variant of a native FMU's description, derived from its FMI 2.0 model description.

Every native FMU (a single model, ``cgen.model_description``, or an exported loop,
``container.model_description``) is described once, as FMI 2.0; :func:`model_description`
rewrites that tree into FMI 3.0 so the two variants cannot drift: the same names, value
references, units, start values, causalities, variabilities and dependencies. What FMI 3.0
changes: ``guid`` is the ``instantiationToken``; each ``ScalarVariable`` with its type element
is one ``Float64`` / ``Int32`` / ``Boolean`` element; the model structure lists value references
instead of indices (``Output``, ``InitialUnknown``); the C source files move to
``sources/buildDescription.xml`` (:func:`build_description`); and FMI 3.0 asks for one
independent variable, ``time`` (value reference one past the largest used, as none is free
below it; the FMI 2.0 variant has no such variable, so ``c/fmi3adapter.h`` answers it).
"""
from __future__ import annotations

from xml.etree import ElementTree

from ipcosim.harness.native import cgen
from ipcosim.harness.native.exchange import INDICATOR_PREFIX

#: FMI 2.0 type element -> FMI 3.0 variable element.
TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
#: FMI 2.0 CoSimulation attributes kept (with their FMI 3.0 spelling).
_CS_ATTRIBUTES = {"modelIdentifier": "modelIdentifier",
                  "canHandleVariableCommunicationStepSize": "canHandleVariableCommunicationStepSize",
                  "canBeInstantiatedOnlyOncePerProcess": "canBeInstantiatedOnlyOncePerProcess",
                  "canGetAndSetFMUstate": "canGetAndSetFMUState", "canSerializeFMUstate": "canSerializeFMUState"}
_ROOT_ATTRIBUTES = ("modelName", "description", "generationTool", "variableNamingConvention")


def model_description(fmi2_xml: bytes) -> bytes:
    """The FMI 3.0 ``modelDescription.xml`` of the FMU that ``fmi2_xml`` describes as FMI 2.0."""
    src = ElementTree.fromstring(fmi2_xml)
    attrs = {"fmiVersion": "3.0", **{a: src.get(a) for a in _ROOT_ATTRIBUTES if src.get(a) is not None},
             "instantiationToken": src.get("guid", "")}
    root = ElementTree.Element("fmiModelDescription", attrs)
    me = src.find("ModelExchange")
    if me is not None:  # FMI 3.0 says "needs" where FMI 2.0 said "not needed"
        ElementTree.SubElement(root, "ModelExchange", {
            **{_CS_ATTRIBUTES[k]: v for k, v in me.attrib.items() if k in _CS_ATTRIBUTES},
            "needsCompletedIntegratorStep": "false" if me.get("completedIntegratorStepNotNeeded") == "true"
            else "true"})
    cs = src.find("CoSimulation")
    ElementTree.SubElement(root, "CoSimulation", {_CS_ATTRIBUTES[k]: v for k, v in cs.attrib.items()
                                                  if k in _CS_ATTRIBUTES})
    for tag in ("UnitDefinitions", "LogCategories", "DefaultExperiment"):
        element = src.find(tag)
        if element is not None:
            root.append(element)
    scalars = list(src.find("ModelVariables"))
    vr_of_index = {i + 1: sv.get("valueReference") for i, sv in enumerate(scalars)}
    mv = ElementTree.SubElement(root, "ModelVariables")
    used = [int(sv.get("valueReference")) for sv in scalars]
    ElementTree.SubElement(mv, "Float64", {"name": "time", "valueReference": str(max(used, default=-1) + 1),
                                           "causality": "independent", "variability": "continuous",
                                           "description": "simulation time"})
    for sv in scalars:
        typed = next(iter(sv))
        if typed.tag not in TYPES:
            raise ValueError(f"{src.get('modelName')}: variable {sv.get('name')} of type {typed.tag} has no FMI 3.0 "
                             "type here")
        attrs = {**sv.attrib, **typed.attrib}
        if "derivative" in attrs:  # a state's index in FMI 2.0, its value reference in FMI 3.0
            attrs["derivative"] = vr_of_index[int(attrs["derivative"])]
        ElementTree.SubElement(mv, TYPES[typed.tag], attrs)
    ms = ElementTree.SubElement(root, "ModelStructure")
    fmi2_ms = src.find("ModelStructure")
    for group, tag in (("Outputs", "Output"), ("Derivatives", "ContinuousStateDerivative"),
                       ("InitialUnknowns", "InitialUnknown")):
        for unknown in fmi2_ms.iterfind(f"{group}/Unknown"):
            attrs = {"valueReference": vr_of_index[int(unknown.get("index"))]}
            if unknown.get("dependencies") is not None:
                attrs["dependencies"] = " ".join(vr_of_index[int(i)] for i in unknown.get("dependencies").split())
            ElementTree.SubElement(ms, tag, attrs)
    if me is not None:  # FMI 3.0 names the event indicators' variables (FMI 2.0 only counts them)
        for sv in scalars:
            if sv.get("name", "").startswith(INDICATOR_PREFIX):
                ElementTree.SubElement(ms, "EventIndicator", {"valueReference": sv.get("valueReference")})
    return cgen.xml_bytes(root)


def build_description(identifier: str, sources: list[str]) -> bytes:
    """``sources/buildDescription.xml``: the C99 files to compile for ``identifier``, include folder ``.``."""
    root = ElementTree.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    config = ElementTree.SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = ElementTree.SubElement(config, "SourceFileSet", {"language": "C99"})
    for name in sources:
        ElementTree.SubElement(files, "SourceFile", {"name": name})
    return cgen.xml_bytes(root)


def source_files(fmi2_xml: bytes) -> list[str]:
    """The C files an FMI 2.0 model description lists in ``<SourceFiles>``."""
    return [f.get("name") for f in ElementTree.fromstring(fmi2_xml).iterfind("CoSimulation/SourceFiles/File")]
