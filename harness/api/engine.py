"""The Python API of the master: :func:`prepare` for many runs of one scenario (parameter sweeps)
that share the loaded, checked and extracted FMUs, and :func:`run_with`, the one path behind
``ipcosim run`` and :func:`ipcosim.run` (a :class:`RunOptions`, plus the master's extension points
``observers`` and ``manipulators``). Where the FMUs are extracted is :mod:`~ipcosim.harness.api.extraction`'s;
what the IP02 task adds to a run, :mod:`~ipcosim.harness.api.task`'s.

Example::

    import ipcosim

    result = ipcosim.run("single-mass-lqr", stop_time=5.0, set={"plant.Mp": 0.2})
    result.metrics["settling_time_s"], result["plant.cart_position"]

    with ipcosim.prepare("double-mass-hsmc") as prepared:      # load and extract once
        for mp in (0.10, 0.12, 0.14):
            r = prepared.run(set={"plant.Mp": mp}, raise_on_error=False)
"""
from __future__ import annotations

import dataclasses
import functools
import json
import os
import sys
import tempfile
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from ipcosim.errors import IpcosimError, UsageError, closest
from ipcosim.fmus.metrics import (
    CYCLE_SOURCES,
    amplitude_bound,
    predicted_amplitude_bound,
    streamed_task_metrics,
    tasks_of,
)
from ipcosim.harness.api.extraction import (  # noqa: F401 -- NoBinaryError, binary_folders: importable here too
    EXTRACT_PREFIX,
    NoBinaryError,
    archive_members,
    binary_folders,
    check_binary,
    remove_stale_extractions,
    remove_temp,
    runtime_members,
)
from ipcosim.harness.api.grammar import strip_nominal
from ipcosim.harness.api.options import RunOptions, run_options
from ipcosim.harness.api.task import has_linear_model, start_value, with_bound
from ipcosim.harness.master import signals
from ipcosim.harness.master.algorithm import ALGORITHMS, GAUSS_SEIDEL, StepSizeError
from ipcosim.harness.master.execution import Execution, SlaveFactory, check_times
from ipcosim.harness.master.manipulators import Manipulator
from ipcosim.harness.master.me_slave import library_of, slave_of
from ipcosim.harness.master.observers import Observer, Progress
from ipcosim.harness.master.realtime import RealtimePacer
from ipcosim.harness.master.recorder import TaskMetrics
from ipcosim.harness.master.results import Result, RunOutput, SimulationError, json_safe
from ipcosim.harness.master.slaves import LoadedSlaves
from ipcosim.harness.master.system import System
from ipcosim.harness.scenario.archive import safe_extract
from ipcosim.harness.scenario.binding import bind, warn_all
from ipcosim.harness.scenario.default_experiment import default_step, default_stop_time
from ipcosim.harness.scenario.ssp import load_scenario
from ipcosim.harness.scenario.structure import Scenario, select_parameter_set
from ipcosim.harness.scenario.values import with_set

if TYPE_CHECKING:  # the swaps are loaded by a run that swaps a component (:func:`_swap_label`)
    from ipcosim.harness.scenario.swaps import SwapTarget


class NothingToSimulateError(IpcosimError, ValueError):
    """A system without a single FMU component (only nested systems and connectors): a run would
    record time alone."""


def plot_run(result: Result, path: Path | None = None) -> Any:
    """The figure of a pendulum run (:attr:`Result.plotter` of the results made here): the
    matplotlib Figure, or with ``path`` the PNG written there (see :mod:`ipcosim.harness.api.plot`)."""
    from ipcosim.harness.api.plot import figure, plot_result

    return figure(result) if path is None else plot_result(result, path)


