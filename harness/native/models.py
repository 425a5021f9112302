"""Native models: each plant, control law and the setpoint traced from its Python definition.

A :class:`NativeModel` is what the C generator (``ipcosim.harness.native.cgen``) needs: the model's
variables (read from the Python flavour's model description, so names, value references,
units and start values cannot drift), its internal state slots, and the traced assignments
of its ``initialize`` and ``step`` functions.

* Plants: the step is ``FastETDRK4.step`` (``ipcosim.fmus.integrator``) over the plant's internal
  right-hand side (``ipcosim.fmus.plant``), after the amplifier's clip (``ipcosim.fmus.physics``),
  followed by the conversion of the internal state back to the outputs. The physical constants
  stay parameters; the integrator's stage matrices (computed in Python for ``integrator_step``)
  are further parameters ``etdrk4_S<k>_<i>_<j>``.
* Laws: the law object built by ``ipcosim.controllers.catalog.build_law`` for the default
  parameter values has every number replaced by a leaf (``ipcosim.harness.native.leaves``) and its
  own ``step`` traced twice: once from the reset state (first sample) and once from the state
  after a sample; a ``first`` flag selects between them. Numbers that a step assigns are state;
  the others are parameters, named like the Python FMU's parameter they equal
  (``gain_aliases``) or after their path.
* Setpoint: ``ipcosim.controllers.reference.reference_at`` at the end of the step.
"""
from __future__ import annotations

import copy
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping
from xml.etree import ElementTree

from ipcosim.errors import IpcosimError
from ipcosim.harness.native import exchange, tracer
from ipcosim.harness.native.leaves import c_name, numbers
from ipcosim.harness.native.tracer import Node, leaf, select
from ipcosim.harness.native.variable import TAPPED, NativeVariable


class NativeModelError(IpcosimError, RuntimeError):
    """A model cannot be generated (names the model and the reason)."""


@dataclass
class NativeModel:
    """Everything the C generator needs for one model (see the module docstring)."""

    name: str
    timing: str                                 # plant (integrated) | sampled | source (the C MODEL_KIND_*)
    description: str
    variables: list[NativeVariable]
    states: dict[str, float]                    # state slot key -> start value
    initialize: list[tuple[str, Any]]           # (slot key, node) assignments
    step: list[tuple[str, Any]]
    checked: list[str]                          # slot keys that must stay finite
    python_only: list[str] = field(default_factory=list)   # Python parameters this flavour lacks
    paths: dict[str, str] = field(default_factory=dict)    # law number path -> native parameter (laws)
    meta: dict[str, Any] = field(default_factory=dict)     # {"role": plant|law|source, "law", "plant"}
    checks: dict[str, str] = field(default_factory=dict)   # parameter -> finite | positive | nonnegative | zero
    unit_definitions: list[ElementTree.Element] = field(default_factory=list)
    exchange: Any = None                                   # model exchange (plants: exchange.Exchange)

    def variable(self, name: str) -> NativeVariable:
        for v in self.variables:
            if v.name == name:
                return v
        raise KeyError(name)


# ============================================================================ the Python flavour


def python_variables(fmu: Path) -> tuple[list[NativeVariable], list[ElementTree.Element], str]:
    """Variables, unit definitions and description of a built Python FMU."""
    with zipfile.ZipFile(fmu) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
    out = []
    svs = root.find("ModelVariables")
    assert svs is not None
    elems = list(svs)
    for sv in elems:
        typ = next(iter(sv))
        start = typ.get("start")
        out.append(NativeVariable(name=sv.get("name", ""), vr=int(sv.get("valueReference", "0")),
                            causality=sv.get("causality", "local"), variability=sv.get("variability", "continuous"),
                            type=typ.tag, initial=sv.get("initial"), unit=typ.get("unit"),
                            description=sv.get("description", ""),
                            start=None if start is None else (1.0 if start == "true" else 0.0 if start == "false"
                                                              else float(start))))
    structure = root.find("ModelStructure")
    names = [v.name for v in out]
    if structure is not None:
        for tag, attr in (("Outputs", "depends_on"), ("InitialUnknowns", "initial_depends_on")):
            sect = structure.find(tag)
            for u in (sect if sect is not None else []):
                var = out[int(u.get("index", "0")) - 1]
                deps = u.get("dependencies")
                setattr(var, attr, None if deps is None else tuple(names[int(i) - 1] for i in deps.split()))
    units = list(root.find("UnitDefinitions") or [])
    return out, units, root.get("description", "")


