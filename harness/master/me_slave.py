"""Model-exchange slaves: an FMU's model-exchange interface integrated by the master between
communication points, with the interface of the co-simulation slaves (:mod:`~ipcosim.harness.master.slave`).

The solver is CVODE (SUNDIALS, variable-order BDF with a dense Newton solver) as FMPy bundles it
(``fmpy.sundials.CVodeSolver``) and drives it in ``fmpy.simulate_fmu``: the event indicators are its
root functions (state events located to the solver's tolerance), its absolute tolerance is the
relative tolerance times each state's nominal value, its largest step a fiftieth of the run.
A communication step from ``t`` to ``t + h`` integrates up to the next time event or ``t + h``,
whichever comes first; after each integrator step ``completedIntegratorStep`` may ask for a step
event. At every event (time, state, step) the FMU enters event mode, iterates
``fmi2NewDiscreteStates`` / ``fmi3UpdateDiscreteStates`` until no discrete state needs an update,
returns to continuous-time mode, and the solver restarts from the new states.

Inputs are held over the communication step (zero-order hold, as a co-simulation FMU holds
them). An input set with a new value at a communication point is a discontinuity: the FMU enters
event mode before the value is set (FMI 2.0 and 3.0 allow setting every input there) and the next
step begins with the event iteration and a solver restart. An FMU that asks to end the simulation
in an event iteration ends the run as a co-simulation FMU's ``terminateSimulation`` does.

The relative tolerance is the component's :attr:`~ipcosim.harness.master.system.Instance.tolerance`
(the SSD's, else the FMU's DefaultExperiment tolerance), else :data:`DEFAULT_TOLERANCE`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.harness.master.fmi2_slave import FMU2Slave
from ipcosim.harness.master.fmi3_slave import FMU3Slave
from ipcosim.harness.master.fmu_slave import FMUSlave, fmi2_tuple_library, load_library
from ipcosim.harness.master.slave import ERROR, OK, TERMINATE, BoundGetSet, RawDoStep, RawGetSet, SlaveError
from ipcosim.harness.master.slaves import fmu_slave
from ipcosim.harness.master.system import Instance, Variable

#: Relative tolerance of the solver when neither the SSD nor the FMU gives one.
DEFAULT_TOLERANCE = 1e-6
#: Most passes of one event iteration before the FMU is declared not to settle.
MAX_EVENT_ITERATIONS = 1000


class _HeldInputs:
    """The solver's input object: the inputs stay as the master set them over the step."""

    def apply(self, *args: Any, **kwargs: Any) -> None:
        return None


