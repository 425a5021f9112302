"""Loading SSP scenarios: ``SystemStructure.ssd`` and ``.ssv`` parameter sets, from a scenario
folder or an ``.ssp`` archive, into an immutable :class:`~ipcosim.harness.scenario.structure.Scenario`.

Parse first, then run: loading only reads and checks files; nothing is instantiated. Every file is
validated against the schema of the SSP version it declares, naming the file and line of a problem.
It reads connector kinds, types and units, the transformations of connections and
``suppressUnitConversion``, unit definitions, the ``DefaultExperiment`` (start, stop and the OSP
``FixedStepAlgorithm`` step used by libcosim), component step-size hints, parameter bindings at every
level (inline, ``.ssv``, ``prefix``, parameter mappings from ``.ssm`` or inline) and the scenario's
named parameter sets. What the master does not run (an SSP as a component, arrays, clocks...) is
refused in one line naming the file, the element and the feature.

The reader, one idea to a module of this package:

    structure   the description it returns (Scenario, Component, Connection...) and select_parameter_set
    files       a folder or an archive's files; XML parsed and validated against the SSP schemas
    locations   where a scenario name and a component's FMU are found
    elements    SSP elements read into the description (values, parameter sets, connectors, units...)
    flatten     nested systems flattened into hierarchical component names
    ssv         SSV parameter files read and written
    ssp         (this module) the whole read: load_scenario
"""
from __future__ import annotations

import os
from pathlib import Path, PurePosixPath
from typing import Sequence

from lxml import etree

from ipcosim.harness.scenario.elements import parse_experiment, parse_parameter_set, parse_unit
from ipcosim.harness.scenario.errors import ScenarioError
from ipcosim.harness.scenario.files import NS, SSD_NAME, ScenarioFiles, display_path, parse_xml, ssp_version
from ipcosim.harness.scenario.flatten import Flattener
from ipcosim.harness.scenario.locations import fmu_search_path, resolve_location
from ipcosim.harness.scenario.structure import Scenario


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
    src = ScenarioFiles(location)
    try:
        return _load(src, [Path(d) for d in fmu_search_path(fmu_dirs)])
    finally:
        src.close()


def _load(src: ScenarioFiles, fmu_dirs: Sequence[Path]) -> Scenario:
    """Parse a scenario: the SSD (schema-validated against its version), its parameter files and
    mappings, then the system, flattened (see :class:`Flattener`), and the default experiment."""
    if not src.exists(SSD_NAME):
        where = display_path(src.location)
        container = "archive" if src.is_archive else "folder"
        raise ScenarioError(f"{where}: no {SSD_NAME} at the top level of the {container}")
    ssd_display = src.display(SSD_NAME)
    root = parse_xml(src.read(SSD_NAME), ssd_display, "SystemStructureDescription.xsd")
    ssv_files = src.top_level(".ssv")
    set_elements = _parameter_files(src, root, ssv_files, ssd_display)
    system_xml = root.find("ssd:System", NS)
    flat = Flattener(src, set_elements, fmu_dirs, ssd_display)
    flat.system(system_xml, "", 0)
    connections = flat.connections()
    units = {u.get("name"): parse_unit(u) for u in root.findall("ssd:Units/ssc:Unit", NS)}
    experiment = parse_experiment(root, ssd_display)
    sets = {}
    set_files = {}
    for fname in ssv_files:
        pset = parse_parameter_set(set_elements[fname], src.display(fname), fname)
        key = pset.name or PurePosixPath(fname).stem
        sets[key] = pset
        set_files[key] = fname
    return Scenario(name=system_xml.get("name"), origin=ssd_display, location=src.location,
                    description=system_xml.get("description") or "", components=tuple(flat.components),
                    connections=tuple(connections), units=units, experiment=experiment,
                    parameter_sets=sets, set_files=set_files, version=ssp_version(root),
                    system_bindings=tuple(sorted(flat.system_bindings, key=lambda b: -b.depth)),
                    parameter_links=tuple(flat.parameter_links), system_connectors=tuple(flat.system_connectors))


def _parameter_files(src: ScenarioFiles, root: etree._Element, ssv_files: Sequence[str],
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