# ============================================================================ plants


#: Instrument options of the Python plant (``ipcosim.fmus.instruments``) that the native plant does not
#: model: each must stay 0 (off) in the native flavour. ``noise_seed`` acts only through it and may take any
#: value. The lab bench's (encoders, end stops, DAC, computation delay) and the taps it models.
NATIVE_INSTRUMENTS_OFF = ("noise_counts",)
#: Longest computation delay of the native plant, in integrator steps (its delay line's length).
NATIVE_MAX_DELAY_STEPS = 32


def stage_coefficients(stages: list[list[list[float]]], n: int) -> dict[str, float]:
    """``{etdrk4_S<k>_<i>_<j>: value}``: the right-hand-side columns (``j >= n``) of the stage matrices of
    ``ipcosim.fmus.integrator.etdrk4_f_form`` (the start-value block is the identity, applied as ``x + ...``)."""
    return {f"etdrk4_S{k}_{i}_{j}": float(row[j]) for k, m in enumerate(stages) for i, row in enumerate(m)
            for j in range(n, len(row))}


def sym_stages(x: list[Any], f: Callable[..., Any], args: tuple[Any, ...], shapes: list[tuple[int, int]],
               present: set[str]) -> list[Any]:
    """``FastETDRK4``'s compiled stages (``ipcosim.fmus.integrator._compile_stages``) with each coefficient in
    ``present`` a parameter leaf: ``y_i = x_i + sum_j S_k[i, j] f_j`` in the same order, the others (the exact
    zeros the Python code leaves out too) left out, then ``f`` at the new stage."""
    n = len(x)
    fs = [list(f(*x, *args))]
    out: list[Any] = []
    for k, (rows, cols) in enumerate(shapes):
        flat = [v for fk in fs for v in fk]
        out = []
        for i in range(rows):
            acc = x[i]
            for j in range(n, cols):
                name = f"etdrk4_S{k}_{i}_{j}"
                if name in present:
                    acc = acc + leaf("V:" + name) * flat[j - n]
            out.append(acc)
        if k < len(shapes) - 1:
            fs.append(list(f(*out, *args)))
    return out


def plant_model(name: str, kind: str, python_fmu: Path, step: float = 1e-3) -> NativeModel:
    """The native plant ``name`` (``IP02SingleMass`` / ``IP02DoubleMass``) traced from the Python plant."""
    from ipcosim.fmus import physics
    from ipcosim.fmus import plant as plant_mod
    from ipcosim.fmus.integrator import FastETDRK4
    from ipcosim.fmus.params import DEFAULT_PRESET, PLANT_KINDS, PRESETS, make

    variables, units, description = python_variables(python_fmu)
    cls = PLANT_KINDS[kind]
    p0 = make(kind, **dict(PRESETS[DEFAULT_PRESET[kind]][1]))
    stepper = FastETDRK4(plant_mod.Plant(p0)._L, step)
    stages = [stepper.S0, stepper.S1, stepper.S2, stepper.S3]
    # the zeros are structural (L is the current's row and column): a redesign checks they stay zero
    coefficients = {k: v for k, v in stage_coefficients(stages, len(stages[0])).items() if v != 0.0}
    states = physics.state_names(kind)
    n = len(states)
    stepped, started = _trace_plant(kind, cls, [(len(m), len(m[0])) for m in stages], set(coefficients))
    zkeys = [f"S:z{i}" for i in range(n)]
    dkeys = [f"S:d{k}" for k in range(NATIVE_MAX_DELAY_STEPS)]
    xkeys = [exchange.state_key(s) for s in states]
    _append(variables, _plant_parameters(step, coefficients))
    _append(variables, exchange.variables(kind))
    present = {v.name for v in variables}
    off = [name for name in NATIVE_INSTRUMENTS_OFF if name in present]
    return NativeModel(
        name=name, timing="plant", description=description, variables=variables, unit_definitions=units,
        states={k: 0.0 for k in zkeys + dkeys + [TAPPED]} | exchange.discrete_starts(kind),
        initialize=list(zip(zkeys, started[:n])) + [(f"V:{s}", v) for s, v in zip(states, started[n:2 * n])]
        + [(k, tracer.const(0.0)) for k in dkeys + [TAPPED]] + list(zip(xkeys, started[2 * n:])),
        step=list(zip(zkeys, stepped[:n])) + [(f"V:{s}", v) for s, v in zip(states, stepped[n:2 * n])]
        + list(zip(dkeys, stepped[2 * n:2 * n + len(dkeys)])) + list(zip(xkeys, stepped[2 * n + len(dkeys):-1]))
        + [(TAPPED, stepped[-1])],
        checked=zkeys, meta={"role": "plant", "plant": kind, "integrator_step": repr(step), "instruments_off": off,
                             "max_delay_steps": NATIVE_MAX_DELAY_STEPS, "stage_coefficients": sorted(coefficients),
                             "design_values": {f: getattr(p0, f) for f in cls.__dataclass_fields__}},
        checks={**{f.name: ("positive" if f.metadata.get("positive") else
                            "nonnegative" if f.metadata.get("nonnegative") else "finite")
                   for f in cls.__dataclass_fields__.values()},
                **{f"initial_{s}": "finite" for s in states}, "integrator_step": "positive",
                **{name: "zero" for name in off}},
        exchange=exchange.exchange(kind, _PlantTrace(kind, cls)))


