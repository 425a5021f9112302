"""The public Python API, re-exported at the top of the package: ``ipcosim.run``,
``ipcosim.scenarios``, ``ipcosim.build`` and ``ipcosim.build_fmu``.

A thin layer over :mod:`ipcosim.harness.api.engine`: the keywords become one
:class:`~ipcosim.harness.api.options.RunOptions`, the object the command line builds from its
arguments, so ``ipcosim.run(...)`` and ``ipcosim run ...`` check and do the same thing and
fail with the same one-line message (an :class:`ipcosim.IpcosimError`).
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.api.options import RunOptions
from ipcosim.harness.master.manipulators import Manipulator
from ipcosim.harness.master.observers import Observer
from ipcosim.harness.master.results import Result


class FMUBuildError(IpcosimError, RuntimeError):
    """A user's FMU script that could not be built (one line naming the script)."""


def run(scenario: str | os.PathLike[str], *, swap: Mapping[str, Any] | None = None,
        set: Mapping[str, Any] | None = None,  # noqa: A002 -- the command line's --set
        stop_time: float | None = None, step: float | None = None, parameter_set: str | None = None,
        realtime: bool = False, out: str | os.PathLike[str] | None = None, observers: Sequence[Observer] = (),
        manipulators: Sequence[Manipulator] = (), **more: Any) -> Result:
    """Co-simulate a scenario once, as ``ipcosim run`` does. (Long on purpose: the public reference of
    its options, with examples that run as doctests, over a two-line body.)

    Parameters
    ----------
    scenario : str or path
        Scenario name (see :func:`scenarios`), scenario folder, SystemStructure.ssd or ``.ssp``.
    swap : mapping, optional
        Components to replace: ``{"controller": "my/MyController.fmu"}`` or ``{"plant": "hil"}``.
    set : mapping, optional
        Start values, ``{"plant.Mp": 0.2}``; ``"1.1*nominal"`` scales the scenario's value.
    stop_time, step : float, optional
        Simulated time and communication step [s] (default: the scenario's, 10 s at 1 ms).
    parameter_set : str, optional
        The scenario's parameter set (``thesis``, ``tuned``) instead of its default.
    realtime : bool
        Pace the run to wall-clock time (on by itself when a component needs it, e.g. a rig).
    out : path, optional
        Write ``results.csv`` and ``metrics.json`` there.
    observers, manipulators : sequences, optional
        Code that watches or changes the run between steps (:mod:`ipcosim.harness.master.observers`,
        :mod:`ipcosim.harness.master.manipulators`, e.g. ``ScheduledValues``).
    **more
        The other options of ``ipcosim run``: ``plot``, ``record``, ``algorithm``,
        ``fmu_dirs``, ``save_baseline``, ``timeout``, ``loop``, ``parameter_file``, ``live``
        (and ``live_host``, ``live_port``, ``live_token``: the run in the browser as it happens,
        docs/live.md) (see :class:`~ipcosim.harness.api.options.RunOptions`).
        SIGINT and SIGTERM during the run, and ``timeout``, stop it between FMU calls with its
        results so far written: :class:`ipcosim.harness.master.signals.Interrupted` (a
        KeyboardInterrupt) is raised after every FMU is freed.

    Returns
    -------
    Result
        ``metrics`` (dict, see docs/api.md), ``data`` (numpy structured array with the
        columns of results.csv), ``plot()``.

    Raises
    ------
    IpcosimError
        Bad option, unknown scenario, missing FMU (``UsageError``, ``ScenarioError``,
        ``BindingError``...), or ``SimulationError`` when the run fails (its ``result``
        holds what was computed).

    Examples
    --------
    >>> import ipcosim
    >>> result = ipcosim.run("single-mass-lqr", stop_time=1.0, set={"plant.Mp": "1.1*nominal"})
    >>> result.metrics["upright"]
    True
    >>> result.data.dtype.names[0], len(result.data)
    ('time', 1001)
    >>> ipcosim.run("single-mass-lqr", stop_time=-1)
    Traceback (most recent call last):
    ...
    ipcosim.errors.UsageError: --stop-time -1: must be a positive number of seconds
    """
    from ipcosim.harness.api.engine import run_with

    options = RunOptions(scenario, swap=swap, set=set, stop_time=stop_time, step=step,  # type: ignore[arg-type]
                         parameter_set=parameter_set, realtime=True if realtime else None, out=out, **more)
    return run_with(options, observers=observers, manipulators=manipulators)