class Prepared:
    """A scenario loaded, checked against its FMUs and extracted, ready to run many times.

    Parameters
    ----------
    scenario_or_path : str or path or Scenario
        Scenario name, folder, SSD file or ``.ssp`` archive (or a loaded Scenario).
    parameter_set : str, optional
        Bind this parameter set (``thesis``, ``tuned``...) instead of the SSD's default.
    swap : mapping of component to FMU path, alias or SwapTarget, optional
        Components to replace (``{"plant": "hil"}``), as ``ipcosim.run(swap=...)``.
    fmu_dirs : sequence of path, optional
        Extra folders to look for FMUs in.
    algorithm : str
        ``gauss-seidel`` (default) or ``jacobi``.
    workdir : path, optional
        Where to extract FMUs (default: a temporary folder removed by :meth:`close`).
    slave_factory : callable, optional
        ``factory(instance) -> Slave`` instead of loading the FMUs (tests).
    system : System, optional
        An already bound system (tests); skips loading and binding.
    warn : bool
        Issue the binding's notes (unconnected inputs...) as Python warnings.
    strict : bool
        Parameters of the scenario that a swapped-in FMU does not have are an error (default:
        ignored, with one warning per component).
    reuse_instances : bool
        Keep each component's FMU instance between runs and reset it (``fmi2Reset``) instead of
        instantiating anew (:attr:`ipcosim.harness.master.fmu_slave.FMUSlave.reusable`): for studies
        of many runs, where each pythonfmu instantiation would keep a few kB alive.
    task_metrics : callable, optional
        The task's metrics of a run's rows (``ipcosim.harness.master.recorder.TaskMetrics``);
        default the IP02 task's, :func:`ipcosim.fmus.metrics.streamed_task_metrics` (a scenario
        without the pendulum's columns gets none).
    """

    def __init__(self, scenario_or_path: str | os.PathLike[str] | Scenario | None = None, *,
                 parameter_set: str | None = None,
                 swap: Mapping[str, str | os.PathLike[str] | SwapTarget] | None = None,
                 fmu_dirs: Sequence[str | os.PathLike[str]] | None = None, algorithm: str = GAUSS_SEIDEL,
                 workdir: str | os.PathLike[str] | None = None, slave_factory: SlaveFactory | None = None,
                 system: System | None = None, warn: bool = True, fmus: str = "python", strict: bool = False,
                 reuse_instances: bool = False,
                 task_metrics: TaskMetrics | None = streamed_task_metrics) -> None:
        from ipcosim.harness.scenario.flavour import check_flavour, to_native

        t0 = time.perf_counter()
        #: Seconds spent loading, binding and extracting, charged to the first run's ``wall_time_s``.
        self.load_seconds = 0.0
        self.fmus = check_flavour(fmus)
        self._python_values: dict[str, dict[str, Any]] = {}
        self._bounds: dict[str, dict[str, Any]] = {}   # the amplitude bound of each run's --set values
        if algorithm not in ALGORITHMS:
            raise UsageError(f"--algorithm {algorithm}: expected one of {', '.join(ALGORITHMS)}")
        self.algorithm = algorithm
        self.slave_factory = slave_factory
        self.task_metrics = task_metrics
        self.parameter_set = parameter_set
        self.swap = {k: _swap_label(v) for k, v in (swap or {}).items()}
        self.reuse_instances = reuse_instances
        self._tmp: Path | None = None
        self._finalizer: Any = None
        self.unzip_dirs: dict[str, Path] = {}
        # loaded once, for every run
        self._slaves = LoadedSlaves(self.unzip_dirs, reuse=reuse_instances, make=slave_of, load=library_of)
        self._libraries, self._kept = self._slaves.libraries, self._slaves.kept
        if system is not None:
            self.system = system
            self.scenario = self._python_scenario = system.scenario
            return
        scenario = self._load(scenario_or_path, parameter_set, fmu_dirs)
        if not scenario.components:
            raise NothingToSimulateError(f"{scenario.origin}: system {scenario.name!r} has no component to "
                                         "simulate (no FMU in it or in its sub-systems)")
        work = self._workdir(workdir)
        try:
            archived = archive_members(scenario, work) if scenario.location.is_file() else {}
            self._python_scenario = scenario  # the laws' own parameters: what the residual cycle is predicted from
            if fmus == "native":
                scenario, self._python_values = to_native(_with_fmus(scenario, archived))
            self.scenario = scenario
            if swap:
                import ipcosim.harness.hil  # noqa: F401 -- registers the ``hil`` swap alias (only a swap needs it)
            self.system = bind(scenario, swap=swap, fmu_files=archived, strict_swaps=strict)
            if warn:
                warn_all(self.system)
            if slave_factory is None:
                self._extract(work)
        except BaseException:
            self.close()  # nothing left in the temporary folder
            raise
        self.load_seconds = time.perf_counter() - t0

    def _load(self, scenario_or_path: str | os.PathLike[str] | Scenario | None, parameter_set: str | None,
              fmu_dirs: Sequence[str | os.PathLike[str]] | None) -> Scenario:
        """The scenario parsed (unless given parsed), with ``parameter_set`` selected (native FMUs:
        looked for in ``build/fmus-native`` too; turned to their flavour once an archive's FMUs are out)."""
        from ipcosim.harness.scenario.flavour import native_fmu_dir

        if isinstance(scenario_or_path, Scenario):
            scenario = scenario_or_path
        else:
            if self.fmus == "native":
                fmu_dirs = [*(fmu_dirs or []), native_fmu_dir()]
            scenario = load_scenario(scenario_or_path, fmu_dirs=fmu_dirs)  # type: ignore[arg-type]
            if build_missing(scenario):
                scenario = load_scenario(scenario_or_path, fmu_dirs=fmu_dirs)  # type: ignore[arg-type]
        if parameter_set:
            scenario = select_parameter_set(scenario, parameter_set)
        return scenario

    def _workdir(self, workdir: str | os.PathLike[str] | None) -> Path:
        """The folder FMUs are extracted to: ``workdir``, or a temporary one removed by :meth:`close`
        (and on a forced exit; a killed process's is removed by the next run, :func:`remove_stale_extractions`)."""
        if workdir is not None:
            work = Path(workdir)
            work.mkdir(parents=True, exist_ok=True)
            return work
        remove_stale_extractions()
        self._tmp = Path(tempfile.mkdtemp(prefix=f"{EXTRACT_PREFIX}{os.getpid()}-"))
        self._finalizer = weakref.finalize(self, remove_temp, str(self._tmp))
        signals.register_temp(self._tmp)
        return self._tmp

    def _extract(self, work: Path) -> None:
        by_file: dict[Path, Path] = {}
        sources = {c.name: c.source for c in self.scenario.components}
        for inst in self.system.instances:
            path = inst.model.path
            assert path is not None
            if path not in by_file:
                fmu = sources.get(inst.name, path.name) if inst.swapped_from is None else str(path)
                check_binary(path, inst.model, f"{self.scenario.origin}: component {inst.name!r} ({fmu})")
                target = work / f"{len(by_file)}-{path.stem}"
                if not (target / "modelDescription.xml").exists():
                    safe_extract(path, target, runtime_members(path, inst.model, target))
                by_file[path] = target
            self.unzip_dirs[inst.name] = by_file[path]

    # ------------------------------------------------------------------ running
    def options(self, options: RunOptions | None = None, **fields: Any) -> RunOptions:
        """The options of one run of this scenario: ``options`` (default: every run option's
        default) with ``fields`` in place, each a :class:`~ipcosim.harness.api.options.RunOptions`
        field that a run takes (``stage="run"``: stop time, step, ``set``, ``out``, ``record``...).

        Raises
        ------
        UsageError
            A field that is not a run option, or one the scenario takes when it is prepared
            (``swap``, ``parameter_set``...) or that only :func:`ipcosim.run` takes (``timeout``, ``live``...).
        """
        stages = {name: how.stage for name, how in run_options()}
        for name in fields:
            if name not in stages:
                raise UsageError(f"{name}: not an option of a run; {closest(name, stages)}")
            if stages[name] != "run":
                where = "prepare()" if stages[name] == "load" else "ipcosim.run()"
                raise UsageError(f"{name}: an option of {where}, not of each run of a prepared scenario")
        if options is None:
            return RunOptions(self.label, **fields)
        if not isinstance(options, RunOptions):
            raise UsageError(f"options {options!r}: expected a RunOptions (give the others by name, "
                             f"e.g. stop_time=...)")
        return dataclasses.replace(options, **fields) if fields else options

    @property
    def label(self) -> str:
        """The scenario's name (what a run's options name as their scenario)."""
        return getattr(self.scenario, "name", None) or "system"

    def execution(self, options: RunOptions | None = None, *, observers: Sequence[Observer] = (),
                  manipulators: Sequence[Manipulator] = (), started: float | None = None,
                  **fields: Any) -> Execution:
        """A ready :class:`Execution` of one run as ``options`` and ``fields`` say (:meth:`options`),
        checked: step, stop time, the ``set`` start values (relative ones, ``"1.1*nominal"``,
        resolved against the bound values), step multiples, the recorded columns; ``out`` opened
        for its files. ``observers`` and ``manipulators`` plug into the master; ``started``: when
        the whole run began (:func:`time.perf_counter`), for its ``wall_time_s``."""
        options = self.options(options, **fields)
        stop_time, step, start_time = options.stop_time, options.step, options.start_time
        stop, why_stop = (stop_time, "") if stop_time is not None else default_stop_time(self.system)
        h, why_step = (step, "") if step is not None else default_step(self.system)
        if stop is None:
            raise StepSizeError(f"{why_stop}; give --stop-time")
        if h is None:
            raise StepSizeError(f"{why_step}; give --step")
        origin = self.scenario.origin
        start = self.scenario.experiment.start_time if start_time is None else start_time
        check_times(start, stop, h, options.record_every, {
            "start": "start_time" if start_time is not None else f"{origin}: DefaultExperiment startTime",
            "stop": "--stop-time" if stop_time is not None else why_stop,
            "step": "--step" if step is not None else (f"{origin}: osp:FixedStepAlgorithm baseStepSize"
                                                        if self.scenario.experiment.step_size is not None
                                                        else why_step)})
        given = set = resolve_relative(self.system, options.set)
        if self.fmus == "native" and set:
            from ipcosim.harness.scenario.flavour import native_set
            set = native_set(self.system, set, self._python_values)
        _, values = with_set(self.system, set or {})
        observers = list(observers)
        if options.progress:
            observers.append(Progress())
        realtime = options.realtime
        if realtime or (realtime is None and self.system.realtime):
            observers += [RealtimePacer(overrun_budget=options.overrun_budget), _card_observer(overruns=True)]
        elif any(i.swapped_from for i in self.system.instances):     # e.g. a HIL adapter on a lockstep rig
            observers.append(_card_observer())
        metadata = self._run_metadata(values, given or {})
        return Execution(self.system, step=h, stop_time=stop, start_time=start_time,
                         algorithm=self.algorithm, set=values, observers=observers,
                         manipulators=manipulators, slave_factory=self.slave_factory or self._slaves,
                         unzip_dirs=self.unzip_dirs,
                         record_every=options.record_every, max_init_iterations=options.max_init_iterations,
                         task_metrics=with_bound(self._run_task_metrics(values), metadata), loop=options.loop,
                         output=RunOutput(options.out, list(options.record) or None, options.plot,
                                          {**metadata, "set": given}, plot_run, started,
                                          {"voltage_limit_V": metadata["voltage_limit_V"]}))  # `ipcosim view` draws it

    def _run_task_metrics(self, values: Mapping[tuple[str, str], Any]) -> TaskMetrics | None:
        """The task metrics of one run: the IP02 task's with the metrics of the run's further tasks
        (:func:`ipcosim.fmus.metrics.tasks_of` the plant's start values after ``values``)."""
        if self.task_metrics is not streamed_task_metrics:
            return self.task_metrics
        try:
            plant = self.system.instance("plant")
        except KeyError:
            return self.task_metrics

        starts = {name: values.get(("plant", name), plant.start_value(name)) for name in plant.model.variables}
        return functools.partial(streamed_task_metrics, tasks=tasks_of(starts.get))

    def run(self, options: RunOptions | None = None, *, observers: Sequence[Observer] = (),
            manipulators: Sequence[Manipulator] = (), raise_on_error: bool = True, **fields: Any) -> Result:
        """Run once.

        Parameters
        ----------
        options : RunOptions, optional
            The run's options (the scenario, swaps and other options a scenario is prepared with
            are this object's own; default: each run option's default).
        observers, manipulators : sequence, optional
            What plugs into the master (:mod:`ipcosim.harness.master.observers`,
            :mod:`ipcosim.harness.master.manipulators`).
        raise_on_error : bool
            Raise SimulationError on failure (after writing ``out``); else return the partial
            Result with ``error`` set.
        **fields
            Run options in place of those of ``options``, by their field names in
            :class:`~ipcosim.harness.api.options.RunOptions`: ``stop_time`` and ``step`` [s] (default:
            the scenario's DefaultExperiment, 10 s at 1 ms for the project's scenarios); ``set``
            (``{"plant.Mp": 0.2, "controller.sample_period": 0.002}`` or ``"1.1*nominal"``);
            ``out`` (write ``results.csv``, ``metrics.json`` and, with ``plot``, ``plot.png``
            there); ``record`` (the columns of results.csv, names or patterns like ``plant.*``;
            default all connectors; a parameter or local named, ``plant.Mp``, is recorded in the
            Result too); ``realtime`` (None: only when a swapped-in component asks for
            it), ``overrun_budget``, ``progress``, ``loop``, ``start_time``, ``record_every``,
            ``max_init_iterations``.

        Raises
        ------
        UsageError
            A field that is not an option of each run (:meth:`options`), or a bad value.
        SimulationError
            If the run failed and ``raise_on_error`` (``.result`` holds the partial result,
            already written to ``out`` when given).
        """
        started = time.perf_counter() - self.load_seconds  # the loading belongs to the first run
        self.load_seconds = 0.0
        execution = self.execution(options, observers=observers, manipulators=manipulators, started=started,
                                   **fields)
        result = execution.run()  # results.csv streamed, metrics.json written at its end (out given)
        if result.error is not None and raise_on_error:
            raise SimulationError(result.error, result)
        return result

    def _run_metadata(self, values: Mapping[tuple[str, str], Any], given: Mapping[str, Any]) -> dict[str, Any]:
        """What a run's figure and metadata say beyond the master's account: the voltage limit it
        draws (:mod:`ipcosim.harness.api.plot`), the parameter set, the swaps and the success criterion's
        amplitude bound (:meth:`_amplitude_bound`), from the values the run starts with (``values`` over the bound
        ones; ``given``: the ``--set`` values as given)."""
        def start(component: str, variable: str) -> Any:
            return start_value(self.system, values, component, variable)

        b2, K = (start("plant", n) for n in ("b2", "K"))
        linear = not any(float(start("plant", n) or 0.0) > 0.0 for n in CYCLE_SOURCES)
        return {"voltage_limit_V": next((v for v in (start(c, "voltage_limit") for c in ("controller", "plant"))
                                         if v), None),
                "parameter_set": self.parameter_set or ",".join(self.scenario.bound_sets) or None,
                "swaps": dict(self.swap), **self._amplitude_bound(given, float(b2 or 0.0), float(K or 0.0), linear)}

    def _amplitude_bound(self, given: Mapping[str, Any], b2: float, K: float, linear: bool) -> dict[str, Any]:
        """The success criterion's amplitude bound of a run, before it runs: from the residual cycle predicted for
        its plant and law (``ipcosim.harness.analysis.residual_cycle.run_bound``) where the scenario has an IP02
        ``plant`` and a ``controller``; else the friction bound of its ``b2`` and ``K``. A ``linear`` plant (no
        Coulomb friction, no encoder counts) under a law with a linear model has no cycle: its bound is the
        margin alone, without loading the analysis (what the prediction gives it too)."""
        from ipcosim.fmus.kinds import PLANT_MODELS

        try:
            plant = self._python_scenario.component("plant")
            self._python_scenario.component("controller")
        except KeyError:
            plant = None
        if plant is None or Path(str(plant.source)).stem not in PLANT_MODELS or self.swap:
            why = "a swapped component" if self.swap else "no IP02 plant and controller to predict from"
            return {"amplitude_bound_m": amplitude_bound(b2, K), "amplitude_bound_from": f"friction bound: {why}",
                    "predicted_cart_peak_to_peak_m": None}
        if linear and has_linear_model(Path(str(self._python_scenario.component("controller").source)).stem):
            return {"amplitude_bound_m": predicted_amplitude_bound(0.0), "amplitude_bound_from": "prediction",
                    "predicted_cart_peak_to_peak_m": 0.0}
        from ipcosim.harness.analysis.residual_cycle import run_bound

        key = json.dumps([given, b2, K], sort_keys=True, default=repr)
        if key not in self._bounds:
            self._bounds[key] = run_bound(self._python_scenario, given, amplitude_bound(b2, K))
        return dict(self._bounds[key])

    def close(self) -> None:
        """Unload the FMUs' libraries and remove the extracted FMUs (if this object created the folder)."""
        self._slaves.close()
        if self._finalizer is not None:
            self._finalizer()

    def __enter__(self) -> "Prepared":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _swap_label(value: str | os.PathLike[str] | SwapTarget) -> str:
    """How a run's metadata names what a component was swapped for: the path or alias as given, a
    :class:`~ipcosim.harness.scenario.swaps.SwapTarget` by its description (else its FMU), the swaps loaded
    only by a run that swaps."""
    from ipcosim.harness.scenario.swaps import SwapTarget

    return (value.description or str(value.fmu)) if isinstance(value, SwapTarget) else str(value)