def _trace_plant(kind: str, cls: type, shapes: list[tuple[int, int]], nonzero: set[str]
                 ) -> tuple[list[Any], list[Any]]:
    """One traced plant step (the integrator state ``z`` after the step, then the outputs) and the traced
    start (``z`` from the initial values), every parameter symbolic (:class:`_PlantTrace`)."""
    plant = _PlantTrace(kind, cls)
    with tracer.math_hooks():
        return tracer.trace(lambda: plant.step(shapes, nonzero)), tracer.trace(plant.start)


class _PlantTrace:
    """The Python plant's step, read with symbolic parameters and states: the input path (DAC codes,
    delay line, voltage limit), the integrator's stages, the constraints (stiction, end stops) and the
    encoders. Each traced value is laid out as the native state wants it: ``z`` (the integrator's
    state), the outputs, then (a step only) the delay buffer and ``x`` (the constrained state)."""

    def __init__(self, kind: str, cls: type) -> None:
        from ipcosim.fmus import instruments, kinds, physics
        from ipcosim.fmus import plant as plant_mod

        self.kind, self.cls = kind, cls
        self.states = physics.state_names(kind)
        self.entry = kinds.get(kind)
        self.internal = self.entry.internal
        self.quantize = tracer.local(instruments.quantize)
        self.resolutions = [leaf("V:pendulum_resolution" if s == "pendulum_angle" else "V:cart_resolution")
                            for s in physics.MEASURED[kind]]
        self._physics, self._instruments, self._plant = physics, instruments, plant_mod

    def params(self) -> Any:
        """The plant's parameter set with every field a symbolic value ``V:<field>``."""
        p = object.__new__(self.cls)
        for f in self.cls.__dataclass_fields__.values():
            object.__setattr__(p, f.name, leaf("V:" + f.name))
        return p

    def outputs(self, x: list[Any]) -> list[Any]:
        """The plant's outputs of state ``x``: the measured states through their encoders."""
        measured = self._physics.MEASURED[self.kind]
        readings = dict(zip(measured, map(self.quantize, [x[self.states.index(m)] for m in measured],
                                          self.resolutions)))
        return [readings.get(s, v) for s, v in zip(self.states, x)]

    def voltage(self, p: Any, buffer: list[Any]) -> tuple[Any, Any]:
        """(the DAC's voltage this step, the voltage applied after the delay line and the limit)."""
        ins = self._instruments
        v = self.quantize(leaf("V:voltage"), leaf("V:voltage_resolution"))
        steps = tracer.local(lambda d, h: min(ins.delay_steps(d, h), float(NATIVE_MAX_DELAY_STEPS)))(
            leaf("V:input_delay"), leaf("V:integrator_step"))
        delayed = tracer.local(lambda *a: ins.delay_line(a[:-2], a[-2], a[-1])[0])(*buffer, v, steps)
        return v, p.amplifier_gain * tracer.local(self._physics.clip_voltage)(delayed, p.voltage_limit)

    def constrain(self, p: Any, before: list[Any], x: list[Any]) -> tuple[list[Any], Any]:
        """``plant.constrain`` in two traced calls (each merges its own branches): the state after stiction
        and the end stops, and whether either held a cart."""
        n, plant_mod = len(self.states), self._plant
        flat = lambda pair: [*pair[0], pair[1]]  # noqa: E731 -- (state, count) -> one flat list
        *x, stuck = tracer.local(lambda *a: flat(plant_mod.stick(a[:n], a[n:], p)))(*before, *x)
        *x, stopped = tracer.local(lambda *a: flat(self._instruments.stop_carts(a[:-1], plant_mod.CARTS[self.kind],
                                                                              a[-1])))(*x, leaf("V:end_stop"))
        return x, stuck + stopped

    def tap(self, p: Any, before: list[Any], z: list[Any]) -> tuple[Any, list[Any], list[Any]]:
        """``InstrumentedPlant._tap`` traced: (the tapped flag after this step, the state and the integrator
        state the step starts from). The taps act once, in the first step that ends after ``tap_time``, when
        an impulse is set."""
        force, torque = leaf("V:tap_force_impulse"), leaf("V:tap_torque_impulse")
        due = tracer.select(leaf(TAPPED) < 0.5, tracer.select(leaf("S:time") > leaf("V:tap_time"),
                                                              force * force + torque * torque > 0.0, False), False)
        x = self._plant.tapped_state(self.kind, before, p, force, torque)
        zx = self.internal.to_internal(x, p) if self.internal else x
        return (tracer.select(due, 1.0, leaf(TAPPED)), [tracer.select(due, a, b) for a, b in zip(x, before)],
                [tracer.select(due, a, b) for a, b in zip(zx, z)])

    def step(self, shapes: list[tuple[int, int]], nonzero: set[str]) -> list[Any]:
        """One step: ``z`` after it, the outputs, the delay buffer shifted, the constrained state ``x``, the
        tapped flag."""
        n = len(self.states)
        p = self.params()
        f = tracer.local(self.entry.folded_rhs(p))
        buffer = [leaf(f"S:d{k}") for k in range(NATIVE_MAX_DELAY_STEPS)]
        v, vA = self.voltage(p, buffer)
        # the state after the last step's constraints, then the taps
        tapped, before, z0 = self.tap(p, [leaf(exchange.state_key(s)) for s in self.states],
                                      [leaf(f"S:z{i}") for i in range(n)])
        z = sym_stages(z0, f, (vA,), shapes, nonzero)
        x = self.internal.output_map(p)(z) if self.internal else list(z)
        x, held = self.constrain(p, before, x)
        if self.internal:
            zx = self.internal.to_internal(x, p)
            z = [tracer.select(held > 0.0, a, b) for a, b in zip(zx, z)]
        else:
            z = x
        return list(z) + self.outputs(x) + [v, *buffer[:-1]] + list(x) + [tapped]

    def start(self) -> list[Any]:
        """The start: ``z`` from the initial values, the outputs, the initial state."""
        x0 = [leaf(f"V:initial_{s}") for s in self.states]
        z0 = self.internal.to_internal(x0, self.params()) if self.internal else x0
        return list(z0) + self.outputs(x0) + x0