@dataclass(frozen=True)
class ScenarioInfo:
    """One scenario of the project: name, one-line description, default experiment, parameter sets."""

    name: str
    description: str
    stop_time: float | None
    step: float | None
    parameter_sets: tuple[str, ...]

    def __str__(self) -> str:
        sets = ", ".join(self.parameter_sets) or "-"
        return f"{self.name}  {self.description}  [{self.stop_time:g} s at {self.step:g} s; sets: {sets}]"


def scenarios() -> list[ScenarioInfo]:
    """The scenarios shipped with ipcosim, by name.

    Returns
    -------
    list of ScenarioInfo

    Raises
    ------
    ScenarioError
        A shipped scenario that does not load (names it).

    Examples
    --------
    >>> import ipcosim
    >>> [s.name for s in ipcosim.scenarios()][:2]
    ['double-mass-adaptive-hsmc', 'double-mass-cascade-pid']
    >>> info = {s.name: s for s in ipcosim.scenarios()}["single-mass-lqr"]
    >>> info.stop_time, info.step
    (10.0, 0.001)
    """
    from ipcosim.harness.scenario.locations import scenario_names
    from ipcosim.harness.scenario.ssp import load_scenario

    out = []
    for name in scenario_names():
        sc = load_scenario(name)
        out.append(ScenarioInfo(name, sc.description, sc.experiment.stop_time, sc.experiment.step_size,
                                tuple(sorted(sc.parameter_sets))))
    return out


def build(out: str | os.PathLike[str] | None = None, *, force: bool = False, ssp_version: str = "1.0") -> list[Path]:
    """Build the project's FMUs (and SSP archives) as ``ipcosim build`` does; unchanged ones are kept.

    Parameters
    ----------
    out : path, optional
        Output folder (FMUs in ``out/fmus``); default: ``build/`` of a source checkout, else
        the per-user cache ``~/.cache/ipcosim/<version>``, where scenarios look for them.
    force : bool
        Rebuild every FMU.
    ssp_version : str
        The SSP version the archives in ``out/ssp`` declare, ``1.0`` (default) or ``2.0``
        (``ipcosim build --ssp-version``).

    Returns
    -------
    list of Path
        The FMU files.

    Examples
    --------
    >>> import ipcosim
    >>> sorted(p.name for p in ipcosim.build())[:2]
    ['AdaptiveHSMCDoubleMass.fmu', 'AdaptiveHSMCSingleMass.fmu']
    """
    from ipcosim.fmus.pybuild import build_all
    from ipcosim.harness.scenario.ssp_pack import SSP_VERSIONS, pack_all
    from ipcosim.harness.support.paths import BUILD_DIR

    root = Path(out) if out is not None else BUILD_DIR
    if ssp_version not in SSP_VERSIONS:
        from ipcosim.errors import UsageError

        raise UsageError(f"ssp_version {ssp_version!r}: expected one of {', '.join(SSP_VERSIONS)}")
    fmus = [r.fmu for r in build_all(root / "fmus", force=force)]
    pack_all(root, ssp_version=ssp_version)
    return fmus


def build_fmu(script: str | os.PathLike[str], *, files: Sequence[str | os.PathLike[str]] = (),
              out: str | os.PathLike[str] | None = None) -> Path:
    """Build an FMU script of your own, cached by content.

    The script holds one subclass of ``ipcosim.fmus.fmi.FmuBase`` (the public FMU base:
    ``add_input``/``add_output``/``add_parameter``, ``setup()``, ``step(t, h)``). As for the
    project's FMUs, the FMU carries a private copy of the ipcosim modules the script imports,
    so it runs without ipcosim installed and beside any other FMU. The FMU is rebuilt only
    when the script, one of ``files``, those modules or the pythonfmu version changed.

    Parameters
    ----------
    script : path
        The FMU script (the model is named after its class).
    files : sequence of path
        Further files or package folders the FMU needs at run time (your own modules, data),
        packed into its ``resources/`` beside the script.
    out : path, optional
        Output folder (default: ``build/`` beside the script).

    Returns
    -------
    Path
        ``out/<Model>.fmu``.

    Raises
    ------
    FMUBuildError
        A missing file, or a script that does not build into a valid FMU (one line naming it).

    Examples
    --------
    >>> import ipcosim, pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (folder / "gain.py").write_text(
    ...     "from ipcosim.fmus.fmi import FmuBase\\n"
    ...     "class Gain(FmuBase):\\n"
    ...     "    def __init__(self, **kw):\\n"
    ...     "        super().__init__(**kw)\\n"
    ...     "        self.add_input('u', unit='V')\\n"
    ...     "        self.add_output('y', unit='V', depends_on=('u',))\\n"
    ...     "    def setup(self):\\n"
    ...     "        self.y = 2 * self.u\\n"
    ...     "    def step(self, t, h):\\n"
    ...     "        self.y = 2 * self.u\\n")
    >>> ipcosim.build_fmu(folder / "gain.py").name
    'Gain.fmu'
    """
    from ipcosim.fmus.pybuild import build_cached

    script, extra, digest = _sources(script, files)
    target = Path(out) if out is not None else script.parent / "build"
    target.mkdir(parents=True, exist_ok=True)
    return build_cached(script, target, str(script), digest,
                        build=lambda: _build_isolated(script, target, digest, extra)).fmu


