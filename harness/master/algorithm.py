"""Co-simulation algorithms: the order in which components step, their step multiples, the
initialization fixed point and the stepping loop.

Ordering (Gauss-Seidel) comes from the FMUs' ``<ModelStructure>``: an output that depends
directly on an input makes its component step after the component feeding that input (the
controller samples the plant's new positions without delay); an input with no direct
feedthrough makes its component step *before* the component feeding it whenever that
leaves the order consistent (the plant integrates over the step with the voltage held from
its start: an exact zero-order hold). A cycle of direct dependencies is an algebraic loop
and is reported with its variables. Jacobi steps every component from the values of the
previous communication point (the libcosim fixed-step algorithm).

Stepping is on integer ticks: tick ``n`` advances from ``t_n = t0 + n h`` to ``t_{n+1}``;
times are computed from integer nanoseconds when the step is a whole number of them (the
same floating-point times libcosim passes). A component with step multiple ``m`` (from its
``sample_period`` parameter) steps once every ``m`` ticks with step ``m h``: in Gauss-Seidel
at the end of its period (``(n + 1) % m == 0``, from ``t_{n+1-m}``), with its inputs set
just before the step; in Jacobi it reads its inputs at the start of its period and its
outputs are published at the end (as libcosim's decimation does).

The loop for a given system is planned once per execution (:func:`loop_plan`: the operations
of a tick, one batched set and one batched get per component and step) and the plan rendered
as Python source (:func:`generate_loop`: all value references, arrays and functions bound as
locals, conversions folded into constants) or as C (:mod:`ipcosim.harness.master.cloop`), so
each step does nothing but the FMI calls, the transfers and one copy of the value vector into
the record.
"""
from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.master.system import Instance, Link, System

GAUSS_SEIDEL = "gauss-seidel"
JACOBI = "jacobi"
ALGORITHMS = (GAUSS_SEIDEL, JACOBI)


