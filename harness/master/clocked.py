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
from fractions import Fraction
from typing import Any, Sequence

from ipcosim.harness.master.clocks import Clocking, exact_seconds
from ipcosim.harness.master.slave import OK, TERMINATE, WARNING, FMU3Slave, SlaveError, load_library
from ipcosim.harness.master.system import Variable


class ClockedSlave(FMU3Slave):
    """An FMI 3.0 co-simulation FMU with clocks, run in Event Mode at their ticks (see the module)."""

    def __init__(self, instance: Any, unzip_dir: Any, clocking: Clocking, logging_on: bool = True,
                 library: Any = None) -> None:
        super().__init__(instance, unzip_dir, logging_on=logging_on, library=library)
        self.clocking = clocking
        self._start = Fraction(0)
        self._next: list[Fraction] = []  # next tick of each input clock, exact
        self._pending: dict[int, float] = {}  # clocked input vr -> value for the next tick
        self._held: dict[int, float] = {}  # clocked output vr -> value read at the last tick
        self.ticks = [0] * len(clocking.inputs())
        #: Every Event Mode the slave held: (time, names of the clocks active there).
        self.events: list[tuple[float, tuple[str, ...]]] = []
        self._failed = ""

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
        self._next = [c.tick(0, self._start) for c in self.clocking.inputs()]
        self._next_f = [float(x) for x in self._next]
        self._tol = [1e-9 * float(c.interval) for c in self.clocking.inputs()]
        self._plans: dict[tuple[int, ...], Any] = {}

    def exit_initialization_mode(self) -> None:
        self._call("fmi3ExitInitializationMode")
        self.state = "stepping"
        status = self._event(float(self._start), entered=True)
        if status > WARNING and status != TERMINATE:
            raise self.fail(self._failed, status, float(self._start))

    # ---------------------------------------------------------------- values
    def _clocked_vars(self, causality: str) -> list[Variable]:
        return [v for v in self.instance.model.variables.values()
                if v.causality == causality and v.vr in self.clocking.clocked]

    def raw(self) -> tuple[Any, Any, Any, Any]:
        handle, do_step, get_real, set_real = super().raw()
        f = self._fmu._functions
        ds = f["fmi3DoStep"]
        refs = [ctypes.byref(x) for x in self._flags]
        term = self._flags[1]
        pending, held = self._pending, self._held
        clocked_in = {v.vr for v in self._clocked_vars("input")}
        clocked_out = {v.vr for v in self._clocked_vars("output")}

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
        clocks = self.clocking.inputs()
        for k in due:
            self.ticks[k] += 1
            self._next[k] = clocks[k].tick(self.ticks[k], self._start)
            self._next_f[k] = float(self._next[k])
        self.events.append((t, tuple(clocks[k].name for k in due)))
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