def _card_observer(overruns: bool = False) -> Observer:
    """The observer of a run's HIL cards (:class:`~ipcosim.harness.hil.observer.CardObserver`),
    imported only for a run that may drive one: a plain simulation loads no HIL code."""
    from ipcosim.harness.hil.observer import CardObserver

    return CardObserver(overruns=overruns)


def build_missing(scenario: Scenario) -> list[str]:
    """Build the project's FMUs that ``scenario`` names but cannot find (the first run after a
    wheel install) into the build folder (:mod:`ipcosim.harness.support.paths`: the user cache for an
    installed wheel), saying so in one line on stderr; they are found there from then on.

    Returns
    -------
    list of str
        The models built (none: nothing was missing, or only FMUs this project does not make,
        which binding then reports by name).
    """
    if scenario.location.is_file() or all(c.fmu is not None for c in scenario.components):
        return []  # an .ssp archive carries its FMUs; every FMU found
    from ipcosim.fmus.pybuild import build_all, model_scripts
    from ipcosim.harness.scenario import locations

    scripts = model_scripts()
    missing = sorted({Path(c.source).stem for c in scenario.components if c.fmu is None} & set(scripts))
    if missing:
        print(f"ipcosim: building the FMUs {scenario.name} needs ({', '.join(missing)}) into "
              f"{locations.BUILD_FMU_DIR}, once", file=sys.stderr, flush=True)
        build_all(locations.BUILD_FMU_DIR, scripts=[scripts[m] for m in missing])
    return missing


