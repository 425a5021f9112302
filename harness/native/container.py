"""A closed loop of native components as one FMI 2.0 co-simulation FMU (``ipcosim export``).

The FMU's C is the components' generated sources compiled together, with two hand-written
files shared by every exported loop (``c/container.c``, ``c/container.h``) and one generated
table (``container_table.c``: components, step order, step multiples, connections, the
container's variables). Nothing scenario-specific is written by hand.

Symbols are kept apart per component: each component is one translation unit
``<component>_unit.c`` (generated, four lines) that defines ``FMI2_FUNCTION_PREFIX`` (the FMI
headers' own scheme: every ``fmi2Xxx`` it defines becomes ``ipcosim_<component>_fmi2Xxx``) and
renames the model's one global, ``model_info``, to ``ipcosim_<component>_model_info``, then
``#include``\\ s the component's generated ``model.c`` (copied as ``<component>_model.c``) and the
shared single-model glue ``fmi2glue.c``. Everything else in those two files is ``static``. The
table reaches each component only through its prefixed FMI functions; the container's own
``fmi2Xxx`` (``container.c``) are the only unprefixed ones.

This module knows nothing of scenarios: :class:`ContainerSpec` says what to put together
(``ipcosim.harness.api.export`` builds it from a scenario the way the master would run it).
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import sys
import tempfile
import uuid
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping
from xml.etree import ElementTree

from ipcosim.errors import IpcosimError
from ipcosim.harness.native import cbuild, cgen, tracer

CONTAINER_FILES = ("container.c", "container.h", "fmi2glue.c", "model.h", "fmi2shared.h", "fmi2me.h")
_TYPE = {"Real": "VAR_REAL", "Integer": "VAR_INTEGER", "Boolean": "VAR_BOOLEAN"}
_FUNCTIONS = ("Instantiate", "FreeInstance", "SetupExperiment", "EnterInitializationMode",
              "ExitInitializationMode", "Terminate", "Reset", "GetReal", "SetReal", "SetInteger", "SetBoolean",
              "DoStep")
REFERENCE = "reference"


class ContainerError(IpcosimError, ValueError):
    """The loop cannot be exported as one FMU (names the component, variable or file)."""


@dataclass(frozen=True)
class InputSpec:
    """Where a component input takes its value: ``source`` = (component, output), or None for an
    input of the container named ``<component>.<input>``; ``add_reference`` adds the
    container's ``reference`` input to it."""

    name: str
    source: tuple[str, str] | None = None
    factor: float = 1.0
    offset: float = 0.0
    add_reference: bool = False


@dataclass(frozen=True)
class ComponentSpec:
    """One component: its native FMU, its step multiple, its Real inputs (with their sources)
    and outputs (read after each of its steps) and the parameter values the loop binds."""

    name: str
    fmu: Path
    multiple: int
    inputs: tuple[InputSpec, ...]
    outputs: tuple[str, ...]
    parameters: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ContainerSpec:
    """The loop: components, Gauss-Seidel step order, base step [s] and the outputs the
    container exposes as ``<component>.<output>``."""

    name: str
    description: str
    components: tuple[ComponentSpec, ...]
    order: tuple[str, ...]
    step: float
    outputs: tuple[tuple[str, str], ...]
    reference_description: str = ""
    max_init_iterations: int = 20
    start_time: float = 0.0
    stop_time: float | None = None  # the DefaultExperiment's, if given


@dataclass
class _Var:
    name: str
    vr: int
    causality: str
    variability: str
    type: str
    start: str | None
    unit: str | None
    description: str
    initial: str | None


