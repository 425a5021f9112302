"""Test FMUs the project did not design for itself: small C models (``tests/data/cfmu/*.c``)
with a plain FMI 2.0 or FMI 3.0 co-simulation glue, compiled at test time with the system C
compiler against the FMI headers FMPy ships (``fmpy/c-code``), and packed as ``.fmu`` files with
a model description written here from one variable table per model.

Models (see each C file): ``Stair`` (Integer counter that ends the simulation itself),
``PassThrough`` (Real, Integer, Boolean and String in and out through a parameter of each
type), ``BouncingBall`` (events inside the step), ``Counter`` (multi-rate: counts its steps,
integrates its input), ``PassThrough3`` and ``Source3`` (FMI 3.0 with the sized types), ``Ints3``
(FMI 3.0: every integer type from Int8 to UInt64, in and out, and 64-bit parameters).

Model exchange (``me_model.h``, glue ``fmi2_me.h`` / ``fmi3_me.h``; :func:`fmi3_variant` for FMI 3.0):
``Decay`` (``x' = -k x + u``, also co-simulation), ``VanDerPol``, ``BouncingBallME`` (an event
indicator per impact) and ``Staircase`` (time events, and the end of the simulation at a limit).
"""
from __future__ import annotations

import re
import shutil
import subprocess
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

SOURCES = Path(__file__).parent / "data" / "cfmu"
#: FMI 3.0 value reference base of each value array (see fmi3_glue.c).
FMI3_BASE = {"r": 0, "i": 100, "b": 200, "s": 300}


@dataclass(frozen=True)
class Var:
    """One variable: ``array`` r/i/b/s and ``index`` into it (the FMI 2.0 value reference)."""

    name: str
    type: str  # FMI 2.0 type (Real, Integer, Boolean, String) or FMI 3.0 type (Float64, Int16...)
    causality: str
    array: str
    index: int
    start: str | None = None
    variability: str | None = None
    initial: str | None = None
    depends: tuple[str, ...] | None = None  # outputs: direct dependencies (None: none)
    derivative: str | None = None  # the state this variable is the derivative of (model exchange)


@dataclass(frozen=True)
class Spec:
    name: str
    source: str
    fmi: str  # "2.0" or "3.0"
    variables: tuple[Var, ...]
    can_handle_variable_step: bool = True
    step: float | None = None
    stop: float | None = None
    #: The interfaces offered: ``cs`` co-simulation, ``me`` model exchange (fmi2_me.h, fmi3_me.h).
    interfaces: tuple[str, ...] = ("cs",)
    #: Model exchange: the event indicator variables, in the order of the model's INDICATORS.
    indicators: tuple[str, ...] = ()
    tolerance: float | None = None

    @property
    def states(self) -> tuple[str, ...]:
        """The continuous states, in the order of their derivatives (the model's STATES)."""
        return tuple(v.derivative for v in self.variables if v.derivative)


def _out(name: str, type_: str, array: str, index: int, depends: tuple[str, ...] | None = None,
         initial: str | None = None, start: str | None = None, variability: str | None = None) -> Var:
    return Var(name, type_, "output", array, index, start, variability, initial, depends)


def _in(name: str, type_: str, array: str, index: int, start: str) -> Var:
    return Var(name, type_, "input", array, index, start)


def _local(name: str, array: str, index: int, derivative: str | None = None) -> Var:
    return Var(name, "Real", "local", array, index, derivative=derivative)


def _par(name: str, type_: str, array: str, index: int, start: str) -> Var:
    return Var(name, type_, "parameter", array, index, start, "fixed" if type_ != "String" else "fixed", "exact")


STAIR = Spec("Stair", "stair.c", "2.0", (
    _out("counter", "Integer", "i", 0, (), variability="discrete"),
    _out("height", "Real", "r", 0, (), variability="discrete"),
    _par("limit", "Integer", "i", 1, "10"), _par("end_simulation", "Boolean", "b", 0, "true"),
    _par("end_midstep", "Boolean", "b", 1, "false"),
), step=0.1, stop=2.0)