def prepare(scenario_or_path: str | os.PathLike[str] | Scenario, **kwargs: Any) -> Prepared:
    """Load, check and extract a scenario once for many runs (see :class:`Prepared`)."""
    return Prepared(scenario_or_path, **kwargs)


def prepare_with(options: RunOptions, *, warn: bool = True) -> Prepared:
    """A :class:`Prepared` scenario for ``options``: its fields of the ``load`` stage (scenario, parameter
    set, swaps, FMU folders, flavour, algorithm, strictness) are :class:`Prepared`'s keywords."""
    load = {name: getattr(options, name) for name, how in run_options() if how.stage == "load"}
    return Prepared(load.pop("scenario"), warn=warn, **load)


def run_with(options: RunOptions, prepared: Prepared | None = None, *, observers: Sequence[Observer] = (),
             manipulators: Sequence[Manipulator] = (), raise_on_error: bool = True) -> Result:
    """Run once as ``options`` say: the one path behind ``ipcosim run`` and :func:`ipcosim.run`.

    ``observers`` and ``manipulators`` plug into the master (:mod:`ipcosim.harness.master.observers`,
    :mod:`ipcosim.harness.master.manipulators`); with ``raise_on_error=False`` a failed run returns
    its partial Result (``error`` set) instead of raising.

    Writes ``options.out`` and ``options.save_baseline`` when given; relative ``set`` values
    (``"1.1*nominal"``) are resolved against the values the scenario binds. SIGINT and SIGTERM
    (in the main thread) and ``options.timeout`` stop the run between FMU calls
    (:mod:`ipcosim.harness.master.signals`): :class:`~ipcosim.harness.master.signals.Interrupted`
    is raised after every FMU is freed, with the results so far in ``options.out``.

    Raises
    ------
    IpcosimError
        A bad option, scenario or FMU (one line naming it); SimulationError for a failed run
        (its ``result`` holds what was computed, already written to ``options.out``).
    """
    if prepared is None:
        with prepare_with(options) as own:
            return run_with(options, own, observers=observers, manipulators=manipulators,
                            raise_on_error=raise_on_error)
    live = open_live_view(options, prepared, resolve_relative(prepared.system, options.set)) if options.live else None
    if live is not None:
        observers = [*observers, live.feed]
    try:
        with signals.deferred(timeout=options.timeout):  # a no-op inside the command line's own
            result = prepared.run(options, observers=observers, manipulators=manipulators,
                                  raise_on_error=raise_on_error)
    except BaseException as exc:
        if live is not None:
            partial = getattr(exc, "result", None)
            live.finished(json_safe(partial.metrics) if partial is not None else None)
            live.close()
        raise
    if live is not None:
        result.metadata["live_url"] = live.url
        live.finished(json_safe(result.metrics))
        live.close()
    if options.save_baseline is not None:
        from ipcosim.harness.testing.baseline import save_baseline

        result.metadata.setdefault("files", {})["baseline"] = str(
            save_baseline(result, options.save_baseline, list(options.record) or None))
    return result