def _plant_parameters(step: float, coefficients: dict[str, float]) -> list[NativeVariable]:
    """The native plant's own parameters: its integrator step and the nonzero stage coefficients."""
    extra = [NativeVariable("integrator_step", 0, "parameter", "fixed", start=step, initial="exact", unit="s",
                      description="communication step the integrator's coefficients are computed for [s]; every "
                                  "fmi2DoStep must use it")]
    for pname, value in coefficients.items():
        k, i, j = pname.split("_")[1:]
        extra.append(NativeVariable(pname, 0, "parameter", "fixed", start=value, initial="exact", unit="1",
                              description=f"ETDRK4 stage matrix {k}[{i},{j}] (ipcosim.fmus.integrator."
                                          "etdrk4_f_form), computed for integrator_step"))
    return extra


def _append(variables: list[NativeVariable], extra: list[NativeVariable]) -> None:
    vr = max(v.vr for v in variables) + 1
    taken = {v.name for v in variables}
    for v in extra:
        if v.name in taken:
            raise NativeModelError(f"native variable {v.name} collides with a Python variable")
        v.vr = vr
        vr += 1
        variables.append(v)


# ============================================================================ laws


def _trace_step(base: Any, measured: tuple[str, ...]) -> tuple[Any, dict[str, Any], dict[str, float]]:
    """Trace ``base.step`` from ``base``'s state: (voltage node, {path: new value}, {path: value before})."""
    keys: list[str] = []
    before = numbers(base)

    def fn() -> list[Any]:
        law = copy.deepcopy(base)
        numbers(law, replace=True)
        law._inputs = lambda m, r: (tuple(m), r)
        u = law.step([leaf(f"V:{m}") for m in measured], leaf("V:reference"))
        after = numbers(law)
        if not keys:
            keys.extend(sorted(after))
        elif sorted(after) != keys:
            raise NativeModelError("a law's state layout depends on a branch")
        return [u] + [after[k] for k in keys]

    from ipcosim.controllers.catalog import law_modules
    from ipcosim.controllers.laws.hsmc import Schedule
    modules = law_modules()
    saturates = {m: m.saturate for m in modules if hasattr(m, "saturate")}
    schedule = Schedule.__call__
    for m, saturate in saturates.items():
        m.saturate = tracer.local(saturate)  # pure functions: their branches merged where they return
    Schedule.__call__ = tracer.local(schedule)  # type: ignore[method-assign]
    try:
        with tracer.math_hooks(*modules):
            out = tracer.trace(fn)
    finally:
        for m, saturate in saturates.items():
            m.saturate = saturate
        Schedule.__call__ = schedule  # type: ignore[method-assign]
    return out[0], dict(zip(keys, out[1:])), before