PASSTHROUGH = Spec("PassThrough", "passthrough.c", "2.0", (
    _in("real_in", "Real", "r", 0, "0.0"), _in("int_in", "Integer", "i", 0, "0"),
    _in("bool_in", "Boolean", "b", 0, "false"), _in("string_in", "String", "s", 0, ""),
    _out("real_out", "Real", "r", 1, ("real_in",)),
    _out("int_out", "Integer", "i", 1, ("int_in",), variability="discrete"),
    _out("bool_out", "Boolean", "b", 1, ("bool_in",), variability="discrete"),
    _out("string_out", "String", "s", 1, ("string_in",), variability="discrete"),
    _par("gain", "Real", "r", 2, "1.0"), _par("offset", "Integer", "i", 2, "0"),
    _par("invert", "Boolean", "b", 2, "false"), _par("prefix", "String", "s", 2, ""),
), step=0.1, stop=1.0)

BOUNCING_BALL = Spec("BouncingBall", "bouncing_ball.c", "2.0", (
    _out("h", "Real", "r", 0, (), initial="exact", start="1.0"),
    _out("v", "Real", "r", 1, (), initial="exact", start="0.0"),
    _par("g", "Real", "r", 2, "9.81"), _par("e", "Real", "r", 3, "0.7"),
    _out("bounces", "Integer", "i", 0, (), variability="discrete"),
    _out("falling", "Boolean", "b", 0, (), variability="discrete"),
), step=0.01, stop=3.0)


def counter(name: str = "Counter", variable_step: bool = True, step: float | None = None) -> Spec:
    """The multi-rate test component, with or without canHandleVariableCommunicationStepSize."""
    return Spec(name, "counter.c", "2.0", (
        _in("u", "Real", "r", 0, "0.0"),
        _out("reached", "Real", "r", 1, ()), _out("integral", "Real", "r", 2, ()),
        _out("steps", "Integer", "i", 0, (), variability="discrete"),
    ), can_handle_variable_step=variable_step, step=step)


PASSTHROUGH3 = Spec("PassThrough3", "passthrough3.c", "3.0", (
    _in("f64_in", "Float64", "r", 0, "0"), _out("f64_out", "Float64", "r", 1, ("f64_in",)),
    _in("f32_in", "Float32", "r", 2, "0"), _out("f32_out", "Float32", "r", 3, ("f32_in",)),
    _in("i32_in", "Int32", "i", 0, "0"), _out("i32_out", "Int32", "i", 1, ("i32_in",), variability="discrete"),
    _in("i16_in", "Int16", "i", 2, "0"), _out("i16_out", "Int16", "i", 3, ("i16_in",), variability="discrete"),
    _in("u8_in", "UInt8", "i", 4, "0"), _out("u8_out", "UInt8", "i", 5, ("u8_in",), variability="discrete"),
    _in("i64_in", "Int64", "i", 6, "0"), _out("i64_out", "Int64", "i", 7, ("i64_in",), variability="discrete"),
    _in("bool_in", "Boolean", "b", 0, "false"),
    _out("bool_out", "Boolean", "b", 1, ("bool_in",), variability="discrete"),
    _in("string_in", "String", "s", 0, ""),
    _out("string_out", "String", "s", 1, ("string_in",), variability="discrete"),
), step=0.1, stop=1.0)

SOURCE3 = Spec("Source3", "source3.c", "3.0", (
    _out("y", "Float64", "r", 0, ()), _par("amplitude", "Float64", "r", 1, "1.0"),
    _par("step_time", "Float64", "r", 2, "0.5"),
    _out("count", "Int32", "i", 0, (), variability="discrete"),
    _out("on", "Boolean", "b", 0, (), variability="discrete"),
    _out("label", "String", "s", 0, (), variability="discrete"),
), step=0.1, stop=1.0)

#: The FMI 3.0 integer types and the short names of Ints3's connectors of each.
INT_TYPES = (("i8", "Int8"), ("u8", "UInt8"), ("i16", "Int16"), ("u16", "UInt16"), ("i32", "Int32"),
             ("u32", "UInt32"), ("i64", "Int64"), ("u64", "UInt64"))