class AlgebraicLoopError(IpcosimError, ValueError):
    """Direct feedthrough dependencies form a cycle (Gauss-Seidel cannot order the components).

    Attributes
    ----------
    variables : list of str
        The ``component.variable`` names along the cycle.
    """

    def __init__(self, message: str, variables: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.variables = list(variables)


class StepSizeError(IpcosimError, ValueError):
    """A step or stop time that is not positive, or a component period the step does not divide."""


class InitializationError(IpcosimError, RuntimeError):
    """Initialization did not reach a fixed point of the connections.

    Attributes
    ----------
    variables : list of str
        Inputs still changing in the last iteration.
    """

    def __init__(self, message: str, variables: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.variables = list(variables)


# --------------------------------------------------------------------------- ordering
def _feeds_directly(link: Link, instances: dict[str, Instance]) -> bool:
    """Whether the link's input reaches an output of its component without delay."""
    ft = instances[link.dst].model.feedthrough
    return any(link.dst_var.name in deps for deps in ft.values())


def find_algebraic_loop(system: System) -> list[str] | None:
    """A cycle of direct dependencies as ``component.variable`` names, or None.

    The graph's nodes are variables: a link joins an output to an input, and an input joins
    every output of its component that depends on it directly (ModelStructure).
    """
    instances = {i.name: i for i in system.instances}
    edges: dict[str, list[str]] = {}
    for link in system.links:
        edges.setdefault(link.src_name, []).append(link.dst_name)
    for inst in system.instances:
        for out, deps in inst.model.feedthrough.items():
            for d in deps:
                edges.setdefault(f"{inst.name}.{d}", []).append(f"{inst.name}.{out}")
    del instances
    color: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        color[node] = 1
        stack.append(node)
        for nxt in edges.get(node, ()):
            if color.get(nxt, 0) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if color.get(nxt, 0) == 0:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        color[node] = 2
        return None

    for node in sorted(edges):
        if color.get(node, 0) == 0:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def _acyclic(nodes: Sequence[str], edges: set[tuple[str, str]]) -> bool:
    return _topological(nodes, edges) is not None


def _topological(nodes: Sequence[str], edges: set[tuple[str, str]]) -> list[str] | None:
    """Kahn's algorithm; ties broken by position in ``nodes`` (the SSD order). None on a cycle."""
    indeg = {n: 0 for n in nodes}
    for _a, b in edges:
        indeg[b] += 1
    order: list[str] = []
    ready = [n for n in nodes if indeg[n] == 0]
    while ready:
        ready.sort(key=nodes.index)
        n = ready.pop(0)
        order.append(n)
        for a, b in sorted(edges):
            if a == n:
                indeg[b] -= 1
                if indeg[b] == 0:
                    ready.append(b)
    return order if len(order) == len(nodes) else None


def gauss_seidel_order(system: System) -> list[str]:
    """Component names in Gauss-Seidel stepping order (see the module documentation).

    Raises
    ------
    AlgebraicLoopError
        If direct dependencies form a cycle (the variables are listed), or components feed
        each other directly in a way no order satisfies.
    """
    loop = find_algebraic_loop(system)
    if loop:
        raise AlgebraicLoopError("algebraic loop (direct feedthrough all the way round): " + " -> ".join(loop)
                                 + "; break it with a delay in one component, or use the Jacobi algorithm",
                                 loop)
    instances = {i.name: i for i in system.instances}
    nodes = [i.name for i in system.instances]
    hard: set[tuple[str, str]] = set()
    soft: list[tuple[str, str]] = []
    for link in system.links:
        if link.src == link.dst:
            continue
        if _feeds_directly(link, instances):
            hard.add((link.src, link.dst))
        else:
            soft.append((link.dst, link.src))
    if not _acyclic(nodes, hard):
        pairs = ", ".join(f"{link.src_name} -> {link.dst_name}" for link in system.links
                          if (link.src, link.dst) in hard)
        raise AlgebraicLoopError(f"components feed each other through direct feedthrough ({pairs}); "
                                 f"no Gauss-Seidel order exists: use the Jacobi algorithm")
    edges = set(hard)
    for e in soft:
        if e not in edges and _acyclic(nodes, edges | {e}):
            edges.add(e)
    order = _topological(nodes, edges)
    assert order is not None
    return order


# --------------------------------------------------------------------------- time base
@dataclass(frozen=True)
class TimeBase:
    """Integer-tick time: ``t_n = t0 + n h``, from integer nanoseconds when possible.

    When the run is not a whole number of steps, the last tick is shorter: it ends at the stop
    time exactly (``short_last``); :meth:`time` of the last tick is the stop time.
    """

    start: float
    step: float
    ticks: int
    start_ns: int | None
    step_ns: int | None
    stop: float = float("nan")
    short_last: bool = False

    @classmethod
    def make(cls, start: float, stop: float, step: float) -> "TimeBase":
        if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
            raise StepSizeError(f"--step {step!r}: the step size must be a positive number of seconds")
        if not (isinstance(stop, (int, float)) and math.isfinite(stop)) or not stop > start:
            raise StepSizeError(f"--stop-time {stop!r}: the stop time must be a number > the start time "
                                f"{start:g} s")
        span = stop - start
        ticks = round(span / step)
        short = ticks < 1 or abs(ticks * step - span) > 1e-9 * max(span, step)
        if short:
            ticks = math.ceil(span / step)
        step_ns = round(step * 1e9)
        start_ns = round(start * 1e9)
        exact = (abs(step_ns - step * 1e9) <= 1e-6 * max(1.0, step * 1e9) and step_ns > 0
                 and abs(start_ns - start * 1e9) <= 1e-6 * max(1.0, abs(start) * 1e9)
                 and start_ns + ticks * step_ns < 2 ** 53)
        base = cls(float(start), float(step), int(ticks), start_ns if exact else None, step_ns if exact else None)
        end = float(stop) if short else base._regular(ticks)
        return cls(base.start, base.step, base.ticks, base.start_ns, base.step_ns, end, short)

    def _regular(self, n: int) -> float:
        if self.step_ns is not None:
            return (self.start_ns + n * self.step_ns) / 1e9
        return self.start + n * self.step

    def time(self, n: int) -> float:
        """``t_n`` (the stop time for the last tick count)."""
        if n >= self.ticks and self.short_last:
            return self.stop
        return self._regular(n)

    def span(self, m: int) -> float:
        """The duration of ``m`` regular ticks."""
        if self.step_ns is not None:
            return (m * self.step_ns) / 1e9
        return m * self.step

    def last_step(self, m: int) -> float:
        """The step of a component with step multiple ``m`` over its last (maybe partial) period."""
        p0 = ((self.ticks - 1) // m) * m
        if p0 + m == self.ticks and not self.short_last:
            return self.span(m)
        return self.time(self.ticks) - self._regular(p0)

    def expr(self, n_expr: str) -> str:
        """Python source computing the time of regular tick ``n_expr``."""
        if self.step_ns is not None:
            return f"({self.start_ns} + ({n_expr}) * {self.step_ns}) / 1e9"
        return f"{self.start!r} + ({n_expr}) * {self.step!r}"


def check_last_steps(time: TimeBase, multiples: Mapping[str, int], instances: Sequence[Instance]) -> None:
    """Every component steps exactly to the stop time: a component whose last step is shorter
    than its regular one must be able to change its step (canHandleVariableCommunicationStepSize).

    Raises
    ------
    StepSizeError
        Naming the components that cannot, and why their last step is shorter.
    """
    bad = []
    for inst in instances:
        m = multiples[inst.name]
        if not inst.model.can_handle_variable_step and abs(time.last_step(m) - time.span(m)) > 1e-12 * time.span(m):
            bad.append(f"{inst.name} ({inst.model.name}: step {time.span(m):g} s, last step "
                       f"{time.last_step(m):.6g} s)")
    if bad:
        span = time.time(time.ticks) - time.start
        raise StepSizeError(f"the run of {span:g} s is not a whole number of steps of "
                            + ", ".join(bad) + ", which cannot take a shorter last step "
                            "(canHandleVariableCommunicationStepSize=\"false\"); choose --stop-time or --step so "
                            "that every component's step divides the run")


def step_multiples(system: System, values: Callable[[str, str], Any], step: float) -> dict[str, int]:
    """Step multiple of every component: ``sample_period / step`` for components with a
    ``sample_period`` parameter, ``step_size_hint / step`` for those with an SSD step-size
    hint, else 1.

    Parameters
    ----------
    values : callable
        ``values(component, variable)`` -> the start value the run will use.

    Raises
    ------
    StepSizeError
        If a period is not a positive whole multiple of ``step``.
    """
    out = {}
    for inst in system.instances:
        period, what = None, ""
        var = inst.model.variables.get("sample_period")
        if var is not None and var.type in ("Real", "Float64") and var.causality == "parameter":
            period, what = values(inst.name, "sample_period"), f"{inst.name}.sample_period"
        elif inst.step_size_hint is not None:
            period, what = inst.step_size_hint, f"{inst.name} step-size hint"
        if period is None:
            out[inst.name] = 1
            continue
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise StepSizeError(f"{what} = {period!r} s: must be a positive number of seconds")
        m = round(period / step)
        if m < 1 or abs(m * step - period) > 1e-9 * period:
            raise StepSizeError(f"{what} = {period:g} s is not a whole multiple of the step {step:g} s "
                                f"(choose --step so that it divides every component's period)")
        out[inst.name] = int(m)
    return out


# --------------------------------------------------------------------------- loop generation
#: FMI 2.0 name of each value kind's getter/setter (for messages).
FMI_NAME = {"integer": "Integer", "boolean": "Boolean", "string": "String"}


@dataclass
class Channel:
    """One component's connectors of one non-Real value kind and their bound get/set.

    ``out_values``/``in_values`` are ``c_int`` array views (Integer, Boolean) or lists of bytes
    (String); ``transfers`` are ``(input index, source block, source output index, mapping)``
    with ``mapping`` a dict of an SSP mapping transformation or None.
    """

    kind: str
    get: Callable[[Any], int]
    set: Callable[[Any], int]
    out_values: Any
    in_values: Any
    n_out: int
    n_in: int
    transfers: tuple[tuple[int, int, int, dict[int, int] | None], ...] = ()
    private_out: Any = None  # Jacobi multi-rate: outputs are read here and published later


@dataclass
class Block:
    """One component's place in the value vector and its raw FMI functions."""

    index: int
    name: str
    handle: Any
    do_step: Callable[..., int]
    get_real: Callable[..., int]
    set_real: Callable[..., int]
    out_vrs: Any  # ctypes c_uint array
    in_vrs: Any
    out_values: Any  # ctypes c_double array (view into the value vector)
    in_values: Any
    n_out: int
    n_in: int
    multiple: int
    private_out: Any = None  # Jacobi multi-rate: outputs are read here and published later
    # transfers into this component's inputs: (input index, source block, source output index, factor, offset)
    transfers: tuple[tuple[int, int, int, float, float], ...] = ()
    #: Integer, Boolean and String connectors (none in a Real-only system: the loop is then unchanged).
    channels: tuple[Channel, ...] = ()


@dataclass
class TypedRecord:
    """Where the loop records the non-Real values: the ``c_int`` vector's rows (row bytes, vector
    address; the rows' address is the loop's ``rbi`` argument) and String rows filled by
    ``snapshot()`` into ``strings[row]`` (a mapping by row number)."""

    int_row_bytes: int = 0
    int_vector: int = 0
    strings: dict | None = None
    snapshot: Callable[[], tuple] | None = None


def generate_loop(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase,
                  record_every: int = 1, typed: TypedRecord | None = None) -> tuple[str, dict[str, Any]]:
    """Python source of the stepping loop and its namespace.

    The generated ``run(n0, n1, rec_address, value_address, row_bytes, int_rec_address=0)`` steps
    ticks ``n0 .. n1-1``; after tick ``n`` it copies the value vector into record row
    ``r = (n + 1) // record_every`` (at ``rec_address + r * row_bytes``; the ``c_int`` vector at
    ``int_rec_address + r * typed.int_row_bytes``) when ``(n + 1) % record_every == 0``. The
    addresses are those of a row 0, which need not exist: a caller that keeps only a window of
    rows passes its first row's address minus the rows before it. It returns None, or
    ``(n, block index, function name, status)`` for the first call that returned more than
    fmi2Warning (or a ``do_step`` that returned :data:`~ipcosim.harness.master.slave.TERMINATE`).
    Every component's last step ends at the stop time: a component whose last period is partial
    (or a run whose last tick is short) takes a shorter last step there.

    The order of the calls comes from :func:`loop_plan` (shared with the C loop of
    :mod:`ipcosim.harness.master.cloop`).
    """
    plan = loop_plan(blocks, order, algorithm, time)
    em = _Emitter(blocks, time)
    em.lines += ["def run(n0, n1, rb, va, rs, rbi=0):", "    for n in range(n0, n1):", f"{IND}t = {time.expr('n')}"]
    em.render(plan, IND)
    _record(em.lines, em.ns, IND, record_every, typed)
    em.lines.append("    return None")
    return "\n".join(em.lines) + "\n", em.ns


IND = "        "

#: A tick of the loop as a tree of operations, shared by the Python and the C back ends
#: (:func:`loop_plan`). Each is a tuple whose first item names it:
#:
#: - ``("transfer", b, k, src, j, factor, offset)``: Real input ``k`` of block ``b`` from output
#:   ``j`` of block ``src``: ``factor * x + offset``, the product only when ``factor != 1``, the
#:   sum only when ``offset != 0`` (``x + 0.0`` would turn -0.0 into 0.0);
#: - ``("ctransfer", b, c, k, src, j, mapping)``: the same for channel ``c`` (through ``mapping``);
#: - ``("set", b)``, ``("cset", b, c)``: the batched set of the Real inputs / of channel ``c``;
#: - ``("step", b, multiple, last, partial)``: ``do_step`` from ``t`` (``multiple`` None) or from
#:   the start of the period ``(n // m) * m``, with step ``h_b``, or ``hl_b`` on the tick ``last``
#:   (``"end"``: ``N - 1``; ``"period"``: the first tick of the last period) when ``partial``;
#: - ``("get", b, private)``, ``("cget", b, c, private)``: the batched get into the value vector
#:   (or the private outputs of a multi-rate Jacobi component);
#: - ``("publish", b)``, ``("cpublish", b, c)``: the private outputs into the value vector;
#: - ``("if", cond, body)``: ``cond`` ``("end", m, partial)``: ``(n + 1) % m == 0`` (or the last
#:   tick, when ``partial``); ``("start", m)``: ``n % m == 0``.
Op = tuple


def loop_plan(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase) -> list[Op]:
    """The operations of one tick of the stepping loop (see :data:`Op`)."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algorithm!r}; expected one of {', '.join(ALGORITHMS)}")
    if algorithm == GAUSS_SEIDEL:
        return _gauss_seidel(blocks, order, time)
    return _jacobi(blocks, order, time)


def _partial(b: Block, time: TimeBase) -> bool:
    """Whether the component's last step differs from its regular one."""
    return time.ticks % b.multiple != 0 or time.short_last


def _inputs(b: Block) -> list[Op]:
    """Transfers into the component's inputs, then its batched sets."""
    ops: list[Op] = [("transfer", b.index, k, src, j, factor, offset) for k, src, j, factor, offset in b.transfers]
    for c, ch in enumerate(b.channels):
        ops += [("ctransfer", b.index, c, k, src, j, mapping) for k, src, j, mapping in ch.transfers]
    if b.n_in:
        ops.append(("set", b.index))
    return ops + [("cset", b.index, c) for c, ch in enumerate(b.channels) if ch.n_in]


def _outputs(b: Block, private: bool) -> list[Op]:
    ops: list[Op] = [("get", b.index, private)] if b.n_out else []
    return ops + [("cget", b.index, c, private) for c, ch in enumerate(b.channels) if ch.n_out]


def _gauss_seidel(blocks: Sequence[Block], order: Sequence[int], time: TimeBase) -> list[Op]:
    """Each component in order: transfers, set, step (multi-rate: at the end of its period)."""
    plan: list[Op] = []
    for idx in order:
        b = blocks[idx]
        m, partial = b.multiple, _partial(b, time)
        ops = _inputs(b) + [("step", b.index, None if m == 1 else m, "end", partial)] + _outputs(b, False)
        plan += ops if m == 1 else [("if", ("end", m, partial), ops)]
    return plan


def _jacobi(blocks: Sequence[Block], order: Sequence[int], time: TimeBase) -> list[Op]:
    """Every component reads the values of ``t_n``, then all step; multi-rate outputs are
    published at the end of their period (a partial last period starts with the shorter step)."""
    plan: list[Op] = []
    for idx in order:
        b = blocks[idx]
        plan += _inputs(b) if b.multiple == 1 else [("if", ("start", b.multiple), _inputs(b))]
    for idx in order:
        b = blocks[idx]
        m, partial = b.multiple, _partial(b, time)
        ops = [("step", b.index, None, "period", partial)] + _outputs(b, m > 1)
        plan += ops if m == 1 else [("if", ("start", m), ops)]
    for idx in order:
        b = blocks[idx]
        if b.multiple > 1:
            ops = ([("publish", b.index)] if b.n_out else []) + [
                ("cpublish", b.index, c) for c, ch in enumerate(b.channels) if ch.n_out]
            plan += [("if", ("end", b.multiple, _partial(b, time)), ops)]
    return plan


#: The FMI function each failure check names (the C loop reports its position in this tuple).
FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")


class _Emitter:
    """Python source lines of a loop plan (:func:`loop_plan`) and the namespace they run in."""

    def __init__(self, blocks: Sequence[Block], time: TimeBase) -> None:
        self.blocks, self.time, self.lines = blocks, time, []
        self.ns: dict[str, Any] = {"memmove": ctypes.memmove}
        for b in blocks:
            i = b.index
            self.ns.update({f"c{i}": b.handle, f"ds{i}": b.do_step, f"gr{i}": b.get_real, f"sr{i}": b.set_real,
                            f"vo{i}": b.out_vrs, f"vi{i}": b.in_vrs, f"O{i}": b.out_values, f"I{i}": b.in_values,
                            f"P{i}": b.private_out, f"h{i}": time.span(b.multiple),
                            f"hl{i}": time.last_step(b.multiple)})
            for k, ch in enumerate(b.channels):
                self.ns.update({f"G{i}_{k}": ch.get, f"S{i}_{k}": ch.set, f"O{i}_{k}": ch.out_values,
                                f"I{i}_{k}": ch.in_values, f"P{i}_{k}": ch.private_out})
                self.ns.update({f"M{i}_{k}_{t[0]}": t[3] for t in ch.transfers if t[3]})

    def render(self, plan: Sequence[Op], indent: str) -> None:
        for op in plan:
            getattr(self, "op_" + op[0])(indent, *op[1:])

    def check(self, indent: str, i: int, call: str, function: str) -> None:
        self.lines += [f"{indent}s = {call}", f"{indent}if s > 1: return (n, {i}, '{function}', s)"]

    def op_if(self, indent: str, cond: tuple, body: Sequence[Op]) -> None:
        if not body:
            return
        if cond[0] == "start":
            self.lines.append(f"{indent}if n % {cond[1]} == 0:")
        else:
            last = f" or n == {self.time.ticks - 1}" if cond[2] else ""
            self.lines.append(f"{indent}if (n + 1) % {cond[1]} == 0{last}:")
        self.render(body, indent + "    ")

    def op_transfer(self, indent: str, i: int, k: int, src: int, j: int, factor: float, offset: float) -> None:
        expr = f"O{src}[{j}]"
        if factor != 1.0:
            expr = f"{factor!r} * {expr}"
        if offset != 0.0:
            expr = f"{expr} + {offset!r}"
        self.lines.append(f"{indent}I{i}[{k}] = {expr}")

    def op_ctransfer(self, indent: str, i: int, c: int, k: int, src: int, j: int, mapping: Any) -> None:
        sc = _channel_index(self.blocks[src], self.blocks[i].channels[c].kind)
        if mapping:
            self.lines += [f"{indent}x = O{src}_{sc}[{j}]", f"{indent}I{i}_{c}[{k}] = M{i}_{c}_{k}.get(x, x)"]
        else:
            self.lines.append(f"{indent}I{i}_{c}[{k}] = O{src}_{sc}[{j}]")

    def op_set(self, indent: str, i: int) -> None:
        self.check(indent, i, f"sr{i}(c{i}, vi{i}, {self.blocks[i].n_in}, I{i})", "fmi2SetReal")

    def op_cset(self, indent: str, i: int, c: int) -> None:
        self.check(indent, i, f"S{i}_{c}(I{i}_{c})", f"fmi2Set{FMI_NAME[self.blocks[i].channels[c].kind]}")

    def op_step(self, indent: str, i: int, multiple: int | None, last: str, partial: bool) -> None:
        start = "t" if multiple is None else self.time.expr(f"(n // {multiple}) * {multiple}")
        N, m = self.time.ticks, self.blocks[i].multiple
        tick = N - 1 if last == "end" else ((N - 1) // m) * m
        h = f"(h{i} if n != {tick} else hl{i})" if partial else f"h{i}"
        self.check(indent, i, f"ds{i}(c{i}, {start}, {h}, 1)", "fmi2DoStep")

    def op_get(self, indent: str, i: int, private: bool) -> None:
        target = "P" if private else "O"
        self.check(indent, i, f"gr{i}(c{i}, vo{i}, {self.blocks[i].n_out}, {target}{i})", "fmi2GetReal")

    def op_cget(self, indent: str, i: int, c: int, private: bool) -> None:
        target = "P" if private else "O"
        self.check(indent, i, f"G{i}_{c}({target}{i}_{c})", f"fmi2Get{FMI_NAME[self.blocks[i].channels[c].kind]}")

    def op_publish(self, indent: str, i: int) -> None:
        self.lines.append(f"{indent}O{i}[:] = P{i}")

    def op_cpublish(self, indent: str, i: int, c: int) -> None:
        self.lines.append(f"{indent}O{i}_{c}[:] = P{i}_{c}[:{self.blocks[i].channels[c].n_out}]")


def _channel_index(block: Block, kind: str) -> int:
    return next(k for k, ch in enumerate(block.channels) if ch.kind == kind)


def _record(L: list[str], ns: dict[str, Any], ind: str, record_every: int, typed: TypedRecord | None) -> None:
    """The lines that copy the values into the record after a tick."""
    rows: list[str] = ["memmove(rb + ROW * rs, va, rs)"]
    if typed is not None and typed.int_row_bytes:
        ns.update({"rsi": typed.int_row_bytes, "vai": typed.int_vector})
        rows.append("memmove(rbi + ROW * rsi, vai, rsi)")
    if typed is not None and typed.strings is not None:
        ns.update({"SREC": typed.strings, "snap": typed.snapshot})
        rows.append("SREC[ROW] = snap()")
    if record_every == 1:
        L.extend(f"{ind}{r.replace('ROW', '(n + 1)')}" for r in rows)
    else:
        L.append(f"{ind}if (n + 1) % {record_every} == 0:")
        L.extend(f"{ind}    {r.replace('ROW', f'((n + 1) // {record_every})')}" for r in rows)


def compile_loop(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase,
                 record_every: int = 1, typed: TypedRecord | None = None) -> tuple[Callable[..., Any], str]:
    """The stepping loop as a function (see :func:`generate_loop`) and its source.

    The source is registered with :mod:`linecache` under a name unique to it, so a traceback
    through the loop shows the generated lines like those of any module.
    """
    import hashlib
    import linecache

    source, ns = generate_loop(blocks, order, algorithm, time, record_every, typed)
    filename = f"<ipcosim stepping loop {hashlib.sha1(source.encode()).hexdigest()[:12]}>"
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    code = compile(source, filename, "exec")
    exec(code, ns)  # noqa: S102 -- source generated above from the system's structure only
    return ns["run"], source