class _Component:
    """A component's native FMU read: model description and generated ``model.c``."""

    def __init__(self, spec: ComponentSpec) -> None:
        self.spec = spec
        self.symbol = c_name(spec.name)
        try:
            with zipfile.ZipFile(spec.fmu) as z:
                root = ElementTree.fromstring(z.read("modelDescription.xml"))
                self.model_c = z.read("sources/model.c").decode()
        except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError) as exc:
            raise ContainerError(f"component {spec.name}: {spec.fmu} is not a native FMU with sources/model.c "
                                 f"({exc})") from None
        if root.get("generationTool") != "ipcosim.harness.native":
            raise ContainerError(f"component {spec.name}: {spec.fmu} is not a native FMU (ipcosim build --native)")
        self.guid = root.get("guid", "")
        self.model = root.get("modelName", "")
        self.units = {u.get("name"): u for u in root.iter("Unit")}
        self.vars: dict[str, _Var] = {}
        for sv in root.iter("ScalarVariable"):
            typed = next(iter(sv))
            self.vars[sv.get("name")] = _Var(
                sv.get("name"), int(sv.get("valueReference")), sv.get("causality", "local"),
                sv.get("variability", "continuous"), typed.tag, typed.get("start"), typed.get("unit"),
                sv.get("description", ""), sv.get("initial"))

    def var(self, name: str, causality: str) -> _Var:
        v = self.vars.get(name)
        if v is None or v.causality != causality or v.type != "Real":
            raise ContainerError(f"component {self.spec.name} ({self.model}): no Real {causality} named {name!r}")
        return v


def c_name(component: str) -> str:
    """The C identifier part for a component name."""
    return re.sub(r"\W", "_", component)


def _start(value: Any, typ: str, default: str | None) -> float:
    if value is None:
        if default is None:
            return 0.0
        value = {"true": 1, "false": 0}.get(default, default)
    return float(value)


class _Layout:
    """The container's variables (value references 0, 1, ...; slots = value references)."""

    def __init__(self, spec: ContainerSpec, comps: dict[str, _Component]) -> None:
        self.vars: list[_Var] = []
        self.start: list[float] = []
        self.slot: dict[str, int] = {}
        self.units: dict[str, ElementTree.Element] = {}
        if any(i.add_reference for c in spec.components for i in c.inputs):
            self._add(_Var(REFERENCE, 0, "input", "continuous", "Real", "0.0", "m", spec.reference_description,
                           None), 0.0, comps[next(c.name for c in spec.components for i in c.inputs
                                                   if i.add_reference)], "m")
        for c in spec.components:
            for i in c.inputs:
                if i.source is None:
                    v = comps[c.name].var(i.name, "input")
                    self._add(_Var(f"{c.name}.{i.name}", 0, "input", v.variability, "Real", v.start, v.unit,
                                   v.description, None), _start(None, "Real", v.start), comps[c.name], v.unit)
        for comp, out in spec.outputs:
            v = comps[comp].var(out, "output")
            self._add(_Var(f"{comp}.{out}", 0, "output", v.variability, "Real", None, v.unit, v.description,
                           "calculated"), 0.0, comps[comp], v.unit)
        for c in spec.components:
            unknown = set(c.parameters) - {n for n, v in comps[c.name].vars.items() if v.causality == "parameter"}
            if unknown:
                raise ContainerError(f"component {c.name} ({comps[c.name].model}): no parameter named "
                                     f"{sorted(unknown)[0]!r}")
            for v in comps[c.name].vars.values():
                if v.causality != "parameter":
                    continue
                if v.type not in _TYPE:
                    raise ContainerError(f"component {c.name}: parameter {v.name} of type {v.type} is not supported")
                value = _start(c.parameters.get(v.name), v.type, v.start)
                text = (str(int(value)) if v.type == "Integer" else ("true" if value else "false")
                        if v.type == "Boolean" else repr(value))
                self._add(_Var(f"{c.name}.{v.name}", 0, "parameter", "fixed", v.type, text, v.unit, v.description,
                               "exact"), value, comps[c.name], v.unit)

    def _add(self, v: _Var, start: float, comp: _Component, unit: str | None) -> None:
        v.vr = len(self.vars)
        self.slot[v.name] = v.vr
        self.vars.append(v)
        self.start.append(start)
        if unit and unit not in self.units:
            if unit in comp.units:
                self.units[unit] = comp.units[unit]
            elif unit == "m":
                el = ElementTree.Element("Unit", {"name": "m"})
                ElementTree.SubElement(el, "BaseUnit", {"m": "1"})
                self.units[unit] = el
            else:
                raise ContainerError(f"component {comp.spec.name}: unit {unit!r} has no definition")