class ModelExchange:
    """What the FMI 2.0 and 3.0 model-exchange slaves share: the event iteration, the solver and
    the communication step (see the module documentation). Mixed in before the co-simulation
    slave of the same FMI version, whose getters, setters, log and lifecycle it keeps."""

    _fmu: Any
    instance: Instance
    unzip_dir: Path
    state: str
    FMI: str

    def _me_setup(self, start_time: float, stop_time: float | None) -> None:
        self._start, self._stop = float(start_time), stop_time
        self._solver: Any = None
        self._event_pending = False
        self._next_event = math.inf
        self._ended_at: float | None = None

    @property
    def tolerance(self) -> float:
        return self.instance.tolerance or DEFAULT_TOLERANCE

    # ------------------------------------------------------------------ FMI version specifics
    def _update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        """``(needs another pass, terminate, next event time defined, next event time)``."""
        raise NotImplementedError

    def _derivatives(self) -> Callable[..., Any]:
        raise NotImplementedError

    # ------------------------------------------------------------------ lifecycle
    def exit_initialization_mode(self) -> None:
        self._call(f"{self.FMI}ExitInitializationMode")  # type: ignore[attr-defined]
        if self._event_iteration():
            raise SlaveError(f"component {self.label()}: the FMU asked to end the simulation in its "  # type: ignore[attr-defined]
                             f"initial event iteration", self.instance.name, f"{self.FMI}ExitInitializationMode")
        self._call(f"{self.FMI}EnterContinuousTimeMode")  # type: ignore[attr-defined]
        self._solver = self._make_solver()
        self.state = "stepping"

    def _make_solver(self) -> Any:
        from fmpy import read_model_description
        from fmpy.sundials import CVodeSolver

        md = read_model_description(str(self.unzip_dir / "modelDescription.xml"), validate=False)
        self._completed_step_needed = bool(md.modelExchange.needsCompletedIntegratorStep)
        fmu = self._fmu
        span = (self._stop if self._stop is not None else self._start + 1.0) - self._start
        solver = CVodeSolver(nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators,
                             get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
                             get_dx=self._derivatives(), get_z=fmu.getEventIndicators,
                             get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime,
                             input=_HeldInputs(), startTime=self._start, maxStep=span / 50.0,
                             relativeTolerance=self.tolerance)
        _errors_to_the_solver_only(solver)
        return solver

    def free(self) -> None:
        self._solver = None  # CVODE's memory before the instance
        super().free()  # type: ignore[misc]

    # ------------------------------------------------------------------ events
    def _event_iteration(self) -> bool:
        """Update the discrete states until they settle (event mode); True when the FMU asks to
        end the simulation. Notes the next time event."""
        for _ in range(MAX_EVENT_ITERATIONS):
            again, terminate, defined, t_next = self._update_discrete_states()
            if terminate:
                return True
            if not again:
                self._next_event = t_next if defined else math.inf
                return False
        raise SlaveError(f"component {self.label()}: the event iteration did not settle in "  # type: ignore[attr-defined]
                         f"{MAX_EVENT_ITERATIONS} passes", self.instance.name, "event iteration")

    def _event(self, time: float) -> bool:
        """Handle an event at ``time`` (event mode entered already): iterate, back to
        continuous-time mode, restart the solver. True when the FMU ended the simulation."""
        if self._event_iteration():
            self._ended_at = time
            return True
        self._fmu.enterContinuousTimeMode()
        self._solver.reset(time)
        return False

    def _input_event(self) -> None:
        """A new input value is about to be set: enter event mode first (once per communication point)."""
        if self.state == "stepping" and not self._event_pending:
            self._fmu.enterEventMode()
            self._event_pending = True

    # ------------------------------------------------------------------ stepping
    def _me_step(self, c: Any, t: float, h: float, flag: int) -> int:
        try:
            return self._advance(t, t + h)
        except Exception as exc:  # noqa: BLE001 -- an FMI call or CVODE failed: a status for the loop
            info = getattr(self._solver, "error_info", None)
            text = f"CVODE: {info[3]}" if isinstance(exc, RuntimeError) and info else f"{type(exc).__name__}: {exc}"
            self._log(None, None, ERROR, None, text.encode())  # type: ignore[attr-defined]
            return ERROR

    def fail(self, function: str, status: int, time: float | None = None) -> SlaveError:
        if function == "fmi2DoStep":  # the loop's name for the step: here the master's integration
            function = "the model-exchange step (CVODE and the FMU's events)"
        return super().fail(function, status, time)  # type: ignore[misc]

    def _advance(self, t: float, t_end: float) -> int:
        """Integrate from ``t`` to ``t_end`` with the events in between (see the module documentation)."""
        fmu, solver = self._fmu, self._solver
        if self._event_pending:
            self._event_pending = False
            if self._event(t):
                return TERMINATE
        time, eps = t, 1e-13 * max(1.0, abs(t_end))
        while t_end - time > eps:
            target = self._next_event if self._next_event < t_end - eps else t_end
            state_event, _, time = solver.step(time, target)
            fmu.setTime(time)
            step_event = terminate = False
            if self._completed_step_needed:
                step_event, terminate = fmu.completedIntegratorStep()
            if terminate:
                self._ended_at = time
                return TERMINATE
            if state_event or step_event or time >= self._next_event - eps:
                fmu.enterEventMode()
                if self._event(time):
                    return TERMINATE
        fmu.setTime(t_end)
        return OK

    def _held(self, put: RawGetSet) -> RawGetSet:
        """``put`` (a raw Real setter) entering event mode first when a value changes."""
        last: list[Any] = [None]

        def set_real(c: Any, vrs: Any, n: int, values: Any) -> int:
            now = tuple(values[:n])
            if now != last[0]:
                self._input_event()
                last[0] = now
            return put(c, vrs, n, values)

        return set_real

    def channel(self, value_type: str, variables: Sequence[Variable]) -> tuple[BoundGetSet, BoundGetSet]:
        get, put = super().channel(value_type, variables)  # type: ignore[misc]
        n, last = len(variables), [None]

        def set_held(buf: Any) -> int:
            now = tuple(buf[:n])
            if now != last[0]:
                self._input_event()
                last[0] = now
            return put(buf)

        return get, set_held

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        self._input_event()
        super().set_values(variables, values)  # type: ignore[misc]

    def terminated(self) -> tuple[bool, str]:
        ended = self._ended_at is not None
        return ended, f"the FMU {'asked' if ended else 'did not ask'} to end the simulation (terminateSimulation)"

    def last_successful_time(self) -> float | None:
        return self._ended_at