def gain_aliases(kind: str, law: str, defaults: dict[str, Any],
                 build: Callable[[dict[str, Any]], Any]) -> tuple[dict[str, str], set[str]]:
    """Which law numbers equal which Python parameter, found by perturbing each parameter in turn.

    Returns ``({path: parameter}, {parameters that also change other numbers: design-only})``.
    """
    base = numbers(build(defaults))
    alias: dict[str, str] = {}
    design_only: set[str] = set()
    for name, value in defaults.items():
        if isinstance(value, bool):
            design_only.add(name)
            continue
        new = float(value) * 1.25 + 0.01
        try:
            moved = numbers(build({**defaults, name: new}))
        except Exception:  # noqa: BLE001 -- a perturbation the design rejects: not actable natively
            design_only.add(name)
            continue
        if set(moved) != set(base):
            design_only.add(name)
            continue
        for path, v in moved.items():
            if v != base[path]:
                if base[path] == float(value) and v == new:
                    alias[path] = name
                else:
                    design_only.add(name)
    return alias, design_only


def law_model(kind: str, law: str, python_fmu: Path) -> NativeModel:
    """The native controller ``<Law><Plant>`` traced from ``ipcosim.controllers.laws``."""
    from ipcosim.controllers import catalog

    name = catalog.model_name(kind, law)
    variables, units, description = python_variables(python_fmu)
    defaults = catalog.defaults(kind, law)
    build = lambda values: native_law(kind, law, values)  # noqa: E731
    law0 = build(defaults)
    if hasattr(law0, "balance"):
        # a swing-up sets its balancing law's predicted state on every catch, before that law uses it: start
        # it at zeros instead of None, so that every path of the first sample has the same state layout
        law0.balance.x_pred = [0.0] * len(law0.balance.coefficients.states)
    step, state_paths, param_paths, before1, before2 = _trace_law(law0, kind)
    alias, design_only = gain_aliases(kind, law, defaults, build)
    alias = {p: a for p, a in alias.items() if a not in design_only}
    extra, renamed = _derived_parameters(law0, [p for p in param_paths if p not in alias], before2, variables)
    native_vars, python_only = _law_variables(name, variables, extra, param_paths, alias, renamed, before2)
    aliases = {f"L:{p}": f"V:{alias.get(p) or renamed[p]}" for p in param_paths}
    step = [(k, _rename(n, aliases)) for k, n in step]
    states = {f"L:{p}": float(before1.get(p, 0.0)) for p in state_paths}
    states.update({"S:first": 1.0, "S:tick": 0.0})
    settable = sorted({v.name for v in native_vars if v.causality == "parameter"})
    return NativeModel(name=name, timing="sampled", description=description, variables=native_vars,
                       unit_definitions=units, states=states, initialize=step, step=step,
                       checked=["V:voltage"] + [f"L:{p}" for p in state_paths], python_only=python_only,
                       paths={p: aliases[f"L:{p}"][2:] for p in param_paths},
                       meta={"role": "law", "law": law, "plant": kind, "design_values": dict(defaults)},
                       checks={**{p: "finite" for p in settable},
                               # the native law keeps its gains at a new sample period (no redesign):
                               # "period" checks only that it is positive there
                               **{s.name: "positive" if s.constraint == "period" else s.constraint
                                  for s in catalog.schema(kind, law)
                                  if s.constraint != "bool" and s.name in {v.name for v in native_vars}}})


