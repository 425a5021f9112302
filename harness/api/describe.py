"""What a scenario is made of, for a user choosing names to ``--set``: its components, their FMUs
in each flavour, and every variable with causality, type, unit, start value (after the
scenario's parameter sets) and description (``ipcosim describe``).

Example::

    from ipcosim.harness.api.describe import describe, describe_text

    info = describe("single-mass-lqr")
    [v["name"] for v in info["components"][2]["variables"] if "python" in v["set"]]
    print(describe_text(info))
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ipcosim.harness.api.engine import Prepared
from ipcosim.harness.master.system import Instance, Model, System
from ipcosim.harness.scenario.flavour import native_fmu_dir
from ipcosim.harness.scenario.model_description import read_model


def describe(scenario: str | os.PathLike[str], *, parameter_set: str | None = None) -> dict[str, Any]:
    """The components of ``scenario`` and their variables, as plain data (``ipcosim describe --json``).

    Parameters
    ----------
    scenario : str or path
        Scenario name, folder, SystemStructure.ssd or ``.ssp`` archive.
    parameter_set : str, optional
        Bind this parameter set instead of the scenario's default.

    Returns
    -------
    dict
        ``{"scenario", "description", "origin", "parameter_sets": {"bound", "available"},
        "experiment": {"start_time_s", "stop_time_s", "step_s"}, "components": [{"name", "model",
        "fmus": {flavour: path or None}, "variables": [{"name", "causality", "type", "unit",
        "start", "description", "set": [flavours a --set may change it in]}], "clocks": [one line per FMI 3.0
        clock: name, kind, period]}]}``. ``fmus``'s
        ``native`` is None where the native FMU is not built (or the model has none).

    Raises
    ------
    IpcosimError
        Unknown scenario or parameter set, unreadable SSD or FMU (one line naming it).
    """
    with Prepared(scenario, parameter_set=parameter_set, slave_factory=_no_slave, warn=False) as prepared:
        system = prepared.system
    sc = system.scenario
    exp = sc.experiment
    return {"scenario": sc.name, "description": sc.description, "origin": sc.origin,
            "parameter_sets": {"bound": list(sc.bound_sets), "available": sorted(sc.parameter_sets)},
            "experiment": {"start_time_s": exp.start_time, "stop_time_s": exp.stop_time, "step_s": exp.step_size},
            "components": [_component(system, inst) for inst in system.instances]}


def _no_slave(instance: Any) -> Any:
    raise AssertionError("describe runs nothing")


def _component(system: System, inst: Instance) -> dict[str, Any]:
    """One component: its FMU per flavour and its variables (which a --set may change, per flavour)."""
    native = _native_model(inst.model)
    fmus = {"python": str(inst.model.path) if inst.model.path else None,
            "native": str(native.path) if native is not None and native.path else None}
    variables = []
    for var in inst.model.variables.values():
        free = system.link_into(inst.name, var.name) is None
        flavours = [name for name, model in (("python", inst.model), ("native", native)) if model is not None
                    and var.name in model.variables and model.variables[var.name].settable and free]
        variables.append({"name": var.name, "causality": var.causality, "type": var.type, "unit": var.unit,
                          "start": inst.start_value(var.name), "description": var.description, "set": flavours})
    extra = [n for n, v in (native.variables.items() if native else ()) if n not in inst.model.variables
             and v.settable and system.link_into(inst.name, n) is None]
    from ipcosim.harness.master.clocks import clocking

    found = clocking(inst.model.path, inst.model.fmi_version, inst.name)
    return {"name": inst.name, "model": inst.model.name, "fmus": fmus, "variables": variables,
            "native_only": extra, "interface": _interface(inst),
            "clocks": [c.describe() for c in (found.clocks if found else ())]}


def _interface(inst: Instance) -> str:
    """The FMU interface the component runs, with the solver when the master integrates it."""
    if inst.interface != "ModelExchange":
        return "co-simulation"
    from ipcosim.harness.master.me_slave import DEFAULT_TOLERANCE

    tolerance = inst.tolerance or DEFAULT_TOLERANCE
    return f"model exchange, integrated by the master (CVODE, relative tolerance {tolerance:g})"


def _native_model(model: Model) -> Model | None:
    """The native flavour's interface of ``model`` where ``ipcosim build --native`` has built it."""
    path = Path(native_fmu_dir()) / f"{model.name}.fmu"
    return read_model(path) if path.is_file() else None


def describe_text(info: dict[str, Any]) -> str:
    """``describe``'s data as the tables ``ipcosim describe`` prints."""
    exp = info["experiment"]
    sets = info["parameter_sets"]
    lines = [f"{info['scenario']}: {info['description']}".rstrip(": "), f"  from {info['origin']}",
             f"  parameter sets: {', '.join(sets['bound']) or 'none'} bound (available: "
             f"{', '.join(sets['available']) or 'none'}); experiment from {exp['start_time_s']:g} s to "
             f"{_value(exp['stop_time_s'])} s, step {_value(exp['step_s'])} s", ""]
    for comp in info["components"]:
        native = comp["fmus"]["native"] or "not built (`ipcosim build --native`)"
        lines += [f"component {comp['name']}: {comp['model']} ({comp['interface']})",
                  f"  python FMU  {comp['fmus']['python']}",
                  f"  native FMU  {native}"]
        rows = [("variable", "causality", "type", "unit", "start", "--set", "description")]
        rows += [(v["name"], v["causality"], v["type"], v["unit"] or "-", _value(v["start"]),
                  ",".join(v["set"]) or "-", v["description"]) for v in comp["variables"]]
        widths = [max(len(r[i]) for r in rows) for i in range(6)]
        lines += ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)) + "  " + r[6] for r in rows]
        lines += [f"  clock {text}" for text in comp.get("clocks", ())]
        if comp["native_only"]:
            lines.append(f"  native flavour only (--fmus native --set): {', '.join(comp['native_only'])}")
        lines.append("")
    lines.append("Set a start value with `ipcosim run SCENARIO --set COMPONENT.VARIABLE=VALUE` (--set column: the "
                 "flavours that accept it; '-': an output, or an input fed by a connection). Every variable is "
                 "recordable by name with --record COMPONENT.VARIABLE (the connectors are recorded by default).")
    return "\n".join(line.rstrip() for line in lines)


def _value(value: Any) -> str:
    if value is None:
        return "-"
    return f"{value:.6g}" if isinstance(value, float) else str(value)
