"""SSP's transformations (SSP 1.0 section 4.5, ``ssc:*Transformation``) applied: a linear
transformation after a unit conversion as one factor and offset, a parameter value transformed,
and enumeration items mapped to the values of the enumeration types at both ends."""
from __future__ import annotations

from typing import Any

from ipcosim.harness.master.system import Model, Variable, value_type_of
from ipcosim.harness.scenario.errors import BindingError
from ipcosim.harness.scenario.structure import Connection, Parameter, Transform


def after_unit_conversion(factor: float, offset: float, conversion: tuple[float, float]) -> tuple[float, float]:
    """A linear transformation (``factor``, ``offset``) applied after a unit conversion, as one factor
    and offset: SSP 1.0 section 4.5.2 converts the unit first, then transforms:
    ``factor * (c0 * x + c1) + offset``."""
    return factor * conversion[0], factor * conversion[1] + offset


def transformed(value: Any, t: Transform, var: Variable, what: str) -> Any:
    """A parameter's value for ``var`` through transformation ``t``: linear (Real values only), or a
    boolean or integer mapping (a value the mapping does not name stays as it is)."""
    if t.type == "LinearTransformation":
        if value_type_of(var.type) != "real":
            raise BindingError(f"{what}: ssc:LinearTransformation on {var.name} ({var.type}); SSP defines it "
                               f"for Real values only")
        return t.factor * float(value) + t.offset
    table_map = dict(t.mapping)
    key = int(bool(value)) if t.type == "BooleanMappingTransformation" else int(value)
    mapped = table_map.get(key, key)
    return bool(mapped) if t.type == "BooleanMappingTransformation" else mapped


def enumeration_mapping(conn: Connection, ma: Model, va: Variable, mb: Model, vb: Variable,
                        where: str) -> tuple[tuple[int, int], ...]:
    """An ``ssc:EnumerationMappingTransformation`` (pairs of item names) as pairs of the items' values
    in the source's and the target's enumeration types."""
    ia, ib = ma.enumerations.get(va.name, {}), mb.enumerations.get(vb.name, {})
    pairs = []
    for source, target in conn.mapping:
        for name, items, v in ((source, ia, va), (target, ib, vb)):
            if name not in items:
                raise BindingError(f"{where}: ssc:EnumerationMappingTransformation names {name!r}, which is not an "
                                   f"item of {v.name}'s enumeration ({', '.join(items)})")
        pairs.append((ia[source], ib[target]))
    return tuple(pairs)


def enumeration_value(model: Model, var: Variable, p: Parameter, what: str) -> int:
    """An ``ssv:Enumeration`` value (an item name, through an ``EnumerationMappingTransformation``
    where a mapping gives one) as the value of that item in the variable's enumeration type."""
    items = model.enumerations.get(var.name)
    if items is None:
        raise BindingError(f"{what}: {p.name} = {p.value!r} is an enumeration item, but {var.name} is {var.type}, "
                           f"not an Enumeration")
    name = p.value
    if p.transform is not None:
        if p.transform.type != "EnumerationMappingTransformation":
            raise BindingError(f"{what}: ssc:{p.transform.type} on the enumeration value {p.name}; SSP maps "
                               f"enumeration items with ssc:EnumerationMappingTransformation")
        name = dict(p.transform.mapping).get(name, name)
    if name not in items:
        raise BindingError(f"{what}: {p.name} = {name!r} is not an item of {var.name}'s enumeration "
                           f"({', '.join(items)})")
    return items[name]
