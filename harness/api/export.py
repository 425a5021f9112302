"""``ipcosim export``: a scenario's whole closed loop as one FMI 2.0 (or 3.0) co-simulation FMU.

The loop is built from the scenario's native components (``ipcosim build --native``), bound and
ordered exactly as ``ipcosim run SCENARIO --fmus native`` runs it (the same
:class:`~ipcosim.harness.api.engine.Prepared` binding and redesign, the master's
``gauss_seidel_order`` and ``step_multiples``), and compiled into one FMU by
:mod:`ipcosim.harness.native.container`. Its variables:

- input ``reference`` [m], start 0: added to what the scenario's setpoint component feeds the
  controller (set the setpoint's ``amplitude`` to 0 to drive the loop from this input alone);
- an input ``<component>.<input>`` for every component input no connection feeds (disturbances);
- an output ``<component>.<output>`` for every output of every component but the setpoint
  (the plant's measurements, the controller's voltage): the names of ``results.csv``'s columns;
- a parameter ``<component>.<name>`` for every native component parameter, with the value the
  scenario binds as its start value.
"""
from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ipcosim.errors import IpcosimError, UsageError
from ipcosim.harness.master.system import Instance, System
from ipcosim.harness.native.container import ComponentSpec, ContainerSpec, InputSpec, build_container, c_name

#: Model name of the component whose output the container's ``reference`` input adds to.
SETPOINT_MODEL = "Setpoint"


@dataclass(frozen=True)
class ExportOptions:
    """What ``ipcosim export`` does: the scenario (name or folder), the FMU file to write, and
    optionally a parameter set of the scenario, the model identifier (default from the
    scenario's name), extra FMU folders, parameter values (``{"controller.sample_period":
    0.002}``, the grammar and the native redesign of ``ipcosim run --set``) that become the
    FMU's parameter start values, and the FMI version of the FMU (``"2"`` or ``"3"``)."""

    scenario: str
    out: Path
    parameter_set: str | None = None
    model_identifier: str | None = None
    fmu_dirs: tuple[Path, ...] = ()
    set: Mapping[str, Any] = field(default_factory=dict)  # noqa: A003 -- the option's name (as RunOptions.set)
    fmi: str = "2"


class ExportError(IpcosimError, ValueError):
    """The scenario cannot be exported as one FMU (names the scenario, component or file)."""


#: Said before a flavour error: the export has no Python flavour to fall back to.
NATIVE_ONLY = "only the native flavour can be exported"


def identifier(scenario_name: str) -> str:
    """A model identifier from a scenario name: ``single-mass-lqr`` -> ``SingleMassLqrLoop``."""
    words = [w for w in c_name(scenario_name).split("_") if w]
    name = "".join(w[:1].upper() + w[1:] for w in words) + "Loop"
    return name if name[0].isalpha() else "Loop" + name


def export(options: ExportOptions) -> Path:
    """Write the scenario's loop as one FMU to ``options.out``; returns the path.

    Raises
    ------
    IpcosimError
        An unknown scenario, a scenario the native flavour cannot run (it names the component
        and parameter), no C compiler, an unwritable ``out`` (one line each).
    """
    out = Path(options.out)
    _check_out(out)
    return build_container(loop_spec(options), out, fmi=options.fmi)


def loop_spec(options: ExportOptions) -> ContainerSpec:
    """The :class:`ContainerSpec` of the scenario's loop, bound and ordered as ``ipcosim run
    SCENARIO --fmus native`` runs it (``options.out`` and ``options.fmi`` are not used).

    Raises
    ------
    IpcosimError
        An unknown scenario, or one the native flavour cannot run (one line).
    """
    from ipcosim.harness.api.engine import Prepared
    from ipcosim.harness.scenario.flavour import FlavourError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prepared = Prepared(options.scenario, parameter_set=options.parameter_set, fmus="native", warn=False,
                                fmu_dirs=list(options.fmu_dirs))
    except FlavourError as exc:
        raise ExportError(f"{NATIVE_ONLY}: {exc}") from None
    with prepared:
        execution = prepared.execution(set=options.set)
        spec = container_spec(prepared.system, [execution.instances[i].name for i in execution.order],
                              execution.multiples, execution.step_size,
                              options.model_identifier or identifier(prepared.scenario.name), execution.set)
        return dataclasses.replace(spec, start_time=execution.start_time, stop_time=execution.stop_time)


def _check_out(out: Path) -> None:
    if out.is_dir():
        raise UsageError(f"--out {out}: is a folder, not a file")
    if out.suffix != ".fmu":
        raise UsageError(f"--out {out}: the file name must end in .fmu")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise UsageError(f"--out {out}: cannot write there ({parent} is not a writable folder)"
                          if not parent.is_dir() or not os.access(parent, os.W_OK)
                          else f"--out {out}: the file is not writable")


def container_spec(system: System, order: list[str], multiples: dict[str, int], step: float, name: str,
                   set: Mapping[tuple[str, str], Any] | None = None) -> ContainerSpec:
    """The :class:`ContainerSpec` of a bound native system, stepped as the master would
    (``set``: parameter values by (component, parameter), as the execution holds them)."""
    set = dict(set or {})
    for (comp, var), value in set.items():
        if system.instance(comp).model.variables[var].causality != "parameter":
            raise ExportError(f"--set {comp}.{var}={value}: only parameters can be set for the export "
                              "(the FMU's inputs are set by its host)")
    setpoints = {i.name for i in system.instances if i.model.name == SETPOINT_MODEL}
    components = tuple(_component(inst, system, multiples[inst.name], setpoints,
                                  {var: value for (comp, var), value in set.items() if comp == inst.name})
                       for inst in system.instances)
    outputs = tuple((inst.name, v.name) for inst in system.instances if inst.name not in setpoints
                    for v in inst.outputs if v.type == "Real")
    description = (f"{system.scenario.name}: {system.scenario.description} The whole closed loop "
                   f"({', '.join(order)}) as one FMU (ipcosim export).").strip()
    return ContainerSpec(name=name, description=description, components=components, order=tuple(order),
                         step=step, outputs=outputs,
                         reference_description="reference position added to the setpoint's output "
                                               "(set the setpoint's amplitude to 0 to follow this input alone)")


def _component(inst: Instance, system: System, multiple: int, setpoints: set[str],
               values: dict[str, Any]) -> ComponentSpec:
    if inst.model.path is None:
        raise ExportError(f"component {inst.name}: no FMU file")
    if inst.interface != "CoSimulation":
        raise ExportError(f"component {inst.name}: runs as model exchange (integrated by the master); the exported "
                          "loop steps co-simulation FMUs only")
    for v in inst.connectors:
        if v.type != "Real":
            raise ExportError(f"component {inst.name}: connector {v.name} is of type {v.type}; the exported loop "
                              "connects Real variables only")
    inputs = []
    for v in inst.inputs:
        link = system.link_into(inst.name, v.name)
        if link is None:
            inputs.append(InputSpec(v.name))
        else:
            inputs.append(InputSpec(v.name, (link.src, link.src_var.name), link.factor, link.offset,
                                    add_reference=link.src in setpoints))
    return ComponentSpec(name=inst.name, fmu=Path(inst.model.path), multiple=multiple, inputs=tuple(inputs),
                         outputs=tuple(v.name for v in inst.outputs),
                         parameters={**{var.name: value for var, value in inst.parameters}, **values})