def open_live_view(options: RunOptions, prepared: Prepared, values: Mapping[str, Any]) -> Any:
    """The live view of a run (``--live``): its page served, its address printed; the scene after the
    plant kind, the rig's status from a monitor session (opened by the page's serving process) when a HIL
    adapter drives a virtual rig (:func:`ipcosim.harness.hil.observer.rig_monitor`). Returns the
    :class:`~ipcosim.harness.live.session.LiveSession` whose ``feed`` the run observes with."""
    from ipcosim.harness.api.options import scenario_label
    from ipcosim.harness.hil.observer import rig_monitor
    from ipcosim.harness.live.scene import scene
    from ipcosim.harness.live.session import open_live

    def start(component: str, variable: str) -> Any:
        if f"{component}.{variable}" in values:
            return values[f"{component}.{variable}"]
        try:
            return prepared.system.instance(component).start_value(variable)
        except KeyError:
            return None

    swaps = ", ".join(f"{k}={v}" for k, v in prepared.swap.items())
    title = scenario_label(options.scenario) + (f" ({swaps})" if swaps else "")
    monitor = rig_monitor(prepared.system.instances, start)
    rig = (None if monitor is None else
           {"card_type": monitor.card_type, "card_id": monitor.card_id, "host": monitor.host, "port": monitor.port})
    return open_live(lambda names: scene(names, title, start), host=options.live_host, port=options.live_port,
                     token=options.live_token, rig=rig, rig_token=monitor.token if monitor else None)