def _sources(script: str | os.PathLike[str],
             files: Sequence[str | os.PathLike[str]]) -> tuple[Path, list[Path], str]:
    """The script and further files as absolute paths, and the digest of everything the FMU is
    built from: the script, the ipcosim modules it imports, the files (``.py`` of a folder).

    Raises
    ------
    FMUBuildError
        A file that does not exist.
    """
    from ipcosim.fmus.pybuild import runtime_modules, source_digest

    script = Path(script).resolve()
    extra = [Path(f).resolve() for f in files]
    for f in [script, *extra]:
        if not f.exists():
            raise FMUBuildError(f"build_fmu: {f} does not exist")
    contents = [p for f in extra for p in ([f] if f.is_file() else sorted(f.rglob("*.py")))]
    return script, extra, source_digest(script, [*runtime_modules(script), *contents])


def _build_isolated(script: Path, target: Path, digest: str, extra: Sequence[Path]) -> Path:
    """Build the script's FMU, leaving behind no module the builder imported from the script's folder.

    Raises
    ------
    FMUBuildError
        The first line of the builder's error.
    """
    from ipcosim.fmus.pybuild import BuildError, build_one

    saved = set(sys.modules)
    try:
        return build_one(script, target, digest=digest, project_files=extra)
    except BuildError as exc:
        raise FMUBuildError(str(exc).strip().splitlines()[0]) from exc
    finally:  # the builder imports the script and its own modules: do not leave them behind
        for name in set(sys.modules) - saved:
            if str(getattr(sys.modules.get(name), "__file__", "") or "").startswith(str(script.parent)):
                del sys.modules[name]


def linearize(plant: str, *, preset: str | None = None, inductance: bool = True, **params: float) -> Any:
    """The plant's linear model about the upright equilibrium, as ``ipcosim linearize`` gives it.

    Parameters
    ----------
    plant : str
        ``single-mass`` or ``double-mass``.
    preset : str, optional
        Parameter preset (default: the thesis's set for the plant).
    inductance : bool
        Keep the motor current as a state (False: 4 or 6 states).
    **params : float
        Physical parameters to change, e.g. ``Mp=0.2``.

    Returns
    -------
    LinearModel
        ``A, B, C, D`` (numpy arrays), ``states``, ``outputs``, ``poles``.

    Examples
    --------
    >>> import ipcosim
    >>> model = ipcosim.linearize("single-mass", inductance=False)
    >>> model.states
    ('cart_position', 'cart_velocity', 'pendulum_angle', 'pendulum_velocity')
    >>> model.A.shape, model.B.shape
    ((4, 4), (4, 1))
    """
    from ipcosim.fmus.linearize import linearize as linearize_params
    from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, ParameterError
    from ipcosim.fmus.params import preset as make_preset

    if plant not in DEFAULT_PRESET:
        raise ParameterError(f"plant {plant!r}: expected one of {', '.join(DEFAULT_PRESET)}")
    name = preset or DEFAULT_PRESET[plant]
    if name in PRESETS and PRESETS[name][0] != plant:
        raise ParameterError(f"preset {name!r} is a {PRESETS[name][0]} preset, not {plant}")
    return linearize_params(make_preset(name, **params), inductance=inductance)