INTS3 = Spec("Ints3", "ints3.c", "3.0", tuple(
    v for k, (short, t) in enumerate(INT_TYPES)
    for v in (_in(f"{short}_in", t, "i", 2 * k, "0"),
              _out(f"{short}_out", t, "i", 2 * k + 1, (f"{short}_in",), variability="discrete"))
) + (_par("p64", "Int64", "i", 16, "0"), _par("pu64", "UInt64", "i", 17, "0"),
     _out("p64_out", "Int64", "i", 18, (), variability="discrete"),
     _out("pu64_out", "UInt64", "i", 19, (), variability="discrete")), step=0.1, stop=0.3)

STAIR3 = Spec("Stair3", "stair.c", "3.0", (
    _out("counter", "Int32", "i", 0, (), variability="discrete"),
    _out("height", "Float64", "r", 0, (), variability="discrete"),
    _par("limit", "Int32", "i", 1, "10"),
), step=0.1, stop=2.0)


#: Model exchange (me_model.h): x' = -k x + u, also as co-simulation (its exact step).
DECAY = Spec("Decay", "decay.c", "2.0", (
    _out("x", "Real", "r", 0, (), initial="exact", start="1.0"), _par("k", "Real", "r", 1, "1.0"),
    _in("u", "Real", "r", 2, "0.0"), _local("der(x)", "r", 3, "x"),
), step=0.01, stop=2.0, interfaces=("cs", "me"))

VANDERPOL = Spec("VanDerPol", "vanderpol.c", "2.0", (
    _out("x0", "Real", "r", 0, (), initial="exact", start="2.0"),
    _out("x1", "Real", "r", 1, (), initial="exact", start="0.0"), _par("mu", "Real", "r", 2, "1.0"),
    _local("der(x0)", "r", 3, "x0"), _local("der(x1)", "r", 4, "x1"),
), step=0.01, stop=10.0, interfaces=("me",))

BOUNCING_BALL_ME = Spec("BouncingBallME", "ball_me.c", "2.0", (
    _out("h", "Real", "r", 0, (), initial="exact", start="1.0"),
    _out("v", "Real", "r", 1, (), initial="exact", start="0.0"),
    _par("g", "Real", "r", 2, "9.81"), _par("e", "Real", "r", 3, "0.7"),
    _local("der(h)", "r", 4, "h"), _local("der(v)", "r", 5, "v"), _local("impact", "r", 6),
    _out("last_bounce", "Real", "r", 7, (), variability="discrete"),
    _out("bounces", "Integer", "i", 0, (), variability="discrete"),
    _out("resting", "Boolean", "b", 0, (), variability="discrete"),
), step=0.01, stop=2.0, interfaces=("me",), indicators=("impact",))

STAIRCASE = Spec("Staircase", "staircase.c", "2.0", (
    _par("period", "Real", "r", 0, "0.15"),
    _out("height", "Real", "r", 1, (), variability="discrete"),
    _out("last_tick", "Real", "r", 2, (), variability="discrete"),
    _out("counter", "Integer", "i", 0, (), variability="discrete"), _par("limit", "Integer", "i", 1, "0"),
), step=0.1, stop=1.0, interfaces=("me",))

_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32"}


def fmi3_variant(spec: Spec) -> Spec:
    """The FMI 3.0 variant of an FMI 2.0 model-exchange test model (same C model, name + ``3``)."""
    variables = tuple(Var(v.name, _FMI3_TYPES.get(v.type, v.type), v.causality, v.array, v.index, v.start,
                          v.variability, v.initial, v.depends, v.derivative) for v in spec.variables)
    return Spec(spec.name + "3", spec.source, "3.0", variables, spec.can_handle_variable_step, spec.step, spec.stop,
                spec.interfaces, spec.indicators, spec.tolerance)


# --------------------------------------------------------------------------- model descriptions
def _vr(spec: Spec, v: Var) -> int:
    return v.index if spec.fmi == "2.0" else FMI3_BASE[v.array] + v.index


def _experiment(spec: Spec) -> str:
    attrs = "".join(f' {k}="{x!r}"' for k, x in (("stopTime", spec.stop), ("stepSize", spec.step),
                                                 ("tolerance", spec.tolerance)) if x is not None)
    return f"  <DefaultExperiment startTime=\"0.0\"{attrs}/>\n" if attrs else ""


