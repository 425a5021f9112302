"""The conformance suite's test FMUs: the adder ``y = k1*u1 + k2*u2`` (``tests/data/cfmu/adder.c``,
with the calculated parameter ``k_sum = k1 + k2`` and the local ``twice_y = 2 y``) as an FMI 2.0 and
an FMI 3.0 FMU, optionally with units on its variables (FMI ``UnitDefinitions``)."""
from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Mapping

import cfmu
from lxml import etree

#: Start values of the adder's parameters and inputs (adder.c's model_reset).
K1, K2, U1, U2 = 1.0, 1.0, 1.0, 1.0


def adder(name: str, fmi: str) -> cfmu.Spec:
    real = "Real" if fmi == "2.0" else "Float64"
    return cfmu.Spec(name, "adder.c", fmi, (
        cfmu.Var("u1", real, "input", "r", 0, "1.0"), cfmu.Var("u2", real, "input", "r", 1, "1.0"),
        cfmu.Var("y", real, "output", "r", 2, None, None, None, ("u1", "u2")),
        cfmu.Var("k1", real, "parameter", "r", 3, "1.0", "fixed", "exact"),
        cfmu.Var("k2", real, "parameter", "r", 4, "1.0", "fixed", "exact"),
        cfmu.Var("k_sum", real, "calculatedParameter", "r", 5, None, "fixed", "calculated"),
        cfmu.Var("twice_y", real, "local", "r", 6, None, "continuous", "calculated"),
    ), step=0.1, stop=1.0)


#: Unit definitions the unit rules use: (kg, m, s, A, K, mol, cd, rad) exponents, factor, offset.
UNIT_DEFS: dict[str, tuple[dict[str, int], float, float]] = {
    "m": ({"m": 1}, 1.0, 0.0), "km": ({"m": 1}, 1000.0, 0.0),
    "m/s2": ({"m": 1, "s": -2}, 1.0, 0.0), "cm/s2": ({"m": 1, "s": -2}, 0.01, 0.0),
}


def with_units(fmu: Path, units: Mapping[str, str], out: Path) -> Path:
    """A copy of ``fmu`` at ``out`` whose variables ``units`` (name -> unit) carry those units, with
    their ``UnitDefinitions`` (from :data:`UNIT_DEFS`)."""
    with zipfile.ZipFile(fmu) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    root = etree.fromstring(members["modelDescription.xml"])
    fmi2 = root.get("fmiVersion") == "2.0"
    defs = etree.Element("UnitDefinitions")
    for name in sorted(set(units.values())):
        exps, factor, offset = UNIT_DEFS[name]
        unit = etree.SubElement(defs, "Unit", name=name)
        etree.SubElement(unit, "BaseUnit", **{k: str(v) for k, v in exps.items()}, factor=repr(factor),
                         offset=repr(offset))
    root.insert(list(root).index(root.find("CoSimulation")) + 1, defs)
    for var in root.find("ModelVariables"):
        if var.get("name") in units:
            (var[0] if fmi2 else var).set("unit", units[var.get("name")])
    members["modelDescription.xml"] = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    with zipfile.ZipFile(out, "w") as zf:
        for n, data in members.items():
            zf.writestr(n, data)
    return out


#: The enumeration type the Enumeration rules use: item name -> value.
MODE = {"Off": 0, "Slow": 1, "Fast": 2}


def with_enumeration(fmu: Path, variables: tuple[str, ...], out: Path) -> Path:
    """A copy of an FMI 2.0 ``fmu`` at ``out`` whose Integer ``variables`` are of the Enumeration type
    ``Mode`` (:data:`MODE`), declared in its ``TypeDefinitions``."""
    with zipfile.ZipFile(fmu) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    root = etree.fromstring(members["modelDescription.xml"])
    types = etree.Element("TypeDefinitions")
    enum = etree.SubElement(etree.SubElement(types, "SimpleType", name="Mode"), "Enumeration")
    for name, value in MODE.items():
        etree.SubElement(enum, "Item", name=name, value=str(value))
    root.insert(list(root).index(root.find("CoSimulation")) + 1, types)
    for var in root.find("ModelVariables"):
        if var.get("name") in variables:
            var[0].tag = "Enumeration"
            var[0].set("declaredType", "Mode")
    members["modelDescription.xml"] = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    with zipfile.ZipFile(out, "w") as zf:
        for n, data in members.items():
            zf.writestr(n, data)
    return out