class ME2Slave(ModelExchange, FMU2Slave):
    """An FMI 2.0 model-exchange FMU integrated by the master (see the module documentation)."""

    def instantiate(self) -> None:
        if self._fmu is None:
            self._fmu = load_me_library(self.instance, self.unzip_dir)
        super().instantiate()

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self._me_setup(start_time, stop_time)
        self._call("fmi2SetupExperiment", 1, self.tolerance, float(start_time), 1 if stop_time is not None else 0,
                   float(stop_time or 0.0))

    def _update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        again, terminate, _, _, defined, t_next = self._fmu.newDiscreteStates()
        return bool(again), bool(terminate), bool(defined), float(t_next)

    def _derivatives(self) -> Callable[..., Any]:
        return self._fmu.getDerivatives

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        return self._fmu.component, self._me_step, self._get_real, self._held(self._set_real)


class ME3Slave(ModelExchange, FMU3Slave):
    """An FMI 3.0 model-exchange FMU integrated by the master (see the module documentation)."""

    def instantiate(self) -> None:
        if self._fmu is None:
            self._fmu = load_me_library(self.instance, self.unzip_dir)
        try:
            super().instantiate()  # fmpy's FMU3Model.instantiate: fmi3InstantiateModelExchange
        except SlaveError as exc:
            name = "fmi3InstantiateModelExchange"
            raise SlaveError(str(exc).replace("fmi3InstantiateCoSimulation", name), self.name, name) from None

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self._me_setup(start_time, stop_time)
        super().setup_experiment(start_time, stop_time)

    def enter_initialization_mode(self) -> None:
        start, stop = self._start, self._stop
        self._call("fmi3EnterInitializationMode", True, self.tolerance, start, stop is not None, float(stop or 0.0))
        self.state = "initialization"

    def _update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        again, terminate, _, _, defined, t_next = self._fmu.updateDiscreteStates()
        return bool(again), bool(terminate), bool(defined), float(t_next)

    def _derivatives(self) -> Callable[..., Any]:
        return self._fmu.getContinuousStateDerivatives

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        types = {v.vr: v.type for v in self.instance.model.variables.values()}
        get_real, set_real = self._real_io(types)
        return self._fmu.component, self._me_step, get_real, self._held(set_real)


def _errors_to_the_solver_only(solver: Any) -> None:
    """CVODE's errors to the solver's own handler only (it keeps them for the message), not also
    printed by SUNDIALS' default handler on stderr."""
    import ctypes

    from fmpy.sundials.sundials_context import SUNContext, SUNContext_PushErrHandler, sundials_core

    clear = sundials_core.SUNContext_ClearErrHandlers
    clear.argtypes, clear.restype = [SUNContext], ctypes.c_int
    clear(solver.sunctx)
    SUNContext_PushErrHandler(solver.sunctx, solver.ehfun_, None)


def slave_of(instance: Instance, unzip_dir: Path, logging_on: bool = True, library: Any = None) -> FMUSlave:
    """The slave of one extracted FMU for the interface the component runs: for model exchange
    :class:`ME3Slave` (FMI 3.0) or :class:`ME2Slave`, else :func:`~ipcosim.harness.master.slaves.fmu_slave`'s."""
    if instance.interface != "ModelExchange":
        return fmu_slave(instance, unzip_dir, logging_on=logging_on, library=library)
    cls = ME3Slave if instance.model.fmi_version.startswith("3") else ME2Slave
    return cls(instance, unzip_dir, logging_on=logging_on, library=library)


def library_of(instance: Instance, unzip_dir: Path) -> Any:
    """The loaded library :func:`slave_of` makes a slave from (see
    :func:`~ipcosim.harness.master.fmu_slave.load_library`)."""
    return load_me_library(instance, unzip_dir) if instance.interface == "ModelExchange" else load_library(
        instance, unzip_dir)


def load_me_library(instance: Instance, unzip_dir: Path) -> Any:
    """An FMPy ``FMU2Model`` (``FMU3Model`` for FMI 3.0) with the FMU's model-exchange library loaded.

    Raises
    ------
    SlaveError
        If the shared library cannot be loaded.
    """
    from fmpy.fmi2 import FMU2Model
    from fmpy.fmi3 import FMU3Model

    model = instance.model
    identifier = model.model_exchange_identifier or model.model_identifier
    fmi3 = model.fmi_version.startswith("3")
    library = None if fmi3 else fmi2_tuple_library(unzip_dir, identifier)
    try:
        return (FMU3Model if fmi3 else FMU2Model)(
            guid=model.guid, unzipDirectory=str(unzip_dir), modelIdentifier=identifier, instanceName=instance.name,
            **({"libraryPath": library} if library else {}))
    except Exception as exc:  # noqa: BLE001 -- fmpy raises bare exceptions
        raise SlaveError(f"component {instance.name} ({model.name}): cannot load the FMU's model-exchange "
                         f"library: {exc}", instance.name, "load") from None
