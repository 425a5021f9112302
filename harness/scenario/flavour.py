"""FMU flavours: run a scenario on the Python FMUs (``build/fmus``) or the native ones (``build/fmus-native``).

A scenario's parameter sets are written in the Python flavour's parameter names. On the native
flavour, each component's bound values are translated by ``ipcosim.harness.native.redesign`` (the
same Python design code computes the gains and matrices the native FMU takes as parameters),
and a ``--set`` on a parameter the native FMU lacks is an error that names the flavour.
"""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from ipcosim.errors import IpcosimError

if TYPE_CHECKING:  # the command line reads the flavours' names without loading the SSP reader
    from ipcosim.harness.scenario.structure import Scenario

FLAVOURS = ("python", "native")
#: ``--fmus`` of the studies: ``auto`` (the default) takes the native FMUs when they are built and
#: can run the study, else the Python ones.
STUDY_FLAVOURS = ("auto", *FLAVOURS)


class FlavourError(IpcosimError, ValueError):
    """A scenario cannot run on the chosen FMU flavour (names the component and the flavour)."""


def native_fmu_dir() -> Path:
    """Where ``ipcosim build --native`` puts the native FMUs."""
    from ipcosim.harness.support.paths import BUILD_DIR
    return Path(BUILD_DIR) / "fmus-native"


def check_flavour(fmus: str) -> str:
    """``fmus`` if it is a known flavour, else FlavourError."""
    if fmus not in FLAVOURS:
        raise FlavourError(f"--fmus {fmus}: expected one of {', '.join(FLAVOURS)}")
    return fmus


def to_native(scenario: Scenario) -> tuple[Scenario, dict[str, dict[str, Any]]]:
    """The scenario with every component's bindings redesigned for its native FMU.

    Returns the new scenario and ``{component: {Python parameter: bound value}}``.

    Raises
    ------
    FlavourError
        A component whose FMU is not a native ipcosim FMU, or a binding the redesign rejects.
    """
    from ipcosim.harness.native.redesign import native_info, redesign
    from ipcosim.harness.scenario.structure import Parameter, ParameterSet

    components = []
    python_values: dict[str, dict[str, Any]] = {}
    for comp in scenario.components:
        info = native_info(comp.fmu) if comp.fmu is not None else None
        if info is None:
            from ipcosim.harness.native.cbuild import model_names

            model = Path(str(comp.source)).stem
            hint = (f"{model} has no native flavour (docs/native.md lists the models)" if model not in model_names()
                    else "run `ipcosim build --native`")
            raise FlavourError(f"{scenario.origin}: component {comp.name!r}: no native flavour of {comp.source} "
                               f"(found {comp.fmu}); {hint}")
        values = {p.name: p.value for pset in comp.bindings for p in pset.parameters}
        python_values[comp.name] = values
        try:
            native = redesign(info, values)
        except Exception as exc:  # noqa: BLE001 -- the design's own error, named for the component
            raise FlavourError(f"{scenario.origin}: component {comp.name!r} (native {info['model']}): {exc}") from None
        params = tuple(Parameter(name, _type(comp, name, value), value) for name, value in native.items())
        source = comp.bindings[0].source if comp.bindings else None
        name = comp.bindings[0].name if comp.bindings else "native"
        components.append(dataclasses.replace(comp, bindings=(ParameterSet(name, params, source),) if params else ()))
    return dataclasses.replace(scenario, components=tuple(components)), python_values


def _type(comp: Any, name: str, value: Any) -> str:
    for pset in comp.bindings:
        for p in pset.parameters:
            if p.name == name:
                return p.type
    return "Integer" if isinstance(value, int) and not isinstance(value, bool) else "Real"


def native_set(system: Any, set: Mapping[str, Any], python_values: Mapping[str, Mapping[str, Any]]
                     ) -> dict[str, Any]:
    """A run's ``set`` (``--set``) for native FMUs: checked against the native variables, redesigned where needed.

    Raises
    ------
    FlavourError
        Naming the component, the parameter and the flavour.
    """
    from ipcosim.harness.native.redesign import NativeParameterError, check_settable, native_info, redesign
    from ipcosim.harness.scenario.rebuild import rebuild_hint

    by_comp: dict[str, dict[str, Any]] = {}
    for key, value in set.items():
        comp, _, var = str(key).partition(".")
        by_comp.setdefault(comp, {})[var] = value
    out = dict(set)
    for comp, values in by_comp.items():
        try:
            inst = system.instance(comp)
        except KeyError:
            continue  # with_set reports the unknown component
        info = native_info(inst.model.path) if inst.model.path else None
        if info is None:
            continue
        known = {n for n, v in inst.model.variables.items() if v.causality in ("parameter", "input")}
        try:
            check_settable(info, info["model"], sorted(values), known)
        except NativeParameterError as exc:
            hint = "" if exc.design_only else rebuild_hint(inst.model)
            raise FlavourError(f"--set {comp}.{exc.parameter}: component {comp!r}: {exc}{hint}") from None
        if info["role"] in ("law", "plant") and any(v.causality == "parameter"
                                                    for n, v in inst.model.variables.items() if n in values):
            merged = {**python_values.get(comp, {}), **{k: float(v) for k, v in values.items()}}
            try:
                native = redesign(info, merged)
            except Exception as exc:  # noqa: BLE001 -- the design's own error, named for the component
                raise FlavourError(f"--set on component {comp!r} (native {info['model']}): {exc}") from None
            for name, value in native.items():
                if name in known and inst.model.variables[name].causality == "parameter":
                    out[f"{comp}.{name}"] = value
    return out


def write_native_folder(scenario_name: str, dest: Path | str) -> Path:
    """A copy of scenario folder ``scenario_name`` that any SSP tool runs on the native FMUs.

    ``dest/resources/`` gets the native FMUs and every ``.ssv`` a component binds is rewritten
    with that component's redesigned native values (:func:`to_native`).
    """
    from xml.sax.saxutils import quoteattr

    from ipcosim.harness.scenario.ssp import load_scenario

    dest = Path(dest)
    scenario, _ = to_native(load_scenario(scenario_name, fmu_dirs=[native_fmu_dir()]))
    src = scenario.location if scenario.location.is_dir() else scenario.location.parent
    shutil.copytree(src, dest, dirs_exist_ok=True)
    (dest / "resources").mkdir(exist_ok=True)
    for comp in scenario.components:
        assert comp.fmu is not None
        shutil.copy(comp.fmu, dest / comp.source)
        for pset in comp.bindings:
            if pset.source and pset.source.endswith(".ssv"):
                rows = [f'    <ssv:Parameter name={quoteattr(p.name)}><ssv:{p.type} value="{p.value!r}"/>'
                        f'</ssv:Parameter>' for p in pset.parameters]
                (dest / pset.source).write_text(
                    '<?xml version="1.0" encoding="UTF-8"?>\n'
                    '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
                    f'version="1.0" name={quoteattr(pset.name)}>\n  <ssv:Parameters>\n' + "\n".join(rows)
                    + "\n  </ssv:Parameters>\n</ssv:ParameterSet>\n")
    return dest
