"""Turn a scenario name or path (plus run settings) into a run specification."""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from ipcosim.errors import UsageError
from ipcosim.harness.scenario.flavour import STUDY_FLAVOURS
from ipcosim.harness.studies.runners import PurePlantSpec, RunSpec

#: Scenario names served without FMUs (pure-Python stand-ins, see ``ipcosim.harness.studies.runners``).
PURE_SCENARIOS = {"pure:single-mass-lqr": PurePlantSpec}


def default_out(scenario: str, kind: str = "sweep") -> Path:
    """A study's default output folder, ``out/<kind>/<scenario name>`` (``kind``: sweep, tune...)."""
    name = Path(scenario.rstrip("/")).name.replace(":", "-")
    if name.endswith(".ssp"):
        name = name[:-4]
    return Path("out") / kind / name


def spec_for(scenario: str, stop_time: float | None = None, step: float | None = None,
             set: Mapping[str, float] | None = None, series: bool = False,
             parameter_set: str | None = None, fmus: str = "python") -> RunSpec:
    """The run specification of a scenario.

    Parameters
    ----------
    scenario : str
        A scenario name (``single-mass-lqr``), a path to a scenario folder or ``.ssp``, or a
        pure-Python stand-in (``pure:single-mass-lqr``).
    stop_time, step : float, optional
        Override the scenario's experiment.
    set : mapping, optional
        ``component.variable`` values set in every run (``--set``).
    series : bool
        Return the run's signals (thinned) with its metrics, under ``series`` (for figures).
    parameter_set : str, optional
        Bind this named parameter set of the scenario (``thesis``, ``tuned``, ``autotuned``)
        instead of its default.
    fmus : {'python', 'native'}
        FMU flavour of a co-simulated scenario (``ipcosim.harness.scenario.flavour``).
    """
    if stop_time is not None and not stop_time > 0:
        raise UsageError(f"--stop-time {stop_time}: must be positive")
    if step is not None and not step > 0:
        raise UsageError(f"--step {step}: must be positive")
    if scenario in PURE_SCENARIOS:
        if parameter_set:
            raise UsageError(f"--parameter-set {parameter_set}: {scenario} has no parameter sets")
        kwargs: dict = {"with_series": series}
        if stop_time is not None:
            kwargs["stop_time"] = stop_time
        if step is not None:
            kwargs["step"] = step
        spec = PURE_SCENARIOS[scenario](**kwargs)
        if set:
            unknown = [k for k in set if k not in spec.parameters]
            if unknown:
                raise UsageError(f"--set {unknown[0]}: {scenario} has no parameter {unknown[0]!r}")
            spec.parameters = {**spec.parameters, **set}
        return spec
    from ipcosim.harness.studies.cosim import CosimSpec

    return CosimSpec.from_scenario(scenario, stop_time=stop_time, step=step, set=set, series=series,
                                   parameter_set=parameter_set, fmus=fmus)


def for_executor(spec: RunSpec, executor: object) -> RunSpec:
    """The spec to send to ``executor``: on a Dask cluster, co-simulation specs carry their
    scenario and FMUs (workers may be other machines); locally, workers read the files."""
    from ipcosim.harness.studies.executors import DaskExecutor

    if not isinstance(executor, DaskExecutor):
        return spec
    from ipcosim.harness.studies.runners import MultiSpec

    if isinstance(spec, MultiSpec):
        return MultiSpec(specs=[for_executor(s, executor) for s in spec.specs], name=spec.name)
    portable = getattr(spec, "portable", None)
    return portable() if callable(portable) else spec




def study_spec(scenario: str, fmus: str = "auto", names: Iterable[str] = (),
               check: Callable[[RunSpec], object] | None = None, **kwargs: Any) -> tuple[RunSpec, str]:
    """The run specification of a study (sweep, robustness, tune, compare) on an FMU flavour.

    ``fmus="auto"`` chooses the native flavour (C FMUs, ``ipcosim build --native``; several times
    faster, equal results to 1e-9, docs/native.md) when all of these hold, else the Python one:
    the native FMUs are built; the scenario runs on them (no measurement noise or taps, a native model
    for every component); every parameter the study sets or varies (``names``, ``component.variable``)
    is a parameter of the native FMUs and not an instrument option the native plant lacks; and
    ``check(spec)`` (the study's own parsing of its options against ``spec.parameters``) passes.
    ``python`` and ``native`` are taken as given (a study the flavour cannot run fails as with
    ``ipcosim run --fmus``).

    Returns the spec and one line saying which flavour runs and, for ``auto``, why.
    """
    if fmus not in STUDY_FLAVOURS:
        raise UsageError(f"--fmus {fmus}: expected one of {', '.join(STUDY_FLAVOURS)}")
    python = functools.lru_cache(maxsize=1)(lambda: spec_for(scenario, fmus="python", **kwargs))  # loaded once
    if fmus != "auto" or scenario in PURE_SCENARIOS:
        spec = python() if fmus != "native" else spec_for(scenario, fmus="native", **kwargs)
        if fmus == "native" and scenario not in PURE_SCENARIOS:
            _check_native_names(spec, list(names), python)
        if check is not None:
            check(spec)
        if scenario in PURE_SCENARIOS:
            return spec, "no FMUs (a pure-Python stand-in)"
        return spec, f"{fmus} FMUs"
    reason = _native_refusal(scenario, list(names), check, kwargs, python)
    if isinstance(reason, str):
        spec = python()
        if check is not None:
            check(spec)
        return spec, f"python FMUs (native flavour not used: {reason})"
    return reason, "native FMUs (auto: built, and they run this study; --fmus python to compare)"


