"""Co-simulation algorithms: the order in which components step, their step multiples and the
time base.

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

The loop for a given system is planned once per execution
(:func:`ipcosim.harness.master.plan.loop_plan`: the operations of a tick, one batched set and
one batched get per component and step) and the plan rendered as Python source
(:mod:`ipcosim.harness.master.pyloop`) or as C (:mod:`ipcosim.harness.master.cloop`).
"""
from __future__ import annotations

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


