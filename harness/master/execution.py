"""The execution: owns the slaves, the algorithm, the observers and the manipulators of one
run, and runs the FMI 2.0 lifecycle::

    instantiate -> setupExperiment -> parameter bindings, overrides (start values)
    -> enterInitializationMode -> propagate outputs to inputs until a fixed point
    -> exitInitializationMode -> steps (manipulators, algorithm, observers)
    -> terminate -> freeInstance (every instance, also after a failure)

Parameters are set before entering initialization mode, where SSP 1.0 puts parameter
bindings and where libcosim sets start values, so FMUs that derive quantities on entering
initialization see them. Runtime values live here (the value vector), never on the parsed
scenario.

Values: all Real connectors of all components share one ``ctypes`` double vector (per
component its outputs, then its inputs); each component reads its outputs into and sets its
inputs from its own slice of it with one call, and the vector is copied to the record after
every step.
"""
from __future__ import annotations

import ctypes
import math
import time as _time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.harness.master import signals
from ipcosim.harness.master.algorithm import (
    ALGORITHMS,
    GAUSS_SEIDEL,
    InitializationError,
    StepSizeError,
    TimeBase,
    check_last_steps,
    gauss_seidel_order,
    step_multiples,
)
from ipcosim.harness.master.cloop import LOOPS, CLoop, LoopUnavailable, python_functions
from ipcosim.harness.master.manipulators import Manipulator, Overrides
from ipcosim.harness.master.observers import Observer
from ipcosim.harness.master.plan import Block, Channel, TypedRecord
from ipcosim.harness.master.pyloop import compile_loop
from ipcosim.harness.master.results import Result, RowWriter, SimulationError
from ipcosim.harness.master.slave import DISCARD, TERMINATE, FMUSlave, Slave
from ipcosim.harness.master.system import Instance, System, Variable, kind_of

SlaveFactory = Callable[[Instance], Slave]
#: The task's metrics of a run: ``task_metrics(chunks, names) -> dict``, where ``chunks()``
#: iterates over the recorded rows (structured arrays, a chunk at a time; it may be called more
#: than once) and ``names`` are the fields. Given by whoever knows the scenario (the master
#: knows no task): ``ipcosim.harness.engine`` gives ``ipcosim.fmus.metrics.streamed_task_metrics``.
TaskMetrics = Callable[[Callable[[], Iterable[np.ndarray]], Sequence[str]], Mapping[str, Any]]

#: At most this many ticks run between two looks at the record for non-finite values, at
#: pending signals, and two writes of the results.
CHUNK = 512
#: Wall-clock seconds a chunk of ticks aims at (fewer ticks per chunk for slow FMUs), so rows
#: reach the disk several times a second.
CHUNK_SECONDS = 0.2
#: Most communication steps of one run (a year at 1 kHz is 3e10).
MAX_TICKS = 10 ** 12


