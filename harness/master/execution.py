"""The execution: owns the slaves, the algorithm, the observers and the manipulators of one
run, and runs the FMI 2.0 lifecycle::

    instantiate -> setupExperiment -> parameter bindings, ``set`` values (start values)
    -> enterInitializationMode -> calculated parameters into their connected parameters
    -> propagate outputs to inputs until a fixed point
    -> exitInitializationMode -> steps (manipulators, algorithm, observers)
    -> terminate -> freeInstance (every instance, also after a failure)

Parameters are set before entering initialization mode, where SSP 1.0 puts parameter
bindings and where libcosim sets start values, so FMUs that derive quantities on entering
initialization see them. Runtime values live in the run's
:class:`~ipcosim.harness.master.layout.Layout` (the value vectors), never on the parsed
scenario; its :class:`~ipcosim.harness.master.recorder.Recorder` keeps the rows and assembles
the result; the stepping loop is planned by :mod:`ipcosim.harness.master.plan` and rendered
in Python (:mod:`~ipcosim.harness.master.pyloop`) or C (:mod:`~ipcosim.harness.master.cloop`) and run
in chunks by the execution's stepping phase (:mod:`~ipcosim.harness.master.stepping`, its base class).
"""
from __future__ import annotations

import ctypes
import math
import time as _time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

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
from ipcosim.harness.master.layout import Layout, named_variables
from ipcosim.harness.master.manipulators import Manipulator, SetValues
from ipcosim.harness.master.me_slave import slave_of
from ipcosim.harness.master.observers import Observer
from ipcosim.harness.master.plan import Block
from ipcosim.harness.master.recorder import Recorder, TaskMetrics, TickFailure, timing_metrics
from ipcosim.harness.master.results import Result, RowWriter, RunOutput, open_output, select_columns
from ipcosim.harness.master.slave import Slave
from ipcosim.harness.master.stepping import CHUNK, CHUNK_SECONDS, Stepping
from ipcosim.harness.master.system import Instance, System, value_type_of

SlaveFactory = Callable[[Instance], Slave]

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