def table_c(spec: ContainerSpec, comps: dict[str, _Component], lay: _Layout, gid: str) -> str:
    """``container_table.c``: the loop as data for ``container.c``."""
    names = [c.name for c in spec.components]
    pos = {n: k for k, n in enumerate(names)}
    lines = ["/* The exported loop's table: generated by ipcosim.harness.native.container (do not edit). */",
             '#include "container.h"', ""]
    rows = []
    for k, c in enumerate(spec.components):
        lines += _component_c(spec, k, comps[c.name], lay, pos)
        rows.append(f'    {{"{c.name}", "{comps[c.name].guid}", &fmi_{k}, {c.multiple}, {len(c.outputs)}, out_{k}, '
                    f"{len(c.inputs)}, in_{k}, src_{k}}},")
    vars_rows = [f'    {{{v.vr}u, {v.vr}, {_TYPE[v.type]}, {dict(parameter=1, input=2).get(v.causality, 0)}, '
                 f'"{v.name}"}},' for v in lay.vars]
    params = [f"    {{{lay.slot[f'{c.name}.{v.name}']}, {k}, {v.vr}u, {_TYPE[v.type]}}},"
              for k, c in enumerate(spec.components) for v in comps[c.name].vars.values() if v.causality == "parameter"]
    outputs = [f"    {{{lay.slot[f'{c}.{o}']}, {pos[c]}, {spec.components[pos[c]].outputs.index(o)}}},"
               for c, o in spec.outputs]
    step_ns = round(spec.step * 1e9)
    lines += [
        f"static const ContainerComponent components[{len(rows)}] = {{", *rows, "};", "",
        f"static const int order[{len(names)}] = {{{_join(pos[n] for n in spec.order)}}};", "",
        f"static const ModelVariable variables[{len(vars_rows)}] = {{", *vars_rows, "};", "",
        f"static const int by_vr[{len(lay.vars)}] = {{{_join(range(len(lay.vars)))}}};", "",
        f"static const double start_values[{len(lay.start)}] = {{",
        *(f"    {tracer.c_double(x)}," for x in lay.start), "};", "",
        f"static const ParameterLink parameters[{max(len(params), 1)}] = {{", *(params or ["    {0, 0, 0u, 0},"]),
        "};", "",
        f"static const OutputLink outputs[{max(len(outputs), 1)}] = {{", *(outputs or ["    {0, 0, 0},"]), "};", "",
        "const ContainerInfo container_info = {",
        f'    "{spec.name}", "{gid}", variables, {len(vars_rows)}, by_vr, {len(lay.vars)}, {len(lay.start)}, '
        "start_values,",
        f"    components, {len(rows)}, order, parameters, {len(params)}, outputs, {len(outputs)},",
        f"    {step_ns}LL, {tracer.c_double(float(spec.step))}, {spec.max_init_iterations}}};", ""]
    return "\n".join(lines)


def _component_c(spec: ContainerSpec, k: int, comp: _Component, lay: _Layout, pos: dict[str, int]) -> list[str]:
    """Component ``k``'s part of the table: its prefixed FMI functions, value references, input sources."""
    c = spec.components[k]
    p = f"ipcosim_{comp.symbol}_fmi2"
    lines = [f"/* {c.name}: {comp.model} */"]
    lines += [f"fmi2{f}TYPE {p}{f};" for f in _FUNCTIONS]
    lines += [f"static const ComponentFunctions fmi_{k} = {{", *(f"    {p}{f}," for f in _FUNCTIONS), "};"]
    outs = [comp.var(o, "output").vr for o in c.outputs]
    ins = [comp.var(i.name, "input").vr for i in c.inputs]
    lines.append(f"static const fmi2ValueReference out_{k}[{max(len(outs), 1)}] = {{{_join(outs)}}};")
    lines.append(f"static const fmi2ValueReference in_{k}[{max(len(ins), 1)}] = {{{_join(ins)}}};")
    src = []
    for i in c.inputs:
        add = lay.slot[REFERENCE] if i.add_reference else -1
        if i.source is None:
            src.append(f"    {{SOURCE_INPUT, -1, {lay.slot[f'{c.name}.{i.name}']}, 1.0, 0.0, {add}}},")
            continue
        sc, so = i.source
        src_spec = spec.components[pos[sc]]
        if so not in src_spec.outputs:
            raise ContainerError(f"component {c.name}: input {i.name} reads {sc}.{so}, which is not among "
                                 f"{sc}'s outputs read by the loop")
        src.append(f"    {{SOURCE_OUTPUT, {pos[sc]}, {src_spec.outputs.index(so)}, "
                   f"{tracer.c_double(float(i.factor))}, {tracer.c_double(float(i.offset))}, {add}}},")
    return lines + [f"static const InputSource src_{k}[{max(len(src), 1)}] = {{",
                    *(src or ["    {SOURCE_INPUT, -1, 0, 1.0, 0.0, -1},"]), "};", ""]