def check_times(start: float, stop: Any, step: Any, record_every: Any = 1,
                sources: Mapping[str, str] | None = None) -> TimeBase:
    """Check the run's times before anything is allocated; the integer time base.

    Parameters
    ----------
    start, stop, step : float
        [s]; ``stop`` and ``step`` as given (any type: checked here).
    record_every : int
        Record every n-th communication point.
    sources : mapping, optional
        Where ``start``, ``stop`` and ``step`` came from, for the messages, e.g.
        ``{"stop": "--stop-time", "step": "ssp/x/SystemStructure.ssd: baseStepSize"}``.

    Raises
    ------
    StepSizeError
        One line naming the value and where it came from.
    """
    src = {"start": "startTime", "stop": "--stop-time", "step": "--step", **(sources or {})}
    for key, value in (("step", step), ("stop", stop), ("start", start)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise StepSizeError(f"{src[key]} {value!r}: not a finite number of seconds")
    if not step > 0:
        raise StepSizeError(f"{src['step']} {step:g}: the step size must be a positive number of seconds")
    if not stop > start:
        raise StepSizeError(f"{src['stop']} {stop:g}: the stop time must be after the start time {start:g} s "
                            f"({src['start']})")
    if isinstance(record_every, bool) or not isinstance(record_every, int) or record_every < 1:
        raise StepSizeError(f"record_every = {record_every!r} must be a positive integer")
    ticks = (stop - start) / step
    if ticks > MAX_TICKS:
        raise StepSizeError(f"{src['stop']} {stop:g} s at {src['step']} {step:g} s: {ticks:.3g} steps, more than "
                            f"the limit {MAX_TICKS:.0e} (check the units: seconds)")
    return TimeBase.make(start, stop, step)  # a run that is not a whole number of steps ends with a short step


class NonFiniteError(SimulationError, FloatingPointError):
    """A component produced a NaN or infinite output."""


class Execution:
    """One run of a bound system.

    Parameters
    ----------
    system : System
        From :func:`ipcosim.harness.scenario.binding.bind`.
    step : float
        Communication step [s] (the master's tick).
    stop_time : float
        End of the run [s].
    start_time : float, optional
        Start [s]; default the scenario's DefaultExperiment startTime.
    algorithm : str
        ``gauss-seidel`` (default) or ``jacobi``.
    overrides : mapping of (component, variable) to value
        Start values applied after the bindings (already checked).
    observers, manipulators : sequences
        See :mod:`ipcosim.harness.master.observers`, :mod:`ipcosim.harness.master.manipulators`.
    slave_factory : callable, optional
        ``factory(instance) -> Slave``; default :class:`FMUSlave` on ``unzip_dirs``.
    unzip_dirs : mapping of component name to Path
        Extracted FMUs (for the default factory).
    record_every : int
        Record every n-th communication point.
    max_init_iterations : int
        Bound on the initialization fixed-point iterations.
    writer : RowWriter, optional
        Where the rows go while the run proceeds (default: a spool file only); see
        :meth:`row_fields` for its fields.
    task_metrics : callable, optional
        The task's metrics of the recorded rows (see :data:`TaskMetrics`), added to the
        result's metrics; None: only the run's own (timing, observers).
    loop : str
        The stepping loop: ``auto`` (default: the C loop of :mod:`ipcosim.harness.master.cloop`
        when every component's stepping functions are C functions, the system has Real
        connectors only and a C compiler is found; else the Python loop), ``c`` (the C loop, or
        :class:`~ipcosim.harness.master.cloop.LoopUnavailable` saying why not) or ``python``.
        The metadata's ``loop`` says which ran and why.
    """

    def __init__(self, system: System, step: float, stop_time: float, start_time: float | None = None,
                 algorithm: str = GAUSS_SEIDEL, overrides: Mapping[tuple[str, str], Any] | None = None,
                 observers: Sequence[Observer] = (), manipulators: Sequence[Manipulator] = (),
                 slave_factory: SlaveFactory | None = None, unzip_dirs: Mapping[str, Path] | None = None,
                 record_every: int = 1, max_init_iterations: int = 20, writer: RowWriter | None = None,
                 task_metrics: TaskMetrics | None = None, loop: str = "auto") -> None:
        if algorithm not in ALGORITHMS:
            raise StepSizeError(f"unknown algorithm {algorithm!r}; expected one of {', '.join(ALGORITHMS)}")
        if loop not in LOOPS:
            raise ValueError(f"loop {loop!r}: expected one of {', '.join(LOOPS)}")
        self.loop = loop
        #: Which loop ran: ``c``, or ``python`` with the reason in parentheses when C was not used.
        self.loop_used = ""
        self.system = system
        self.algorithm = algorithm
        start = system.scenario.experiment.start_time if start_time is None else float(start_time)
        self.timebase = TimeBase.make(start, stop_time, step)
        if not (isinstance(record_every, int) and record_every >= 1):
            raise StepSizeError(f"record_every = {record_every!r} must be a positive integer")
        self.record_every = record_every
        self.max_init_iterations = max_init_iterations
        self.overrides = dict(overrides or {})
        self.observers = list(observers)
        self.manipulators = [Overrides(self.overrides)] + list(manipulators)
        self.unzip_dirs = dict(unzip_dirs or {})
        self.slave_factory = slave_factory or self._fmu_slave
        self.instances = list(system.instances)
        self.index = {inst.name: i for i, inst in enumerate(self.instances)}
        self.multiples = step_multiples(system, self._planned_value, self.timebase.step)
        check_last_steps(self.timebase, self.multiples, self.instances)
        if algorithm == GAUSS_SEIDEL:
            self.order = [self.index[n] for n in gauss_seidel_order(system)]
        else:
            self.order = list(range(len(self.instances)))
        self.init_order = self.order
        self._layout()
        self.slaves: list[Slave] = []
        self.writer = writer
        self.task_metrics = task_metrics
        self.tick = 0
        self.init_iterations = 0
        self._loop_source = ""
        self.terminated_by: dict[str, Any] | None = None

    # ------------------------------------------------------------------ properties
    @property
    def n_ticks(self) -> int:
        return self.timebase.ticks

    @property
    def step_size(self) -> float:
        return self.timebase.step

    @property
    def start_time(self) -> float:
        return self.timebase.start

    @property
    def stop_time(self) -> float:
        return self.timebase.time(self.timebase.ticks)

    def time_of(self, n: int) -> float:
        """Simulated time after ``n`` ticks."""
        return self.timebase.time(n)

    @property
    def component_order(self) -> list[str]:
        return [self.instances[i].name for i in self.order]

    # ------------------------------------------------------------------ setup
    def _planned_value(self, comp: str, var: str) -> Any:
        if (comp, var) in self.overrides:
            return self.overrides[(comp, var)]
        return self.system.instance(comp).start_value(var)

    def _fmu_slave(self, instance: Instance) -> Slave:
        return FMUSlave(instance, self.unzip_dirs[instance.name])

    def _layout(self) -> None:
        """Place every Real connector in the value vector; build the record columns."""
        self._real_outputs: list[list[Variable]] = []
        self._real_inputs: list[list[Variable]] = []
        offsets = []
        pos = 0
        for inst in self.instances:
            outs = [v for v in inst.outputs if kind_of(v.type) == "real"]
            ins = [v for v in inst.inputs if kind_of(v.type) == "real"]
            self._real_outputs.append(outs)
            self._real_inputs.append(ins)
            offsets.append((pos, pos + len(outs)))
            pos += len(outs) + len(ins)
        self.n_values = pos
        self.values_c = (ctypes.c_double * (pos + 1))()  # +1: empty slices still map one element
        self.values = np.ctypeslib.as_array(self.values_c)[:pos]
        self._out_offset = [o for o, _ in offsets]
        self._in_offset = [i for _, i in offsets]
        self._slot: dict[tuple[str, str], int] = {}
        for k, inst in enumerate(self.instances):
            for j, v in enumerate(self._real_outputs[k]):
                self._slot[(inst.name, v.name)] = self._out_offset[k] + j
            for j, v in enumerate(self._real_inputs[k]):
                self._slot[(inst.name, v.name)] = self._in_offset[k] + j
                start = self._planned_value(inst.name, v.name)
                self.values[self._in_offset[k] + j] = float(start) if start is not None else 0.0
        self.output_slots = np.array([self._out_offset[k] + j for k in range(len(self.instances))
                                      for j in range(len(self._real_outputs[k]))], dtype=int)
        # record columns: every Real connector in SSD order; connected inputs are the
        # transformed source values (what the connection delivers at that time)
        self.columns: list[tuple[str, int, tuple[int, float, float] | None]] = []
        for inst in self.instances:
            for v in inst.connectors:
                if kind_of(v.type) != "real":
                    continue
                name = f"{inst.name}.{v.name}"
                link = self.system.link_into(inst.name, v.name)
                if link is not None:
                    src = self._slot[(link.src, link.src_var.name)]
                    self.columns.append((name, self._slot[(inst.name, v.name)], (src, link.factor, link.offset)))
                else:
                    self.columns.append((name, self._slot[(inst.name, v.name)], None))
        self._layout_typed()

    def _layout_typed(self) -> None:
        """Place the Integer and Boolean connectors in one ``c_int`` vector (per component:
        integer outputs, inputs, boolean outputs, inputs) and the String connectors in lists
        per component; describe every record column's kind in one place, ``column_kinds``
        (``time``, then every connector in SSD order: ``real``, ``integer``, ``boolean``, ``string``)."""
        self._typed: list[dict[str, tuple[list[Variable], list[Variable]]]] = []
        self._int_offset: dict[tuple[int, str], int] = {}
        self._strings: dict[int, tuple[list[bytes], list[bytes]]] = {}
        self._tslot: dict[tuple[str, str], tuple[str, int]] = {}  # (kind, int slot or string index)
        string_slots: list[tuple[list[bytes], int]] = []
        pos = 0
        for k, inst in enumerate(self.instances):
            groups = {}
            for kind in ("integer", "boolean", "string"):
                outs = [v for v in inst.outputs if kind_of(v.type) == kind]
                ins = [v for v in inst.inputs if kind_of(v.type) == kind]
                if not (outs or ins):
                    continue
                groups[kind] = (outs, ins)
                if kind == "string":
                    lists = ([b""] * len(outs), [b""] * len(ins))
                    self._strings[k] = lists
                    for lst, vs in zip(lists, (outs, ins)):
                        for j, v in enumerate(vs):
                            self._tslot[(inst.name, v.name)] = ("string", len(string_slots))
                            string_slots.append((lst, j))
                else:
                    self._int_offset[(k, kind)] = pos
                    for j, v in enumerate(outs + ins):
                        self._tslot[(inst.name, v.name)] = (kind, pos + j)
                    pos += len(outs) + len(ins)
            self._typed.append(groups)
        self.n_ints = pos
        self.ints_c = (ctypes.c_int * (pos + 1))()
        self.ints = np.ctypeslib.as_array(self.ints_c)[:pos]
        self._string_slots = string_slots
        for (comp, var), (kind, slot) in self._tslot.items():
            if self.instances[self.index[comp]].model.variables[var].causality == "input":
                self._store(kind, slot, self._planned_value(comp, var))
        self.column_kinds: dict[str, str] = {"time": "real"}
        self.typed_columns: list[tuple[str, str, int, tuple[int, dict[int, int]] | None]] = []
        for inst in self.instances:
            for v in inst.connectors:
                kind = kind_of(v.type)
                if kind is None:
                    continue
                self.column_kinds[f"{inst.name}.{v.name}"] = kind
                if kind == "real":
                    continue
                link = self.system.link_into(inst.name, v.name)
                src = (self._tslot[(link.src, link.src_var.name)][1], dict(link.mapping)) if link else None
                self.typed_columns.append((f"{inst.name}.{v.name}", kind, self._tslot[(inst.name, v.name)][1], src))

    def _store(self, kind: str, slot: int, value: Any) -> None:
        """Put a start value into the typed value store."""
        if kind == "string":
            lst, j = self._string_slots[slot]
            lst[j] = b"" if value is None else (value if isinstance(value, bytes) else str(value).encode())
        else:
            self.ints[slot] = int(bool(value)) if kind == "boolean" else int(value or 0)

    def _channels(self, k: int, slave: Slave) -> tuple[Channel, ...]:
        """The component's Integer, Boolean and String channels (see :class:`Channel`)."""
        out = []
        for kind, (outs, ins) in self._typed[k].items():
            if kind == "string":
                o_vals, i_vals = self._strings[k]
            else:
                off = self._int_offset[(k, kind)]
                o_vals = (ctypes.c_int * max(len(outs), 1)).from_buffer(self.ints_c, 4 * off)
                i_vals = (ctypes.c_int * max(len(ins), 1)).from_buffer(self.ints_c, 4 * (off + len(outs)))
            transfers = []
            for j, v in enumerate(ins):
                link = self.system.link_into(self.instances[k].name, v.name)
                if link is not None:
                    src = self.index[link.src]
                    src_j = [x.name for x in self._typed[src][kind][0]].index(link.src_var.name)
                    transfers.append((j, src, src_j, dict(link.mapping) or None))
            private = None
            if self.multiples[self.instances[k].name] > 1 and self.algorithm != GAUSS_SEIDEL and outs:
                private = [b""] * len(outs) if kind == "string" else (ctypes.c_int * len(outs))()
            get = slave.channel(kind, outs)[0] if outs else None
            put = slave.channel(kind, ins)[1] if ins else None
            out.append(Channel(kind, get, put, o_vals, i_vals, len(outs), len(ins), tuple(transfers), private))
        return tuple(out)

    def _typed_record(self) -> TypedRecord | None:
        if not self.n_ints and not self._string_slots:
            return None
        slots = self._string_slots
        return TypedRecord(int_row_bytes=4 * self.n_ints if self.n_ints else 0,
                           int_vector=ctypes.addressof(self.ints_c),
                           strings=self.record_s if slots else None,
                           snapshot=(lambda: tuple(lst[j] for lst, j in slots)) if slots else None)

    def _blocks(self) -> list[Block]:
        blocks = []
        for k, (inst, slave) in enumerate(zip(self.instances, self.slaves)):
            handle, do_step, get_real, set_real = slave.raw()
            outs, ins = self._real_outputs[k], self._real_inputs[k]
            n_out, n_in = len(outs), len(ins)
            out_values = (ctypes.c_double * max(n_out, 1)).from_buffer(self.values_c, 8 * self._out_offset[k])
            in_values = (ctypes.c_double * max(n_in, 1)).from_buffer(self.values_c, 8 * self._in_offset[k])
            transfers = []
            for j, v in enumerate(ins):
                link = self.system.link_into(inst.name, v.name)
                if link is None:
                    continue
                src = self.index[link.src]
                src_j = [x.name for x in self._real_outputs[src]].index(link.src_var.name)
                transfers.append((j, src, src_j, float(link.factor), float(link.offset)))
            m = self.multiples[inst.name]
            private = (ctypes.c_double * max(n_out, 1))() if (m > 1 and self.algorithm != GAUSS_SEIDEL) else None
            blocks.append(Block(index=k, name=inst.name, handle=handle, do_step=do_step, get_real=get_real,
                                set_real=set_real, out_vrs=(ctypes.c_uint * max(n_out, 1))(*[v.vr for v in outs]),
                                in_vrs=(ctypes.c_uint * max(n_in, 1))(*[v.vr for v in ins]),
                                out_values=out_values, in_values=in_values, n_out=n_out, n_in=n_in,
                                multiple=m, private_out=private, transfers=tuple(transfers),
                                channels=self._channels(k, slave)))
        return blocks

    # ------------------------------------------------------------------ manipulation API
    def set_start(self, component: str, variable: str, value: Any) -> None:
        """Set a start value (instantiated state; used by manipulators' ``initialize``)."""
        slave = self.slaves[self.index[component]]
        var = self.instances[self.index[component]].model.variables[variable]
        slave.set_values([var], [value])
        slot = self._slot.get((component, variable))
        if slot is not None and var.causality == "input":
            self.values[slot] = float(value)
        typed = self._tslot.get((component, variable))
        if typed is not None and var.causality == "input":
            self._store(typed[0], typed[1], value)

    def set_real(self, component: str, variable: str, value: float) -> None:
        """Set a Real variable now (manipulators' ``step``). For an input connector the value
        is also what the next batched set sends; a connected input is overwritten by its
        connection at the component's next step."""
        slot = self._slot.get((component, variable))
        var = self.instances[self.index[component]].model.variables[variable]
        if slot is not None and var.causality == "input":
            self.values[slot] = float(value)
        self.slaves[self.index[component]].set_values([var], [float(value)])

    def get(self, component: str, variable: str) -> Any:
        """Current value of a connector (from the value store): float, int, bool or str."""
        if (component, variable) in self._slot:
            return float(self.values[self._slot[(component, variable)]])
        kind, slot = self._tslot[(component, variable)]
        if kind == "string":
            lst, j = self._string_slots[slot]
            return lst[j].decode("utf-8", "replace")
        return bool(self.ints[slot]) if kind == "boolean" else int(self.ints[slot])

    # ------------------------------------------------------------------ run
    def row_names(self) -> list[str]:
        """Field names of the recorded rows: ``time``, then ``component.variable`` (every
        connector of every type, in SSD order)."""
        return list(self.column_kinds)

    def run(self) -> Result:
        """Run the lifecycle; always returns a Result (``result.error`` set on failure).

        Rows go to the writer chunk by chunk as the run proceeds (memory stays bounded).
        Every instance is terminated (when FMI allows it) and freed, also after a failure, a
        KeyboardInterrupt or a signal deferred by :mod:`ipcosim.harness.master.signals`
        (re-raised after cleanup with ``.result`` set).
        """
        self.writer = self.writer or RowWriter(self.row_fields())
        rows = CHUNK // self.record_every + 2  # the record holds at most a chunk of rows
        self.record = np.zeros((rows, max(self.n_values, 1)))
        self.record_i = np.zeros((rows, max(self.n_ints, 1)), dtype=np.int32)
        self.record_s: dict[int, tuple] = {}  # String rows by (absolute) row number
        self._base_row = 0
        self._last_emit = _time.monotonic()
        self._write_seconds = 0.0  # spent handing rows to the writer (results.csv): not the loop's
        error: BaseException | None = None
        interrupted: BaseException | None = None
        wall0 = _time.perf_counter()
        wall_loop = 0.0
        try:
            signals.check()
            self._instantiate()
            self._initialize()
            self._record_start()
            for obs in self.observers:
                obs.start(self)
            loop_t0, written0 = _time.perf_counter(), self._write_seconds
            self._step_all()
            wall_loop = _time.perf_counter() - loop_t0 - (self._write_seconds - written0)
        except KeyboardInterrupt as exc:
            interrupted = error = exc
            self._flush_pending()
        except Exception as exc:  # noqa: BLE001 -- reported in the Result, cleanup below
            error = exc.cause if isinstance(exc, _TickFailure) and exc.cause is not None else exc
            self._flush_pending()
        finally:
            cleanup_error = self._cleanup()
            if error is None and cleanup_error is not None:
                error = cleanup_error
            for obs in self.observers:
                try:
                    obs.finish(self, error)
                except Exception as exc:  # noqa: BLE001
                    error = error or exc
        wall = _time.perf_counter() - wall0
        task = self._task_metrics()
        result = self._result(self.writer.finish(), error, wall, wall_loop, task)
        if interrupted is not None:
            what = getattr(interrupted, "message", "interrupted")
            result.error = f"{what} at t = {self.time_of(self.tick):.6g} s"
            result.metadata["error"] = result.error
            result.metadata["status"] = "interrupted"
            interrupted.result = result  # type: ignore[attr-defined]  -- for callers that save it
            raise interrupted
        return result

    def _record_start(self) -> None:
        """Row 0: the values at the start time, after initialization, checked and written."""
        self.record[0, :self.n_values] = self.values
        self.record_i[0, :self.n_ints] = self.ints
        if self._string_slots:
            self.record_s[0] = tuple(lst[j] for lst, j in self._string_slots)
        self._check_finite(0, 1)
        self._emit(1)

    def _instantiate(self) -> None:
        for inst in self.instances:
            signals.check()
            slave = self.slave_factory(inst)
            self.slaves.append(slave)
            slave.instantiate()
        for slave in self.slaves:
            slave.setup_experiment(self.start_time, self.stop_time)
        for slave, inst in zip(self.slaves, self.instances):
            if inst.parameters:
                slave.set_values([v for v, _ in inst.parameters], [x for _, x in inst.parameters])
        for man in self.manipulators:
            man.initialize(self)

    def _initialize(self) -> None:
        """Enter initialization mode, propagate to a fixed point, exit initialization mode."""
        signals.check()
        for slave in self.slaves:
            slave.enter_initialization_mode()
        self.blocks = self._blocks()
        for b in self.blocks:  # every output as the FMUs compute it from their start values
            self._get_outputs(b, None)
        changed: list[str] = []
        for it in range(1, self.max_init_iterations + 1):
            signals.check()
            changed = self._sweep()
            self.init_iterations = it
            if not changed:
                break
        else:
            raise InitializationError(
                f"initialization did not reach a fixed point in {self.max_init_iterations} iterations; "
                f"still changing: {', '.join(changed)}", changed)
        if self.algorithm == GAUSS_SEIDEL:
            # Leave initialization mode component by component in step order, handing each the
            # outputs its upstream components computed on leaving (FMUs whose outputs are
            # "calculated" may compute them only in fmi2ExitInitializationMode).
            for idx in self.order:
                b = self.blocks[idx]
                self._transfer(b, [])
                self._set_inputs(b)
                self.slaves[idx].exit_initialization_mode()
                self._get_outputs(b, self.start_time)
        else:
            # Jacobi: every component leaves from the values of initialization mode, then the
            # outputs are read (what libcosim does); they reach the inputs at the first step.
            for idx in self.order:
                self.slaves[idx].exit_initialization_mode()
            for b in self.blocks:
                self._get_outputs(b, self.start_time)
        self._run_loop, self._loop_source = self._compile_loop()

    def _compile_loop(self) -> tuple[Callable[..., Any], str]:
        """The stepping loop this run uses (see the ``loop`` parameter) and its source;
        ``loop_used`` says which."""
        if self.loop != "python":
            why = ""
            slow = python_functions(self.blocks)
            if slow and self.loop == "auto":
                why = "components stepped by Python functions: " + ", ".join(slow)
            else:
                try:
                    cloop = CLoop(self.blocks, self.order, self.algorithm, self.timebase, self.record_every,
                                  self.record.shape[1] * 8, ctypes.addressof(self.values_c))
                    self.loop_used = "c"
                    return cloop.run, cloop.source
                except LoopUnavailable as exc:
                    if self.loop == "c":
                        raise LoopUnavailable(f"--loop c: the C stepping loop cannot run: {exc}") from None
                    why = str(exc)
            self.loop_used = f"python ({why})"
        else:
            self.loop_used = "python (forced)"
        return compile_loop(self.blocks, self.order, self.algorithm, self.timebase, self.record_every,
                            self._typed_record())

    def _sweep(self) -> list[str]:
        """One pass in step order: transfer, set inputs, read outputs; returns changed inputs."""
        changed: list[str] = []
        for idx in self.init_order:
            b = self.blocks[idx]
            self._transfer(b, changed)
            self._set_inputs(b)
            self._get_outputs(b, None)
        return changed

    def _set_inputs(self, b: Block) -> None:
        """Set every input of ``b`` from the value store (initialization)."""
        if b.n_in:
            status = b.set_real(b.handle, b.in_vrs, b.n_in, b.in_values)
            if status > 1:
                raise self.slaves[b.index].fail("fmi2SetReal", status, self.start_time)
        for ch in b.channels:
            if ch.n_in:
                status = ch.set(ch.in_values)
                if status > 1:
                    raise self.slaves[b.index].fail(f"fmi2Set{ch.kind.capitalize()}", status, self.start_time)

    def _transfer(self, b: Block, changed: list[str]) -> None:
        """Copy connected outputs into ``b``'s inputs; append the names of inputs that changed."""
        inputs = self._real_inputs[b.index]
        for k, src, j, factor, offset in b.transfers:
            new = factor * self.blocks[src].out_values[j] + offset
            old = b.in_values[k]
            if not (new == old or (math.isnan(new) and math.isnan(old))):
                b.in_values[k] = new
                changed.append(f"{b.name}.{inputs[k].name}")
        for ch in b.channels:
            ins = self._typed[b.index][ch.kind][1]
            for k, src, j, mapping in ch.transfers:
                src_ch = next(c for c in self.blocks[src].channels if c.kind == ch.kind)
                new = src_ch.out_values[j]
                new = mapping.get(new, new) if mapping else new
                if ch.in_values[k] != new:
                    ch.in_values[k] = new
                    changed.append(f"{b.name}.{ins[k].name}")

    def _get_outputs(self, b: Block, t: float | None) -> None:
        if b.n_out:
            status = b.get_real(b.handle, b.out_vrs, b.n_out, b.out_values)
            if status > 1:
                raise self.slaves[b.index].fail("fmi2GetReal", status, t if t is not None else self.start_time)
        for ch in b.channels:
            if ch.n_out:
                status = ch.get(ch.out_values)
                if status > 1:
                    raise self.slaves[b.index].fail(f"fmi2Get{ch.kind.capitalize()}", status,
                                                    t if t is not None else self.start_time)

    def _emit(self, rows: int) -> None:
        """Hand the record rows ``_base_row .. rows-1`` (absolute numbers) to the writer."""
        t0 = _time.perf_counter()
        k = rows - self._base_row
        if k > 0:
            self.writer.append(self._rows(self._base_row, k))
            if self.record_s:
                for row in range(self._base_row, rows):
                    self.record_s.pop(row, None)
            self._base_row = rows
        self._last_emit = _time.monotonic()
        self._write_seconds += _time.perf_counter() - t0

    def _flush_pending(self) -> None:
        """After an interruption: write the rows of the completed chunks still in the buffer."""
        if self._base_row > 0:  # stepping had started (row 0 written)
            try:
                self._emit(self.tick // self.record_every + 1)
            except Exception:  # noqa: BLE001 -- the first error is the one reported
                pass

    def _step_all(self) -> None:
        """Run every tick in chunks between observer/manipulator events, writing the rows of
        each chunk and looking at pending signals in between."""
        N = self.n_ticks
        row_bytes = self.record.shape[1] * 8
        int_row_bytes = self.record_i.shape[1] * 4
        va = ctypes.addressof(self.values_c)
        run = self._run_loop
        every = self.record_every
        due_man = {id(m): m.next_tick(-1) for m in self.manipulators}
        due_obs = {id(o): o.next_tick(0) for o in self.observers}
        n, chunk = 0, min(CHUNK, 16)
        while n < N:
            signals.check()
            for man in self.manipulators:
                if due_man[id(man)] == n:
                    man.step(self, n)
                    due_man[id(man)] = man.next_tick(n)
            target = min(N, n + chunk)
            for k in (*due_man.values(), *due_obs.values()):
                if k is not None and n < k < target:
                    target = k
            # the loop writes row r at rb + r * row_bytes: map this chunk's first row to record[0]
            rb = self.record.ctypes.data - self._base_row * row_bytes
            rbi = self.record_i.ctypes.data - self._base_row * int_row_bytes
            marks = [s.errors_logged for s in self.slaves]
            t0 = _time.perf_counter()
            failure = run(n, target, rb, va, row_bytes, rbi)
            if failure is not None:
                fn, idx, function, status = failure
                self.tick = fn
                rows = fn // every + 1
                self._check_finite(self._base_row, rows)
                self._emit(rows)
                slave = self.slaves[idx]
                logged_error = slave.errors_logged > marks[idx]
                if not logged_error and self._ended_by_fmu(idx, function, status):
                    self._record_last_successful(slave)
                    return
                err = slave.fail(function, status, self.time_of(fn))
                if status == DISCARD and function == "fmi2DoStep":
                    ended, query = slave.terminated()
                    why = ("but it logged an error in that step: a failure" if ended and logged_error
                           else "the FMU did not end the simulation")
                    err = type(err)(f"{err} ({query}, {why})", err.component, err.function, err.status, err.time)
                raise _TickFailure(str(err), rows, err)
            rows = target // every + 1
            self._check_finite(n // every + 1, rows)
            chunk = _next_chunk(chunk, target - n, _time.perf_counter() - t0)
            # write when the next chunk might not fit in the record buffer, and at least every
            # CHUNK_SECONDS (observers that need every tick make chunks of one tick)
            if (rows - self._base_row + chunk // every + 1 > len(self.record)
                    or _time.monotonic() - self._last_emit >= CHUNK_SECONDS):
                self._emit(rows)
            n = self.tick = target
            for obs in self.observers:
                if due_obs[id(obs)] == n:
                    obs.step(self, n)
                    due_obs[id(obs)] = obs.next_tick(n)
        self._emit(N // every + 1)

    def _ended_by_fmu(self, idx: int, function: str, status: int) -> bool:
        """Whether a failed ``do_step`` is a component ending the simulation itself (FMI 2.0:
        fmi2Discard and fmi2GetBooleanStatus(fmi2Terminated) true; FMI 3.0: terminateSimulation).
        The run then ends normally at ``self.tick``, the last communication point every component
        reached; the metadata names the component."""
        if function != "fmi2DoStep" or status not in (DISCARD, TERMINATE):
            return False
        slave = self.slaves[idx]
        ended, query = slave.terminated()
        if not ended:
            return False
        t, t_next = self.time_of(self.tick), self.time_of(self.tick + 1)
        self.terminated_by = {"component": slave.name, "model": slave.model_name, "time": t,
                              "note": f"component {slave.describe()} ended the simulation in its step from "
                                      f"t = {t:.6g} s to {t_next:.6g} s ({query}); the run ends at t = {t:.6g} s"}
        return True

    def _record_last_successful(self, slave: Any) -> None:
        """After a component ended the simulation within its step: the row at the time it reached
        there (its last successful time, when past the last full row), with every component's
        outputs as they are then -- the row FMPy's ``simulate_fmu`` records."""
        t, t_next = self.time_of(self.tick), self.time_of(self.tick + 1)
        t_last = slave.last_successful_time()
        if t_last is None or not t + 1e-12 * max(1.0, abs(t)) < t_last <= t_next:
            return
        for b in self.blocks:
            self._get_outputs(b, t_last)
        self.record[0, :self.n_values] = self.values
        self.record_i[0, :self.n_ints] = self.ints
        if self._string_slots:
            self.record_s[self._base_row] = tuple(lst[j] for lst, j in self._string_slots)
        row = self._rows(self._base_row, 1)
        row["time"] = t_last
        self._check_finite(self._base_row, self._base_row + 1)
        self.writer.append(row)
        self._base_row += 1
        assert self.terminated_by is not None
        self.terminated_by.update(last_successful_time=t_last, note=self.terminated_by["note"].replace(
            f"the run ends at t = {t:.6g} s", f"recorded up to its last successful time t = {t_last:.6g} s"))

    def _check_finite(self, row0: int, row1: int) -> None:
        """Raise for the first non-finite output in record rows ``row0 .. row1-1`` (absolute
        numbers, ``row0`` being the first row held in the record buffer); the rows before it
        are handed to the writer first."""
        if row1 <= row0 or not len(self.output_slots):
            return
        block = self.record[row0 - self._base_row:row1 - self._base_row][:, self.output_slots]
        if np.isfinite(block).all():
            return
        bad = ~np.isfinite(block)
        bad_row = int(np.argmax(bad.any(axis=1)))
        row = row0 + bad_row
        # of the outputs that went bad in that row, blame the one of the earliest component in
        # step order (the others most likely computed theirs from it)
        rank = {idx: pos for pos, idx in enumerate(self.order)}
        slots = [int(self.output_slots[c]) for c in np.flatnonzero(bad[bad_row])]
        slot = min(slots, key=lambda s: (rank[self._slot_owner(s)], s))
        k = self._slot_owner(slot)
        inst = self.instances[k]
        var = self._real_outputs[k][slot - self._out_offset[k]].name
        t = self.time_of(row * self.record_every)
        msg = (f"component {inst.name} ({inst.model.name}): output {inst.name}.{var} = "
               f"{float(self.record[row - self._base_row, slot])} at t = {t:.6g} s (non-finite value)")
        self._emit(row + 1)  # the bad row too: it shows what went wrong
        raise _TickFailure(msg, row + 1, NonFiniteError(msg))

    def _slot_owner(self, slot: int) -> int:
        """Index of the component whose outputs hold value-vector slot ``slot``."""
        for k in range(len(self.instances)):
            if self._out_offset[k] <= slot < self._in_offset[k]:
                return k
        raise KeyError(slot)

    def _cleanup(self) -> BaseException | None:
        """Terminate (where FMI allows) and free every instantiated slave; first error returned."""
        first: BaseException | None = None
        for slave in self.slaves:
            try:
                if slave.state not in ("failed", "failed-instantiate"):
                    slave.terminate()
            except Exception as exc:  # noqa: BLE001 -- keep freeing the others
                first = first or exc
            finally:
                try:
                    slave.free()
                except Exception as exc:  # noqa: BLE001
                    first = first or exc
        return first

    # ------------------------------------------------------------------ result
    def row_fields(self) -> list[tuple[str, str]]:
        """Name and numpy type of every recorded field: ``time``, then ``component.variable``
        (see :data:`COLUMN_DTYPE`)."""
        return [(n, COLUMN_DTYPE[k]) for n, k in self.column_kinds.items()]

    def _rows(self, first_row: int, rows: int) -> np.ndarray:
        """Record buffer rows ``0 .. rows-1`` (absolute ``first_row ..``) as a structured array
        of the row fields."""
        rec = self.record[:rows]
        data = np.zeros(rows, dtype=self.row_fields())
        ticks = (first_row + np.arange(rows)) * self.record_every
        if self.timebase.step_ns is not None:
            data["time"] = (self.timebase.start_ns + ticks * self.timebase.step_ns) / 1e9
        else:
            data["time"] = self.timebase.start + ticks * self.timebase.step
        data["time"][ticks >= self.n_ticks] = self.timebase.time(self.n_ticks)
        for name, slot, link in self.columns:
            if link is None:
                data[name] = rec[:, slot]
            else:
                src, factor, offset = link
                data[name] = factor * rec[:, src] + offset
        self._typed_rows(data, first_row)
        return data

    def _task_metrics(self) -> dict[str, Any]:
        """The task metrics from the rows written (a chunk at a time: bounded memory)."""
        if self.task_metrics is None:
            return {}
        try:
            return dict(self.task_metrics(self.writer.chunks, self.row_names()))
        except Exception as exc:  # noqa: BLE001 -- metrics must not hide the run's result
            return {"metrics_error": str(exc)}

    def _result(self, data: np.ndarray, error: BaseException | None, wall: float, wall_loop: float,
                task: dict[str, Any]) -> Result:
        rows = len(data)
        simulated = float(data["time"][-1] - data["time"][0]) if rows else 0.0
        metrics: dict[str, Any] = dict(task)
        metrics.update(timing_metrics(simulated, wall, wall_loop))
        for obs in self.observers:
            try:
                metrics.update(obs.metrics())
            except Exception as exc:  # noqa: BLE001
                metrics.setdefault("observer_errors", []).append(str(exc))
        message = None
        if error is not None:
            message = _one_line(error)
        sc = self.system.scenario
        metadata: dict[str, Any] = {
            "scenario": sc.name, "origin": sc.origin, "algorithm": self.algorithm,
            "start_time": self.start_time, "stop_time": self.stop_time, "step": self.step_size,
            "ticks": self.n_ticks,
            "ticks_done": self.tick if error is not None or self.terminated_by else self.n_ticks,
            "record_every": self.record_every, "loop": self.loop_used or None, "order": self.component_order,
            "step_multiples": dict(self.multiples),
            "initialization_iterations": self.init_iterations,
            "components": {i.name: {"model": i.model.name, "guid": i.model.guid,
                                    "fmu": str(i.model.path) if i.model.path else None,
                                    "swapped_from": i.swapped_from} for i in self.instances},
            "overrides": {f"{c}.{v}": x for (c, v), x in self.overrides.items()},
            "warnings": list(self.system.warnings), "notes": list(self.system.notes),
            "wall_time_s": wall, "loop_wall_time_s": wall_loop, "write_wall_time_s": self._write_seconds,
            "simulated_s": simulated,
            "status": "ok" if error is None else "failed", "error": message,
            "end_time": float(data["time"][-1]) if rows else None, "terminated_by": self.terminated_by,
            "fmu_messages": {s.name: s.messages()[-5:] for s in self.slaves if s.messages()},
        }
        if self.terminated_by:
            metadata["notes"].append(self.terminated_by["note"])
        return Result(data=data, metrics=metrics, metadata=metadata, error=message)

    def _typed_rows(self, data: np.ndarray, first_row: int) -> None:
        """Fill the Integer, Boolean and String columns of record buffer rows ``0 .. len(data)-1``
        (absolute ``first_row ..``); a connected input: what its connection delivers, i.e. the
        source's value through the mapping."""
        rows = len(data)
        ints = self.record_i[:rows]
        strings = [self.record_s.get(first_row + r) for r in range(rows)] if self._string_slots else []
        for name, kind, slot, link in self.typed_columns:
            src, mapping = link if link is not None else (slot, {})
            if kind == "string":
                values = [row[src].decode("utf-8", "replace") if row is not None else ""
                          for row in strings]
                data[name] = np.array(values, dtype=object) if rows else values
                continue
            col = ints[:, src]
            if mapping:
                col = np.array([mapping.get(int(x), int(x)) for x in col], dtype=np.int64)
            data[name] = col.astype(bool) if kind == "boolean" else col


#: numpy type of a record column of each value kind.
COLUMN_DTYPE = {"real": "f8", "integer": "i4", "boolean": "?", "string": "O"}


def timing_metrics(simulated: float, wall: float, loop: float) -> dict[str, float | None]:
    """``wall_time_s``, ``real_time_factor`` (simulated / wall) and ``loop_real_time_factor``
    (simulated / stepping-loop seconds) of a run that simulated ``simulated`` seconds."""
    return {"wall_time_s": wall, "real_time_factor": simulated / wall if wall > 0 else None,
            "loop_real_time_factor": simulated / loop if loop > 0 else None}


def _next_chunk(chunk: int, ticks: int, seconds: float) -> int:
    """Ticks for the next chunk so that it lasts about CHUNK_SECONDS (between 1 and CHUNK)."""
    if ticks < chunk or seconds <= 0:
        return chunk
    return int(max(1, min(CHUNK, ticks * CHUNK_SECONDS / seconds)))


class _TickFailure(SimulationError):
    """Internal: a failure inside the stepping loop, with the number of complete record rows."""

    def __init__(self, message: str, rows: int, cause: BaseException | None = None) -> None:
        super().__init__(message)
        self.rows = rows
        self.cause = cause


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