class Execution(Stepping):
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
    set : mapping of (component, variable) to value
        Start values applied after the bindings (already checked), as ``ipcosim.run(set=...)``.
    observers, manipulators : sequences
        See :mod:`ipcosim.harness.master.observers`, :mod:`ipcosim.harness.master.manipulators`.
    slave_factory : callable, optional
        ``factory(instance) -> Slave``; default :func:`~ipcosim.harness.master.me_slave.slave_of` on ``unzip_dirs``.
    unzip_dirs : mapping of component name to Path
        Extracted FMUs (for the default factory).
    record_every : int
        Record every n-th communication point.
    max_init_iterations : int
        Bound on the initialization fixed-point iterations.
    writer : RowWriter, optional
        Where the rows go while the run proceeds (default: ``output``'s results.csv, else a spool
        file only); see :meth:`row_fields` for its fields.
    task_metrics : callable, optional
        The task's metrics of the recorded rows (see :data:`~ipcosim.harness.master.recorder.TaskMetrics`), added to the
        result's metrics; None: only the run's own (timing, observers).
    loop : str
        The stepping loop: ``auto`` (default: the C loop of :mod:`ipcosim.harness.master.cloop`
        when every component's stepping functions are C functions, the system has Real
        connectors only and a C compiler is found; else the Python loop), ``c`` (the C loop, or
        :class:`~ipcosim.harness.master.cloop.LoopUnavailable` saying why not) or ``python``.
        The metadata's ``loop`` says which ran and why.
    output : RunOutput, optional
        What the result carries beyond the master's account (metadata, plotter, the whole run's
        timing) and where its files go: results.csv is opened here (its columns checked) and
        streamed while the run proceeds; metrics.json (and plot.png) are written once when it
        ends, also after a failure or an interrupt.
    """

    def __init__(self, system: System, step: float, stop_time: float, start_time: float | None = None,
                 algorithm: str = GAUSS_SEIDEL, set: Mapping[tuple[str, str], Any] | None = None,
                 observers: Sequence[Observer] = (), manipulators: Sequence[Manipulator] = (),
                 slave_factory: SlaveFactory | None = None, unzip_dirs: Mapping[str, Path] | None = None,
                 record_every: int = 1, max_init_iterations: int = 20, writer: RowWriter | None = None,
                 task_metrics: TaskMetrics | None = None, loop: str = "auto",
                 output: RunOutput | None = None) -> None:
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
        #: The start values of the run by (component, variable), applied after the bindings.
        self.set = dict(set or {})
        self.observers = list(observers)
        self.manipulators = [SetValues(self.set)] + list(manipulators)
        self.unzip_dirs = dict(unzip_dirs or {})
        self.slave_factory = slave_factory or self._fmu_slave
        self.instances = list(system.instances)
        self.index = {inst.name: i for i, inst in enumerate(self.instances)}
        self.multiples = step_multiples(system, self._planned_value, self.timebase.step)
        self.multiples.update(_clock_multiples(system, self.timebase))
        check_last_steps(self.timebase, self.multiples, self.instances)
        if algorithm == GAUSS_SEIDEL:
            self.order = [self.index[n] for n in gauss_seidel_order(system)]
        else:
            self.order = list(range(len(self.instances)))
        self.init_order = self.order
        self.output = output or RunOutput()
        self.layout = Layout(system, self._planned_value, named_variables(system, self.output.variables))
        # the buffer holds at most a chunk of rows
        self.recorder = Recorder(self.layout, self.timebase, record_every, self.order,
                                 capacity=CHUNK // record_every + 2, flush_seconds=CHUNK_SECONDS)
        self.slaves: list[Slave] = []
        self.blocks: list[Block] = []
        if writer is None and self.output.folder is not None:  # unknown columns fail before the folder is touched
            columns = select_columns(self.row_names(), self.output.variables)
            writer = RowWriter(self.row_fields(), open_output(self.output.folder) / "results.csv", columns)
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

    def _planned_value(self, comp: str, var: str) -> Any:
        if (comp, var) in self.set:
            return self.set[(comp, var)]
        return self.system.instance(comp).start_value(var)

    def _fmu_slave(self, instance: Instance) -> Slave:
        return slave_of(instance, self.unzip_dirs[instance.name])

    # ------------------------------------------------------------------ manipulation API
    def set_start(self, component: str, variable: str, value: Any) -> None:
        """Set a start value (instantiated state; used by manipulators' ``initialize``)."""
        slave = self.slaves[self.index[component]]
        var = self.instances[self.index[component]].model.variables[variable]
        slave.set_values([var], [value])
        if var.causality == "input":
            self.layout.put(component, variable, value)

    def set_real(self, component: str, variable: str, value: float) -> None:
        """Set a Real variable now (manipulators' ``step``). For an input connector the value
        is also what the next batched set sends; a connected input is overwritten by its
        connection at the component's next step."""
        var = self.instances[self.index[component]].model.variables[variable]
        if var.causality == "input" and value_type_of(var.type) == "real":
            self.layout.put(component, variable, float(value))
        self.slaves[self.index[component]].set_values([var], [float(value)])

    def get(self, component: str, variable: str) -> Any:
        """Current value of a connector (from the value store): float, int, bool or str."""
        return self.layout.get(component, variable)

    # ------------------------------------------------------------------ run
    def row_names(self) -> list[str]:
        """Field names of the recorded rows: ``time``, then ``component.variable`` (every
        connector of every type, in SSD order, then the other variables ``output`` names)."""
        return list(self.layout.column_types)

    def row_fields(self) -> list[tuple[str, str]]:
        """Name and numpy type of every recorded field (see :meth:`Layout.row_fields`)."""
        return self.layout.row_fields()

    def run(self) -> Result:
        """Run the lifecycle; always returns a Result (``result.error`` set on failure).

        Rows go to the writer chunk by chunk as the run proceeds (memory stays bounded).
        Every instance is terminated (when FMI allows it) and freed, also after a failure, a
        KeyboardInterrupt or a signal deferred by :mod:`ipcosim.harness.master.signals`
        (re-raised after cleanup with ``.result`` set). A signal is only recorded meanwhile
        (``signals.holding``), never raised inside an FMU call.
        """
        with signals.holding():
            return self._run()

    def _run(self) -> Result:
        self.recorder.open(self.writer)
        error: BaseException | None = None
        interrupted: BaseException | None = None
        wall0 = _time.perf_counter()
        wall_loop = 0.0
        try:
            wall_loop = self._start_and_step()
        except KeyboardInterrupt as exc:
            interrupted = error = exc
            self.recorder.flush_pending(self.tick)
        except Exception as exc:  # noqa: BLE001 -- reported in the Result, cleanup below
            error = exc.cause if isinstance(exc, TickFailure) and exc.cause is not None else exc
            self.recorder.flush_pending(self.tick)
        finally:
            error = self._finish(error)
        result = self.recorder.result(self, error, _time.perf_counter() - wall0, wall_loop, self.task_metrics)
        if interrupted is not None:
            what = getattr(interrupted, "message", "interrupted")
            result.error = f"{what} at t = {self.time_of(self.tick):.6g} s"
            result.metadata["error"] = result.error
            result.metadata["status"] = "interrupted"
        self._conclude(result)
        if interrupted is not None:
            interrupted.result = result  # type: ignore[attr-defined]  -- for callers that save it
            raise interrupted
        return result

    def _conclude(self, result: Result) -> None:
        """Complete the result (the caller's metadata and plotter, the whole run's timing) and write
        its files: plot.png, then metrics.json once with the final figures (also when the plot fails)."""
        output = self.output
        result.plotter = output.plotter
        result.metadata.update(output.metadata)
        result.metrics.update(output.metrics)
        if output.folder is None:
            self._whole_run_timing(result)
            return
        folder = Path(output.folder)
        files = {"results": folder / "results.csv", "metrics": folder / "metrics.json"}
        try:
            if output.plot:
                try:
                    files["plot"] = result.plot(folder / "plot.png")
                except ImportError as exc:  # the plotting extra is missing: the numbers are written, say so
                    result.metadata["plot_skipped"] = str(exc)
        finally:
            result.metadata["files"] = {k: str(v) for k, v in files.items()}
            self._whole_run_timing(result)
            result.write_metrics(files["metrics"])

    def _whole_run_timing(self, result: Result) -> None:
        """``wall_time_s`` and ``real_time_factor`` of the whole run (loading and writing included)
        when the caller said when it began (``output.started``)."""
        if self.output.started is None:
            return
        meta = result.metadata
        wall = _time.perf_counter() - self.output.started
        result.metrics.update(timing_metrics(meta.get("simulated_s", 0.0), wall, meta.get("loop_wall_time_s", 0.0)))
        meta["wall_time_s"] = wall

    def _start_and_step(self) -> float:
        """Instantiate, initialize, record row 0, start the observers and step every tick;
        the stepping loop's wall-clock seconds (without the writer's)."""
        signals.check()
        self._instantiate()
        self._initialize()
        self.recorder.start()
        for obs in self.observers:
            obs.start(self)
        loop_t0, written0 = _time.perf_counter(), self.recorder.write_seconds
        self._step_all()
        return _time.perf_counter() - loop_t0 - (self.recorder.write_seconds - written0)

    def _finish(self, error: BaseException | None) -> BaseException | None:
        """Free every instance and tell the observers the run ended; the run's error (the
        first one: the run's own, else the cleanup's, else an observer's)."""
        cleanup_error = self._cleanup()
        if error is None and cleanup_error is not None:
            error = cleanup_error
        for obs in self.observers:
            try:
                obs.finish(self, error)
            except Exception as exc:  # noqa: BLE001
                error = error or exc
        return error

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
        self._carry_parameters()
        self.blocks = self.layout.blocks(self.slaves, self.multiples, self.algorithm)
        for b in self.blocks:  # every output as the FMUs compute it from their start values
            self._get_outputs(b, None)
        changed: list[str] = []
        for it in range(1, self.max_init_iterations + 1):
            signals.check()
            changed = self._init_pass()
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
        self.cloop: CLoop | None = None        # the C stepping loop, when the run uses it
        self._run_loop, self._loop_source = self._compile_loop()

    def _carry_parameters(self) -> None:
        """Calculated parameters into the parameters and inputs they are connected to (initialization
        mode: the calculated values exist, the targets may still be set), pass after pass until no
        value changes (a chain of them settles in as many passes as it is long)."""
        links = self.system.parameter_links
        last: dict[int, Any] = {}
        for _ in range(len(links) + 1):
            changed = False
            for k, link in enumerate(links):
                value = self.slaves[self.index[link.src]].get_values([link.src_var])[0]
                if link.value_type == "real":
                    value = link.factor * float(value) + link.offset
                elif link.mapping:
                    value = dict(link.mapping).get(int(value), int(value))
                if last.get(k) != value:
                    changed, last[k] = True, value
                    self.slaves[self.index[link.dst]].set_values([link.dst_var], [value])
                    if link.dst_var.causality == "input":
                        self.layout.put(link.dst, link.dst_var.name, value)
            if not changed:
                return

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
                                  self.recorder.row_bytes, ctypes.addressof(self.layout.values_c))
                    self.loop_used, self.cloop = "c", cloop
                    return cloop.run, cloop.source
                except LoopUnavailable as exc:
                    if self.loop == "c":
                        raise LoopUnavailable(f"--loop c: the C stepping loop cannot run: {exc}") from None
                    why = str(exc)
            self.loop_used = f"python ({why})"
        else:
            self.loop_used = "python (forced)"
        from ipcosim.harness.master.pyloop import compile_loop

        return compile_loop(self.blocks, self.order, self.algorithm, self.timebase, self.record_every,
                            self.recorder.typed_record())

    def _init_pass(self) -> list[str]:
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
                    raise self.slaves[b.index].fail(f"fmi2Set{ch.value_type.capitalize()}", status, self.start_time)

    def _transfer(self, b: Block, changed: list[str]) -> None:
        """Copy connected outputs into ``b``'s inputs; append the names of inputs that changed."""
        inputs = self.layout.real_inputs[b.index]
        for k, src, j, factor, offset in b.transfers:
            new = factor * self.blocks[src].out_values[j] + offset
            old = b.in_values[k]
            if not (new == old or (math.isnan(new) and math.isnan(old))):
                b.in_values[k] = new
                changed.append(f"{b.name}.{inputs[k].name}")
        for ch in b.channels:
            ins = self.layout.typed[b.index][ch.value_type][1]
            for k, src, j, mapping, carrier in ch.transfers:
                src_ch = next(c for c in self.blocks[src].channels if c.value_type == ch.value_type)
                new = src_ch.out_values[j]
                if carrier is not None:
                    new = carrier(new)
                elif mapping:
                    new = mapping.get(new, new)
                if ch.in_values[k] != new:
                    ch.in_values[k] = new
                    changed.append(f"{b.name}.{ins[k].name}")

    def _get_outputs(self, b: Block, t: float | None) -> None:
        """Read ``b``'s outputs into the value vectors; ``t`` None: in initialization mode, the
        output connectors alone (not the recorded variables that are not connectors)."""
        n = b.n_out if t is not None else b.n_out - b.n_named
        if n:
            status = b.get_real(b.handle, b.out_vrs, n, b.out_values)
            if status > 1:
                raise self.slaves[b.index].fail("fmi2GetReal", status, t if t is not None else self.start_time)
        for ch in b.channels:
            get = ch.get if t is not None else ch.init_get
            if ch.n_out and get is not None:
                status = get(ch.out_values)
                if status > 1:
                    raise self.slaves[b.index].fail(f"fmi2Get{ch.value_type.capitalize()}", status,
                                                    t if t is not None else self.start_time)

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


def _clock_multiples(system: System, timebase: TimeBase) -> dict[str, int]:
    """:func:`~ipcosim.harness.master.clocks.clock_multiples` of a system with FMI 3.0 components, the
    only ones with clocks: the clocks' code, and the slave of FMUs with clocks that it registers
    (:mod:`~ipcosim.harness.master.clocked`), are loaded for such a system alone."""
    if not any(str(inst.model.fmi_version).startswith("3") for inst in system.instances):
        return {}
    from ipcosim.harness.master import clocked  # noqa: F401 -- registers the slave of FMUs with clocks
    from ipcosim.harness.master.clocks import clock_multiples

    return clock_multiples(system, timebase)