def _not_native(name: str, native: RunSpec, python: Mapping[str, Any] | None) -> str:
    """Why ``name`` is missing from the ``native`` spec's FMUs (one line), said from what the build recorded:
    a design parameter its native FMU lists as the Python flavour's only (``python_only`` of its
    ``native.json``), a parameter of the ``python`` flavour (its parameters; None: not known) that the native
    FMU was built without (the native folder is older than the sources), or a name neither flavour has."""
    from ipcosim.harness.scenario.flavour import native_fmu_dir
    from ipcosim.harness.scenario.rebuild import rebuild_command

    where = f"{name} is not a parameter of the native FMUs in {native_fmu_dir()}"
    if name.partition(".")[2] in _python_only(native, name.partition(".")[0]):
        return f"{where} (a design parameter of the Python flavour: the native FMUs take the numbers it designs)"
    if python is not None and name in python:
        command = rebuild_command(native_fmu_dir())
        return f"{where}: they are older than the sources" + (f" (`{command}` rebuilds them)" if command else "")
    return f"{where}, nor of the Python ones" if python is not None else where


def _python_only(native: RunSpec, component: str) -> tuple[str, ...]:
    """The design parameters the native FMU of ``component`` was built without (``native.json``); () if unknown."""
    from ipcosim.errors import IpcosimError
    from ipcosim.harness.native.redesign import native_info
    from ipcosim.harness.scenario.ssp import load_scenario

    try:
        sources = {c.name: c.source for c in load_scenario(native.location).components}
    except (IpcosimError, OSError, AttributeError):
        return ()
    fmu = getattr(native, "fmu_files", {}).get(sources.get(component, ""))
    info = native_info(fmu) if fmu else None
    return tuple(info.get("python_only", ())) if info else ()


def _check_native_names(spec: RunSpec, names: list[str], python_spec: Callable[[], RunSpec]) -> None:
    """UsageError for the first of ``names`` the native ``spec`` lacks but the Python flavour has, or whose closest
    name is the Python flavour's only (any other name neither has is left to the study's own check, which
    answers with the closest names)."""
    from ipcosim.errors import close_names, closest

    missing = [n for n in names if n not in spec.parameters]
    if missing:
        python = _python_parameters(python_spec)
        if python is None:
            return   # no Python flavour to compare with: the study's own check answers
        both = set(python) | set(spec.parameters)
        for name in missing:
            if name in python:
                raise UsageError(f"--fmus native: {_not_native(name, spec, python)}; --fmus python runs it")
            near = close_names(name, both)
            only = [n for n in near if n not in spec.parameters]
            if near and near[0] in only:  # a slip of a Python-only name: the native names would suggest others
                raise UsageError(f"--fmus native: unknown parameter {name!r}; {closest(name, both)} "
                                 f"({', '.join(map(repr, only))}: of the Python FMUs only; --fmus python runs them)")


def _python_parameters(python_spec: Callable[[], RunSpec]) -> Mapping[str, Any] | None:
    """The parameters of the scenario's Python-flavour spec, or None when it cannot be made."""
    from ipcosim.errors import IpcosimError

    try:
        return python_spec().parameters
    except (IpcosimError, OSError):
        return None


def _native_refusal(scenario: str, names: list[str], check: Callable[[RunSpec], object] | None,
                    kwargs: Mapping[str, Any], python_spec: Callable[[], RunSpec]) -> RunSpec | str:
    """The native spec of a study, or why the native flavour cannot run it (one line); ``python_spec``
    gives the Python flavour's (made at most once)."""
    from ipcosim.errors import IpcosimError
    from ipcosim.harness.native.models import NATIVE_INSTRUMENTS_OFF
    from ipcosim.harness.scenario.flavour import native_fmu_dir

    if not any(native_fmu_dir().glob("*.fmu")):
        return f"not built in {native_fmu_dir()} (ipcosim build --native)"
    try:
        spec = spec_for(scenario, fmus="native", **kwargs)
    except (IpcosimError, OSError, ValueError) as exc:
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    for name in names:
        if name not in spec.parameters:
            return _not_native(name, spec, _python_parameters(python_spec))
        if name.partition(".")[2] in NATIVE_INSTRUMENTS_OFF:
            return f"{name} is an instrument option the native plant lacks"
    if check is not None:
        try:
            check(spec)
        except (IpcosimError, ValueError) as exc:
            return str(exc).splitlines()[0]
    return spec