def resolve_relative(system: System, values: Mapping[str, Any]) -> dict[str, Any]:
    """The ``--set`` ``values`` with those relative to the scenario's (``"1.1*nominal"``, the ``--vary``
    grammar's scaling) turned into numbers: the value the scenario binds to the variable
    (else the FMU's start value) times the factor.

    Raises
    ------
    UsageError
        A relative value for an unknown component or variable, or one without a numeric nominal.
    """
    out: dict[str, Any] = {}
    for key, value in values.items():
        factor, relative = strip_nominal(value, f"--set {key}={value}") if isinstance(value, str) else ("", False)
        if not relative:
            out[key] = value
            continue
        comp, _, var = key.partition(".")
        try:
            out[key] = float(factor) * float(system.instance(comp).start_value(var))
        except (KeyError, TypeError, ValueError):
            raise UsageError(f"--set {key}={value}: expected NUMBER*nominal on a numeric variable of the "
                             f"scenario") from None
    return out


def _with_fmus(scenario: Scenario, fmus: Mapping[str, Path]) -> Scenario:
    """The scenario with the FMU of each component in ``fmus`` (an archive's extracted members)."""
    import dataclasses

    if not fmus:
        return scenario
    return dataclasses.replace(scenario, components=tuple(
        dataclasses.replace(c, fmu=fmus.get(c.name, c.fmu)) for c in scenario.components))