def _join(items: Any) -> str:
    return ", ".join(str(x) for x in items) or "0"


def unit_c(comp: _Component) -> str:
    """``<component>_unit.c``: the component's model and the single-model glue under its prefix."""
    return (f"/* Component {comp.spec.name} ({comp.model}) under the prefix ipcosim_{comp.symbol}_: generated by "
            "ipcosim.harness.native.container (do not edit). */\n"
            '#include "fmi2Functions.h"\n'
            "#undef fmi2FullName\n"
            "#define IPCOSIM_PASTE(a, b) a##b\n"
            f"#define fmi2FullName(name) IPCOSIM_PASTE(ipcosim_{comp.symbol}_, name)\n"
            f"#define model_info ipcosim_{comp.symbol}_model_info\n"
            f'#include "{comp.symbol}_model.c"\n'
            '#include "fmi2glue.c"\n')


def _check(spec: ContainerSpec) -> None:
    names = [c.name for c in spec.components]
    symbols = [c_name(n) for n in names]
    if len(set(symbols)) != len(symbols):
        raise ContainerError(f"component names {names} do not give distinct C identifiers")
    if "fmi2" in symbols:  # the FMI 3.0 container's own prefix (fmi3container.c)
        raise ContainerError(f"component name {names[symbols.index('fmi2')]!r} is reserved for the container itself")
    if sorted(spec.order) != sorted(names):
        raise ContainerError(f"step order {list(spec.order)} is not an order of the components {names}")
    step_ns = round(spec.step * 1e9)
    if not (spec.step > 0 and step_ns > 0 and abs(step_ns - spec.step * 1e9) <= 1e-6 * spec.step * 1e9):
        raise ContainerError(f"step {spec.step!r} s: the exported loop needs a step of a whole number of nanoseconds")


def write_sources(spec: ContainerSpec, dest: Path, variant: cbuild.Variant = cbuild.VARIANTS["2"]
                  ) -> tuple[list[str], str, _Layout, dict[str, _Component]]:
    """Write ``sources/`` of the container into ``dest``: (listed C files, GUID, layout, components)."""
    _check(spec)
    comps = {c.name: _Component(c) for c in spec.components}
    lay = _Layout(spec, comps)
    dest.mkdir(parents=True, exist_ok=True)
    cbuild.copy_glue(dest, (*CONTAINER_FILES, variant.container_glue), variant)
    files = ["container_table.c", variant.container_glue]
    digest = hashlib.sha256()
    for c in spec.components:
        comp = comps[c.name]
        (dest / f"{comp.symbol}_model.c").write_text(comp.model_c)
        (dest / f"{comp.symbol}_unit.c").write_text(unit_c(comp))
        files.append(f"{comp.symbol}_unit.c")
        digest.update(comp.model_c.encode())
    for name in CONTAINER_FILES:
        digest.update((cbuild.C_DIR / name).read_bytes())
    digest.update(table_c(spec, comps, lay, "").encode())
    gid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"ipcosim-export/{spec.name}/{digest.hexdigest()}")) + "}"
    (dest / "container_table.c").write_text(table_c(spec, comps, lay, gid))
    return files, gid, lay, comps


