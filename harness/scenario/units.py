"""Units of a scenario and its FMUs: the unit definitions that apply (the FMUs', then the SSD's),
a connector's unit, and the factor and offset that convert a value between two units."""
from __future__ import annotations

from typing import Mapping

from ipcosim.harness.master.system import Model, Variable
from ipcosim.harness.scenario.structure import Scenario, Unit


def unit_table(scenario: Scenario, *models: Model) -> dict[str, Unit]:
    """The unit definitions by name: the FMUs' (in order), then the SSD's (which win)."""
    table: dict[str, Unit] = {}
    for m in models:
        table.update(m.units)
    table.update(scenario.units)
    return table


def unit_conversion(src: str | None, dst: str | None, table: Mapping[str, Unit]) -> tuple[float, float] | None:
    """Factor and offset converting a value in unit ``src`` to unit ``dst``; None if incompatible.

    Equal names (or a missing unit on either side) convert with (1, 0). Different names convert
    when both are defined with the same base-unit exponents.
    """
    if src is None or dst is None or src == dst:
        return (1.0, 0.0)
    a, b = table.get(src), table.get(dst)
    if a is None or b is None or a.exponents != b.exponents:
        return None
    # value_SI = factor * v + offset
    return (a.factor / b.factor, (a.offset - b.offset) / b.factor)


def connector_unit(scenario: Scenario, comp: str, var: Variable) -> str | None:
    """The unit of component ``comp``'s connector for ``var``: the SSD's, else the FMU variable's."""
    c = next((x for x in scenario.component(comp).connectors if x.name == var.name), None)
    return (c.unit if c is not None and c.unit else None) or var.unit
