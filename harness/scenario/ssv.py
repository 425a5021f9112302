"""SSV parameter files: read (``--parameter-file``, any ``.ssv``) and written (the one SSV writer:
the scenarios' parameter sets, ``ipcosim tune``'s ``autotuned.ssv``, ``ipcosim identify``'s
``identified.ssv``).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping
from xml.sax.saxutils import quoteattr

from ipcosim.harness.scenario.elements import parse_parameter_set
from ipcosim.harness.scenario.errors import ScenarioError
from ipcosim.harness.scenario.files import NS, parse_xml


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
    return {param.name: param.value for param in parse_parameter_set(element, str(p), str(p)).parameters}


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