def model_description2(spec: Spec, guid: str) -> str:
    flag = "true" if spec.can_handle_variable_step else "false"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="2.0" modelName="{spec.name}" guid="{guid}" '
             f'variableNamingConvention="flat" numberOfEventIndicators="{len(spec.indicators)}">',
             f'  <ModelExchange modelIdentifier="{spec.name}"/>' if "me" in spec.interfaces else "",
             f'  <CoSimulation modelIdentifier="{spec.name}" canHandleVariableCommunicationStepSize="{flag}"/>'
             if "cs" in spec.interfaces else "",
             _experiment(spec).rstrip("\n"), "  <ModelVariables>"]
    index = {v.name: k for k, v in enumerate(spec.variables, start=1)}
    outputs = []
    for k, v in enumerate(spec.variables, start=1):
        attrs = f'name="{v.name}" valueReference="{_vr(spec, v)}" causality="{v.causality}"'
        variability = v.variability or ("fixed" if v.causality == "parameter" else
                                        "continuous" if v.type == "Real" else "discrete")
        attrs += f' variability="{variability}"'
        if v.initial:
            attrs += f' initial="{v.initial}"'
        start = f' start="{escape(v.start)}"' if v.start is not None and (v.causality != "output" or v.initial) else ""
        if v.derivative:
            start += f' derivative="{index[v.derivative]}"'
        lines.append(f"    <ScalarVariable {attrs}><{v.type}{start}/></ScalarVariable>")
        if v.causality == "output":
            outputs.append((k, v))
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    derivatives = [k for k, v in enumerate(spec.variables, start=1) if v.derivative]
    if outputs:
        lines.append("    <Outputs>")
        for k, v in outputs:
            deps = " ".join(str(index[d]) for d in (v.depends or ()))
            lines.append(f'      <Unknown index="{k}" dependencies="{deps}"/>')
        lines.append("    </Outputs>")
    if derivatives:
        lines.append("    <Derivatives>")
        lines.extend(f'      <Unknown index="{k}"/>' for k in derivatives)
        lines.append("    </Derivatives>")
    if outputs or derivatives:
        calculated = sorted([k for k, v in outputs if v.initial != "exact"] + derivatives)
        if calculated:
            lines.append("    <InitialUnknowns>")
            lines.extend(f'      <Unknown index="{k}" dependencies=""/>' for k in calculated)
            lines.append("    </InitialUnknowns>")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(x for x in lines if x) + "\n"