def model_description(spec: ContainerSpec, gid: str, files: list[str], lay: _Layout) -> bytes:
    """The container's FMI 2.0 model description."""
    root = cgen.description_root(spec.name, gid, "ipcosim.harness.native.container", spec.description, files)
    if lay.units:
        ud = ElementTree.SubElement(root, "UnitDefinitions")
        for name in sorted(lay.units):
            ud.append(lay.units[name])
    cgen.log_categories(root)
    experiment = {"startTime": repr(float(spec.start_time)), "stepSize": repr(float(spec.step))}
    if spec.stop_time is not None:
        experiment["stopTime"] = repr(float(spec.stop_time))
    ElementTree.SubElement(root, "DefaultExperiment", experiment)
    mv = ElementTree.SubElement(root, "ModelVariables")
    for v in lay.vars:
        attrs = {"name": v.name, "valueReference": str(v.vr), "causality": v.causality,
                 "variability": v.variability}
        if v.description:
            attrs["description"] = v.description
        if v.initial:
            attrs["initial"] = v.initial
        sv = ElementTree.SubElement(mv, "ScalarVariable", attrs)
        tattrs = {}
        if v.start is not None and v.causality in ("input", "parameter"):
            tattrs["start"] = v.start
        if v.unit and v.type == "Real":
            tattrs["unit"] = v.unit
        ElementTree.SubElement(sv, v.type, tattrs)
    ms = ElementTree.SubElement(root, "ModelStructure")
    outs = ElementTree.SubElement(ms, "Outputs")
    # Outputs are the values after the last step: setting an input changes them only through
    # a step (no direct feedthrough).
    for v in lay.vars:
        if v.causality == "output":
            ElementTree.SubElement(outs, "Unknown", {"index": str(v.vr + 1), "dependencies": ""})
    init = ElementTree.SubElement(ms, "InitialUnknowns")
    for v in lay.vars:
        if v.causality == "output":
            ElementTree.SubElement(init, "Unknown", {"index": str(v.vr + 1)})
    return cgen.xml_bytes(root)


def build_container(spec: ContainerSpec, out: Path | str, cc: str | None = None, fmi: str = "2") -> Path:
    """Generate, compile and pack the container FMU (FMI ``fmi``: ``"2"`` or ``"3"``) into ``out``;
    returns ``out``. It carries a ``win64`` DLL and an ``aarch64`` library beside the ``linux64`` one when
    their cross compilers are found (else one line on stderr says which binary it lacks).

    Raises
    ------
    ContainerError
        No C compiler (the container is useful only compiled), a component that is not a
        native FMU, an unwritable ``out``.
    cbuild.NativeBuildError
        The compiler failed on the sources.
    """
    compilers = cbuild.Compilers.find().with_linux64(cc)
    if compilers.linux64 is None:
        raise ContainerError("no C compiler found (set CC, or install gcc or clang): the exported FMU needs one")
    for line in cbuild.missing_compilers(compilers, "ipcosim export"):
        print(line, file=sys.stderr)
    variant = cbuild.VARIANTS[fmi]
    out = Path(out)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "fmu"
        files, gid, lay, comps = write_sources(spec, root / "sources", variant)
        cbuild.write_descriptions(root, model_description(spec, gid, files, lay), spec.name, files, variant)
        cbuild.compile_binaries(root, files, spec.name, variant, compilers)
        (root / "documentation").mkdir()
        (root / "documentation" / "index.txt").write_text(_readme(spec, comps, files))
        tmp_fmu = Path(tmp) / "out.fmu"
        cbuild.pack(root, tmp_fmu)
        staged = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        try:  # beside the target, then renamed: never half an FMU at --out
            shutil.copyfile(tmp_fmu, staged)
            os.replace(staged, out)
        except OSError as exc:
            raise ContainerError(f"--out {out}: cannot write the FMU ({exc.strerror or exc})") from None
        finally:
            staged.unlink(missing_ok=True)
    return out


def _readme(spec: ContainerSpec, comps: dict[str, _Component], files: list[str]) -> str:
    parts = ", ".join(f"{c.name} ({comps[c.name].model}, every {c.multiple} step(s))" for c in spec.components)
    return (f"{spec.name}: {spec.description}\n\nComponents, in Gauss-Seidel step order {' -> '.join(spec.order)}: "
            f"{parts}. Base step {spec.step!r} s; the communication step must be a whole multiple of it.\n"
            + cbuild.compile_line(files) + "\n")