def _trace_law(law0: Any, kind: str) -> tuple[list[tuple[str, Any]], list[str], list[str], dict[str, float],
                                               dict[str, float]]:
    """The law's step traced from the reset state and from the state after one sample, merged on the
    ``first`` flag: (assignments, state paths, parameter paths, numbers at reset, numbers after a sample)."""
    from ipcosim.fmus.physics import MEASURED

    measured = MEASURED[kind]
    law1 = copy.deepcopy(law0)
    law1.step([0.0] * len(measured), 0.0)
    u1, after1, before1 = _trace_step(law0, measured)
    u2, after2, before2 = _trace_step(law1, measured)
    first = leaf("S:first")
    state_paths = sorted(p for p in set(after1) | set(after2)
                         if after2.get(p) is not leaf("L:" + p) or p not in before1)
    updates = [(f"L:{p}", select(first, after1.get(p, leaf("L:" + p)), after2.get(p, leaf("L:" + p))))
               for p in state_paths]
    step = [("V:voltage", select(first, u1, u2))] + updates + [("S:first", 0.0)]
    used = _leaves([n for _, n in step if isinstance(n, Node)])
    param_paths = sorted(k[2:] for k in used if k.startswith("L:") and k[2:] not in state_paths)
    return step, state_paths, param_paths, before1, before2


def _law_variables(name: str, variables: list[NativeVariable], extra: list[NativeVariable], param_paths: list[str],
                   alias: dict[str, str], renamed: dict[str, str], values: dict[str, float]
                   ) -> tuple[list[NativeVariable], list[str]]:
    """The native law's variables (the Python FMU's, less its design-only parameters, plus ``extra``), each
    parameter starting at the exact number the law holds; and the design-only (Python-only) names."""
    python_params = {v.name for v in variables if v.causality == "parameter"}
    keep = ({alias[p] for p in param_paths if p in alias} | {"sample_period", "voltage_limit"}
            | (set(renamed.values()) & python_params))
    python_only = sorted(v.name for v in variables if v.causality == "parameter" and v.name not in keep)
    native_vars = [v for v in variables if v.causality != "parameter" or v.name in keep]
    for v in native_vars:
        if v.causality == "calculatedParameter" and v.name in renamed.values():
            v.causality, v.variability, v.initial = "parameter", "fixed", "exact"
    native_vars = [v for v in native_vars if v.causality != "calculatedParameter"]
    _append(native_vars, extra)
    for p in param_paths:
        target = alias.get(p) or renamed[p]
        var = next(v for v in native_vars if v.name == target)
        if target in python_params and var.start is not None and f"{float(var.start):.16g}" == f"{values[p]:.16g}":
            # a Python FMU's model description holds 16 significant digits (pythonfmu), the FMU itself the
            # exact value (a default, or a gain it ships: K_*, N, M_*), which is the start value here
            var.start = values[p]
        if var.start is None or var.causality == "parameter" and p not in alias and target not in python_params:
            var.start = values[p]
        if float(var.start) != values[p]:
            raise NativeModelError(f"{name}: {p} = {values[p]} but parameter {target} starts at {var.start}")
    return native_vars, python_only


def _derived_parameters(law: Any, paths: list[str], values: dict[str, float],
                        python_vars: list[NativeVariable]) -> tuple[list[NativeVariable], dict[str, str]]:
    """Native-only parameters for law numbers that equal no Python parameter.

    The designed gains of an LQR or LQG (``K[i]``, ``N`` or ``K_voltage``, ``K_integral``, ``M[i][j]`` of
    its ``coefficients``, for the LQR also reachable as its ``design``: ``ipcosim.controllers.laws``) keep
    the Python FMU's names ``K_<state>``, ``N``, ``K_voltage``, ``K_integral``, ``M_<state>_<output>``
    (``ipcosim.controllers.catalog.gain_specs``).
    """
    renamed: dict[str, str] = {}
    extra: list[NativeVariable] = []
    taken = {v.name for v in python_vars}
    lqr, where = (law.balance, "balance.") if hasattr(law, "balance") else (law, "")  # a swing-up's LQR
    coef = getattr(lqr, "coefficients", None)
    gains: dict[str, str] = {}
    for at in (f"{where}coefficients", f"{where}design") if coef is not None else ():  # one object, two names
        gains.update({f"{at}.K[{i}]": f"K_{s}" for i, s in enumerate(coef.states)})
        gains.update({f"{at}.{g}": g for g in ("N", "K_voltage", "K_integral") if hasattr(coef, g)})
        gains.update({f"{at}.M[{i}][{j}]": f"M_{s}_{o}" for i, s in enumerate(coef.states)
                      for j, o in enumerate(coef.outputs)})
    for p in paths:
        renamed[p] = gains.get(p) or c_name(p)
        if renamed[p] in taken:
            if p not in gains:
                raise NativeModelError(f"law constant {p}: its native name {renamed[p]} is a Python variable")
            continue
        extra.append(NativeVariable(renamed[p], 0, "parameter", "fixed", start=values[p], initial="exact",
                              description=f"law constant {p} (ipcosim.controllers.laws), computed at build time by "
                                          "the Python design; see docs/native.md to redesign"))
    return extra, renamed


