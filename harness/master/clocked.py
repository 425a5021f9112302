"""The slave of a clocked FMI 3.0 co-simulation FMU: Event Mode at every tick of its input clocks.

Instantiated with ``eventModeUsed = fmi3True``. The master steps it so that every tick of its
input clocks ends one of its steps (:func:`~ipcosim.harness.master.clocks.clock_multiple`); its
``do_step`` then runs, as FMI 3.0 (2.2.8, 4.2) says:

1. ``fmi3DoStep`` to the tick (Step Mode);
2. ``fmi3EnterEventMode``; ``fmi3SetClock`` on the input clocks that tick there; ``fmi3SetFloat64``
   of their clocked inputs (the values the master handed over for this step);
3. ``fmi3GetFloat64`` of the clocked outputs of the active clocks (the partition evaluated while
   its clock is active), ``fmi3GetClock`` of the output clocks and their clocked outputs;
4. ``fmi3UpdateDiscreteStates`` until it asks for no further instant; ``fmi3EnterStepMode``.

Leaving initialization enters Event Mode (``eventModeUsed``): the ticks at the start time are
handled there (the same 2-4). Clocked variables are set and read only in those instants: between
them the master's value store holds the clocked outputs read at the last tick (what the FMU
holds), and the clocked inputs wait for the next one. Ticks are compared with exact times
(:class:`~ipcosim.harness.master.clocks.Clock`), never accumulated in floating point.
"""
from __future__ import annotations

import ctypes
import math
from fractions import Fraction
from typing import Any, Sequence

from ipcosim.harness.master.clocks import Clocking, clocking, exact_seconds
from ipcosim.harness.master.clockstep import FAILED
from ipcosim.harness.master.fmi3_slave import FMU3Slave
from ipcosim.harness.master.fmu_slave import load_library
from ipcosim.harness.master.slave import OK, TERMINATE, WARNING, SlaveError
from ipcosim.harness.master.slaves import SPECIAL_SLAVES
from ipcosim.harness.master.system import Variable