def model_description3(spec: Spec, token: str) -> str:
    flag = "true" if spec.can_handle_variable_step else "false"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="3.0" modelName="{spec.name}" instantiationToken="{token}">',
             f'  <ModelExchange modelIdentifier="{spec.name}"/>' if "me" in spec.interfaces else "",
             f'  <CoSimulation modelIdentifier="{spec.name}" canHandleVariableCommunicationStepSize="{flag}" '
             f'hasEventMode="false"/>' if "cs" in spec.interfaces else "",
             _experiment(spec).rstrip("\n"), "  <ModelVariables>",
             '    <Float64 name="time" valueReference="999" causality="independent" variability="continuous"/>']
    for v in spec.variables:
        attrs = f'name="{v.name}" valueReference="{_vr(spec, v)}" causality="{v.causality}"'
        variability = v.variability or ("fixed" if v.causality == "parameter" else
                                        "continuous" if v.type.startswith("Float") else "discrete")
        attrs += f' variability="{variability}"'
        if v.initial:
            attrs += f' initial="{v.initial}"'
        if v.derivative:
            attrs += f' derivative="{_vr(spec, next(s for s in spec.variables if s.name == v.derivative))}"'
        if v.type == "String":
            given = v.start is not None and v.causality != "output"
            start = f'><Start value="{escape(v.start)}"/></String>' if given else "/>"
            lines.append(f"    <String {attrs}{start}")
        else:
            given = v.start is not None and (v.causality != "output" or v.initial == "exact")
            start = f' start="{v.start}"' if given else ""
            lines.append(f"    <{v.type} {attrs}{start}/>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    for v in spec.variables:
        if v.causality == "output":
            deps = " ".join(str(_vr(spec, d)) for d in spec.variables if d.name in (v.depends or ()))
            lines.append(f'    <Output valueReference="{_vr(spec, v)}" dependencies="{deps}"/>')
    for v in spec.variables:
        if v.derivative:
            lines.append(f'    <ContinuousStateDerivative valueReference="{_vr(spec, v)}"/>')
    for v in spec.variables:
        if v.causality == "output" and v.initial != "exact" or v.derivative:
            lines.append(f'    <InitialUnknown valueReference="{_vr(spec, v)}" dependencies=""/>')
    for name in spec.indicators:
        vr = _vr(spec, next(v for v in spec.variables if v.name == name))
        lines.append(f'    <EventIndicator valueReference="{vr}"/>')
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(x for x in lines if x) + "\n"


# --------------------------------------------------------------------------- building
def headers() -> Path:
    """FMPy's copy of the FMI 2.0 and 3.0 headers."""
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


_IMPLEMENTED3 = re.compile(r"^(?:const char \*|fmi3Status |fmi3Instance |void )(fmi3\w+)\(", re.M)


def fmi3_stubs(model_exchange: bool = False) -> str:
    """C stubs (returning fmi3Error) for every FMI 3.0 function fmi3_glue.c (and, for a model-exchange
    model, fmi3_me.h) does not define: loaders such as FMPy resolve every symbol of the standard."""
    glue = (SOURCES / "fmi3_glue.c").read_text() + ((SOURCES / "fmi3_me.h").read_text() if model_exchange else "")
    done = set(_IMPLEMENTED3.findall(glue))
    for kind in ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
                 "Boolean"):
        done.update({f"fmi3Get{kind}", f"fmi3Set{kind}"})
    text = (headers() / "fmi3FunctionTypes.h").read_text()
    out = ['#include "fmi3Functions.h"']
    for ret, name, args in re.findall(r"typedef\s+([\w\s\*]+?)\s*(fmi3\w+)TYPE\s*\(([^;]*)\);", text, re.S):
        if name in done:
            continue
        body = {"fmi3Status": "return fmi3Error;", "fmi3Instance": "return NULL;", "void": ""}.get(ret.strip(),
                                                                                                 "return 0;")
        out.append(f"{ret} {name}({args}) {{ {body} }}")
    return "\n".join(out) + "\n"


def build(spec: Spec, out_dir: Path) -> Path:
    """Compile ``spec``'s model with its FMI glue and pack ``out_dir/<name>.fmu``."""
    compiler = shutil.which("gcc") or shutil.which("cc")
    if compiler is None:
        raise RuntimeError("no C compiler (gcc or cc) on PATH to build the test FMUs")
    work = Path(out_dir) / f"{spec.name}-src"
    work.mkdir(parents=True, exist_ok=True)
    glue = SOURCES / ("fmi2_glue.c" if spec.fmi == "2.0" else "fmi3_glue.c")
    sources = [str(glue)]
    if spec.fmi == "3.0":
        (work / "stubs.c").write_text(fmi3_stubs("me" in spec.interfaces))
        sources.append(str(work / "stubs.c"))
    library = work / f"{spec.name}.so"
    cmd = [compiler, "-shared", "-fPIC", "-O1", f"-I{headers()}", f"-I{SOURCES}",
           f'-DMODEL_FILE="{spec.source}"', f'-DHAS_ME={int("me" in spec.interfaces)}',
           f'-DHAS_CS={int("cs" in spec.interfaces)}', *sources, "-o", str(library), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling {spec.name} failed:\n{proc.stderr}")
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"ipcosim-test/{spec.name}/{spec.fmi}")) + "}"
    md = model_description2(spec, token) if spec.fmi == "2.0" else model_description3(spec, token)
    platform = "linux64" if spec.fmi == "2.0" else "x86_64-linux"
    fmu = Path(out_dir) / f"{spec.name}.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", md)
        zf.write(library, f"binaries/{platform}/{spec.name}.so")
        extra = ("me_model.h", "fmi2_me.h" if spec.fmi == "2.0" else "fmi3_me.h") if "me" in spec.interfaces else ()
        for src in (glue, SOURCES / "model.h", *(SOURCES / x for x in extra), SOURCES / spec.source):
            zf.write(src, f"sources/{src.name}")
    return fmu