def native_law(kind: str, law: str, values: Mapping[str, Any]) -> Any:
    """The law the Python controller FMU runs for flat parameter ``values`` (``controller_fmu``).

    A designed law's (LQR, LQG, the swing-up's balancing LQR) ``values`` may hold its gains (``K_*``,
    ``N``, ``M_*``, ...): they replace the designed ones, and the zero-order-hold model comes from the
    plain-Python ``catalog.law_from_gains`` as in the Python FMU with its shipped gains. Gains together
    with a changed weight or observer pole are refused, as there.
    """
    from ipcosim.controllers import catalog

    designed = law in catalog.DESIGNED_LAWS
    gain_names = {s.name for s in catalog.gain_specs(kind, law)} if designed else set()
    gains = {k: float(v) for k, v in values.items() if k in gain_names}
    design = {k: v for k, v in values.items() if k not in gain_names}
    built = catalog.build_law(kind, law, design, backend="scipy")
    if not designed:
        return built
    full = {**catalog.defaults(kind, law), **design}
    if gains:
        base = catalog.defaults(kind, law)
        weights = [n for n in catalog.weight_parameters(kind, law) if float(full[n]) != float(base[n])]
        if weights:
            raise NativeModelError(f"{catalog.model_name(kind, law)}: parameters {weights[0]} and "
                                   f"{sorted(gains)[0]} were both set: give either the design (weights, observer "
                                   "poles) or the gains K_*, N, M_*, not both")
    return catalog.law_from_gains(kind, law, full, {**catalog.designed_gains(built), **gains})


def _leaves(roots: list[Node]) -> set[str]:
    seen: set[int] = set()
    out: set[str] = set()
    stack = list(roots)
    while stack:
        n = stack.pop()
        if id(n) in seen:
            continue
        seen.add(id(n))
        if n.op == "leaf":
            out.add(n.name)
        stack.extend(n.args)
    return out


def _rename(root: Any, mapping: dict[str, str]) -> Any:
    """The expression with leaves renamed (a fresh graph; interned)."""
    if not isinstance(root, Node):
        return root
    memo: dict[int, Node] = {}

    def go(n: Node) -> Node:
        got = memo.get(id(n))
        if got is not None:
            return got
        if n.op == "leaf":
            new = leaf(mapping.get(n.name, n.name))
        elif n.op == "const":
            new = n
        else:
            args = tuple(go(a) for a in n.args)
            new = tracer._intern(n.op, args, n.is_bool)
        memo[id(n)] = new
        return new

    import sys
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 100000))
    try:
        return go(root)
    finally:
        sys.setrecursionlimit(limit)


# ============================================================================ setpoint


def setpoint_model(python_fmu: Path) -> NativeModel:
    """The native ``Setpoint``: ``reference_at`` traced with every parameter symbolic."""
    from ipcosim.controllers.reference import reference_at

    variables, units, description = python_variables(python_fmu)
    args = ("waveform", "amplitude", "step_time", "offset", "ramp_rate", "period")
    with tracer.math_hooks():
        (ref,) = tracer.trace(lambda: [reference_at(leaf("S:time"), *(leaf(f"V:{a}") for a in args))])
    return NativeModel(name="Setpoint", timing="source", description=description, variables=variables,
                       unit_definitions=units, states={}, initialize=[("V:reference", ref)],
                       step=[("V:reference", ref)], checked=["V:reference"], meta={"role": "source"},
                       checks={a: "finite" for a in args})