class ClockedSlave(FMU3Slave):
    """An FMI 3.0 co-simulation FMU with clocks, run in Event Mode at their ticks (see the module)."""

    def __init__(self, instance: Any, unzip_dir: Any, clocking: Clocking, logging_on: bool = True,
                 library: Any = None) -> None:
        super().__init__(instance, unzip_dir, logging_on=logging_on, library=library)
        self.clocking = clocking
        self._start = Fraction(0)
        self._exact: list[tuple[int, int, int]] = []  # each input clock's ticks as integers (see setup)
        self._next_f: list[float] = []  # the time of each input clock's next tick
        self._pending: dict[int, float] = {}  # clocked input vr -> value for the next tick
        self._held: dict[int, float] = {}  # clocked output vr -> value read at the last tick
        self.ticks = [0] * len(clocking.inputs())
        self._events = 0  # Event Modes held by the Python calls (the C record counts its own)
        self._failed = ""
        self._record: Any = None  # the C record (clockstep) when the C functions serve this FMU
        self._lib: Any = None

    # ---------------------------------------------------------------- life cycle
    def instantiate(self) -> None:
        if self._fmu is None:
            self._fmu = load_library(self.instance, self.unzip_dir)

        def log(env: Any, status: int, category: bytes | None, message: bytes | None) -> None:
            self._log(env, None, status, category, message)

        try:
            self._fmu.instantiate(loggingOn=self.logging_on, eventModeUsed=True, logMessage=log)
        except Exception as exc:  # noqa: BLE001
            self.state = "failed-instantiate"
            msgs = self.messages()
            raise SlaveError(f"component {self.label()}: fmi3InstantiateCoSimulation (eventModeUsed) failed ({exc})"
                             + (f": {msgs[-1]}" if msgs else ""), self.name, "fmi3InstantiateCoSimulation") from None
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        self._uds = [ctypes.c_bool() for _ in range(5)] + [ctypes.c_double()]
        self.state = "instantiated"

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        super().setup_experiment(start_time, stop_time)
        self._start = exact_seconds(start_time)
        # tick i of clock k is (first[k] + i * every[k]) / scale[k] exactly (integers: no drift), and the
        # true division of two Python integers is its correctly rounded floating-point time
        self._exact = [_integers(c.tick(0, self._start), c.interval) for c in self.clocking.inputs()]
        self._next_f = [first / scale for first, _, scale in self._exact]
        self._tol = [1e-9 * float(c.interval) for c in self.clocking.inputs()]
        self._plans: dict[tuple[int, ...], Any] = {}

    def exit_initialization_mode(self) -> None:
        self._call("fmi3ExitInitializationMode")
        self.state = "stepping"
        if self._record is not None:
            status = self._lib.ipcosim_clocked_event(ctypes.byref(self._record), float(self._start), 1)
            self._failed = FAILED[self._record.failed]
        else:
            status = self._event(float(self._start), entered=True)
        if status > WARNING and status != TERMINATE:
            raise self.fail(self._failed, status, float(self._start))

    # ---------------------------------------------------------------- values
    def _clocked_vars(self, causality: str) -> list[Variable]:
        return [v for v in self.instance.model.variables.values()
                if v.causality == causality and v.vr in self.clocking.clocked]

    def raw(self) -> tuple[Any, Any, Any, Any]:
        compiled = self._compiled()
        if compiled is not None:
            return compiled
        return self._python_raw()

    def _compiled(self) -> tuple[Any, Any, Any, Any] | None:
        """The C functions of :mod:`~ipcosim.harness.master.clockstep` over this FMU, or None where they
        cannot serve it (no compiler, output clocks, too many clocks or variables, ticks beyond 2^53)."""
        from ipcosim.harness.master import clockstep

        clocks = self.clocking.inputs()
        ins, outs = self._clocked_vars("input"), self._clocked_vars("output")
        if (self.clocking.outputs() or len(clocks) > clockstep.MAX_CLOCKS or len(ins) > clockstep.MAX_VARS
                or len(outs) > clockstep.MAX_VARS or any(max(x) >= 2 ** 40 for x in self._exact)):
            return None
        lib = clockstep.functions()
        if lib is None:
            return None
        f = self._fmu._functions
        rec = clockstep.Record()
        rec.inst = self._fmu.component
        for field, name in (("do_step", "DoStep"), ("enter_event", "EnterEventMode"), ("enter_step", "EnterStepMode"),
                            ("set_clock", "SetClock"), ("set", "SetFloat64"), ("get", "GetFloat64"),
                            ("update", "UpdateDiscreteStates")):
            setattr(rec, field, ctypes.cast(f[f"fmi3{name}"], ctypes.c_void_p).value)
        rec.nclocks = len(clocks)
        bit = {c.vr: 1 << k for k, c in enumerate(clocks)}
        for k, (c, (first, every, scale)) in enumerate(zip(clocks, self._exact)):
            rec.clock_vr[k], rec.first[k], rec.every[k], rec.scale[k] = c.vr, first, every, scale
            rec.next[k], rec.tol[k] = self._next_f[k], self._tol[k]
        for count, vr_field, mask_field, variables in (("nin", "in_vr", "in_mask", ins),
                                                        ("nout", "out_vr", "out_mask", outs)):
            setattr(rec, count, len(variables))
            for j, v in enumerate(variables):
                getattr(rec, vr_field)[j] = v.vr
                getattr(rec, mask_field)[j] = sum(bit.get(c, 0) for c in self.clocking.clocked[v.vr])
        for j, v in enumerate(ins):
            rec.pending[j] = self._pending.get(v.vr, 0.0)
        self._record, self._lib = rec, lib
        return (ctypes.c_void_p(ctypes.addressof(rec)), lib.ipcosim_clocked_do_step, lib.ipcosim_clocked_get,
                lib.ipcosim_clocked_set)

    @property
    def event_count(self) -> int:
        """How many Event Modes the slave held (leaving initialization included)."""
        return int(self._record.events) if self._record is not None else self._events

    def _python_raw(self) -> tuple[Any, Any, Any, Any]:
        handle, do_step, get_real, set_real = super().raw()
        f = self._fmu._functions
        ds = f["fmi3DoStep"]
        refs = [ctypes.byref(x) for x in self._flags]
        term = self._flags[1]
        pending, held = self._pending, self._held
        clocked_in = {v.vr for v in self._clocked_vars("input")}
        clocked_out = {v.vr for v in self._clocked_vars("output")}
        all_in: dict[int, bool] = {}  # value-reference array -> all of them clocked inputs (outputs)
        all_out: dict[int, bool] = {}

        def step(c: Any, t: float, h: float, flag: int) -> int:
            status = ds(c, t, h, True, *refs)
            if status > WARNING:
                return status
            if term.value:
                return TERMINATE
            end = t + h
            for nxt, tol in zip(self._next_f, self._tol):
                if abs(end - nxt) <= tol:
                    return self._event(end, entered=False)
            return OK

        def get(c: Any, vrs: Any, n: int, out: Any) -> int:
            if self.state != "stepping":
                return get_real(c, vrs, n, out)
            if all_out.get(id(vrs)):
                out[:n] = [held.get(vr, 0.0) for vr in vrs[:n]]
                return OK
            all_out[id(vrs)] = all(vrs[i] in clocked_out for i in range(n))
            for i in range(n):
                vr = vrs[i]
                if vr in clocked_out:
                    out[i] = held.get(vr, 0.0)
                else:
                    one = (ctypes.c_double * 1)()
                    status = get_real(c, (ctypes.c_uint * 1)(vr), 1, one)
                    if status > WARNING:
                        return status
                    out[i] = one[0]
            return OK

        def put(c: Any, vrs: Any, n: int, values: Any) -> int:
            if self.state == "stepping" and all_in.get(id(vrs)):
                pending.update(zip(vrs[:n], values[:n]))
                return OK
            all_in[id(vrs)] = all(vrs[i] in clocked_in for i in range(n))
            for i in range(n):
                if vrs[i] in clocked_in:
                    pending[vrs[i]] = values[i]
            if self.state != "stepping":
                return set_real(c, vrs, n, values)
            free = [i for i in range(n) if vrs[i] not in clocked_in]
            if not free:
                return OK
            return set_real(c, (ctypes.c_uint * len(free))(*[vrs[i] for i in free]), len(free),
                            (ctypes.c_double * len(free))(*[values[i] for i in free]))

        return handle, step, get, put

    # ---------------------------------------------------------------- events
    def _due(self, t: float) -> list[int]:
        """The input clocks (indices) ticking at ``t`` (a tick's correctly rounded time, within rounding)."""
        return [k for k, (nxt, tol) in enumerate(zip(self._next_f, self._tol)) if abs(t - nxt) <= tol]

    def _plan(self, due: tuple[int, ...]) -> tuple[list[tuple[str, tuple]], list[int], Any, Any, Any]:
        """The calls of an event where the clocks ``due`` tick, made once: SetClock's arguments, the
        clocked inputs (value references), their value buffer, and the outputs to read and their buffer."""
        clocks = self.clocking.inputs()
        vrs = [clocks[k].vr for k in due]
        active = set(vrs)
        ins = [v.vr for v in self._clocked_vars("input") if set(self.clocking.clocked[v.vr]) & active]
        outs = [v.vr for v in self._clocked_vars("output") if set(self.clocking.clocked[v.vr]) & active]
        in_buf = (ctypes.c_double * max(len(ins), 1))()
        on = (ctypes.c_bool * len(vrs))(*([True] * len(vrs)))
        calls = [("fmi3SetClock", ((ctypes.c_uint * len(vrs))(*vrs), len(vrs), on))]
        if ins:
            calls.append(("fmi3SetFloat64", ((ctypes.c_uint * len(ins))(*ins), len(ins), in_buf, len(ins))))
        return calls, ins, in_buf, (ctypes.c_uint * max(len(outs), 1))(*outs), outs

    def _event(self, t: float, entered: bool) -> int:
        """Event Mode at ``t`` if a clock ticks there (always on leaving initialization)."""
        due = tuple(self._due(t))
        if not due and not entered:
            return OK
        f = self._fmu._functions
        c = self._fmu.component
        if not entered:
            status = f["fmi3EnterEventMode"](c)
            if status > WARNING:
                self._failed = "fmi3EnterEventMode"
                return status
        if due:
            plan = self._plans.get(due) or self._plans.setdefault(due, self._plan(due))
            calls, ins, in_buf, out_vrs, outs = plan
            for i, vr in enumerate(ins):
                in_buf[i] = self._pending.get(vr, 0.0)
            for name, args in calls:
                status = f[name](c, *args)
                if status > WARNING:
                    self._failed = name
                    return status
            status = self._read_outputs(out_vrs, outs)
            if status > WARNING:
                return status
        status = self._update()
        if status > WARNING:
            return status
        for k in due:
            self.ticks[k] += 1
            first, every, scale = self._exact[k]
            self._next_f[k] = (first + self.ticks[k] * every) / scale
        self._events += 1
        status = f["fmi3EnterStepMode"](c)
        if status > WARNING:
            self._failed = "fmi3EnterStepMode"
        return status

    def _read_outputs(self, out_vrs: Any, outs: list[int]) -> int:
        """The clocked outputs of the active input clocks, then those of the output clocks that tick."""
        f = self._fmu._functions
        c = self._fmu.component
        if outs:
            buf = (ctypes.c_double * len(outs))()
            status = f["fmi3GetFloat64"](c, out_vrs, len(outs), buf, len(outs))
            if status > WARNING:
                self._failed = "fmi3GetFloat64"
                return status
            self._held.update(zip(outs, buf))
        clocks = self.clocking.outputs()
        if not clocks:
            return OK
        state = (ctypes.c_bool * len(clocks))()
        status = f["fmi3GetClock"](c, (ctypes.c_uint * len(clocks))(*[o.vr for o in clocks]), len(clocks), state)
        if status > WARNING:
            self._failed = "fmi3GetClock"
            return status
        ticking = {o.vr for o, on in zip(clocks, state) if on}
        vrs = [v.vr for v in self._clocked_vars("output") if set(self.clocking.clocked[v.vr]) & ticking]
        if vrs:
            buf = (ctypes.c_double * len(vrs))()
            status = f["fmi3GetFloat64"](c, (ctypes.c_uint * len(vrs))(*vrs), len(vrs), buf, len(vrs))
            if status > WARNING:
                self._failed = "fmi3GetFloat64"
                return status
            self._held.update(zip(vrs, buf))
        return OK

    def _update(self, limit: int = 100) -> int:
        """``fmi3UpdateDiscreteStates`` until no further super-dense instant is asked for."""
        f = self._fmu._functions
        refs = [ctypes.byref(x) for x in self._uds]
        for _ in range(limit):
            status = f["fmi3UpdateDiscreteStates"](self._fmu.component, *refs)
            if status > WARNING:
                self._failed = "fmi3UpdateDiscreteStates"
                return status
            if self._uds[1].value:
                return TERMINATE
            if not self._uds[0].value:
                return OK
        self._failed = "fmi3UpdateDiscreteStates (did not converge)"
        return 3

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        super().set_values(variables, values)
        for var, value in zip(variables, values):
            if var.vr in self.clocking.clocked and var.causality == "input":
                self._pending[var.vr] = value


def _integers(first: Fraction, interval: Fraction) -> tuple[int, int, int]:
    """``(a, b, d)`` with ``first = a / d`` and ``interval = b / d``: tick ``i`` is ``(a + i b) / d``."""
    scale = first.denominator * interval.denominator // math.gcd(first.denominator, interval.denominator)
    return int(first * scale), int(interval * scale), scale


def clocked_slave(instance: Any, unzip_dir: Any, logging_on: bool, library: Any) -> ClockedSlave | None:
    """The :class:`ClockedSlave` of an FMI 3.0 FMU with clocks, else None (the plain slaves serve it)."""
    found = clocking(instance.model.path, instance.model.fmi_version, instance.name)
    if found is None:
        return None
    return ClockedSlave(instance, unzip_dir, found, logging_on=logging_on, library=library)


SPECIAL_SLAVES.append(clocked_slave)
