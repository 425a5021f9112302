"""The options of one run: the single object behind ``ipcosim run`` and :func:`ipcosim.run`.

The command line builds a :class:`RunOptions` from its arguments (:meth:`RunOptions.from_args`),
the Python API from keywords (:meth:`RunOptions.create`); both hand it to
:func:`ipcosim.harness.engine.run_with`. A check that fails names the option the way the command
line spells it (``--stop-time -1: must be a positive number of seconds``), so the API raises
the same one-line message the command line prints.
"""
from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ipcosim.errors import UsageError
from ipcosim.harness.grammar import parse_pairs, parse_set
from ipcosim.harness.master.algorithm import ALGORITHMS
from ipcosim.harness.master.cloop import LOOPS
from ipcosim.harness.scenario.flavour import FLAVOURS


def seconds_option(option: str, value: Any) -> float | None:
    """A positive, finite number of seconds (text or number), or None.

    Raises
    ------
    UsageError
        Naming the option and the value.
    """
    return _number_option(option, value, lambda x: math.isfinite(x) and x > 0, "not a number of seconds",
                          "must be a positive number of seconds")


def fraction_option(option: str, value: Any) -> float | None:
    """A fraction in [0, 1] (text or number), or None.

    Raises
    ------
    UsageError
        Naming the option and the value.
    """
    expected = "expected a fraction in [0, 1] (0.01: 1 % of the steps)"
    return _number_option(option, value, lambda x: 0.0 <= x <= 1.0, expected, expected)


def _number_option(option: str, value: Any, ok: Any, not_number: str, out_of_range: str) -> float | None:
    """``value`` as a float if ``ok(float)``, None for None; else UsageError ``"OPTION VALUE: why"``."""
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{option} {value!r}: {not_number}") from None
    if not ok(number):  # NaN fails every check
        raise UsageError(f"{option} {value}: {out_of_range}")
    return number


@dataclass(frozen=True)
class RunOptions:
    """Everything that defines one run of a scenario (see ``ipcosim run --help``).

    Attributes
    ----------
    scenario : str or path
        Scenario name (``single-mass-lqr``), folder, SystemStructure.ssd or ``.ssp`` archive.
    stop_time, step : float or None
        Simulated time and communication step [s]; None: the scenario's DefaultExperiment.
    set : dict
        ``{"component.variable": value}`` start values; a value ``"1.1*nominal"`` is
        relative to the value the scenario binds.
    swap : dict
        ``{"component": FMU path or alias}``, e.g. ``{"plant": "hil"}``.
    parameter_set : str or None
        The scenario's parameter set (``thesis``, ``tuned``) instead of its default.
    realtime : bool or None
        Pace to wall-clock time; None: only when a swapped-in component asks for it.
    out : Path or None
        Folder for ``results.csv`` and ``metrics.json`` (and ``plot.png``); None writes nothing.
    plot : bool
        Also write ``plot.png``.
    record : tuple of str
        Columns of results.csv (names or patterns such as ``plant.*``); empty: every connector.
    algorithm : str
        ``gauss-seidel`` or ``jacobi``.
    fmu_dirs : tuple of Path
        Extra folders to look for FMUs in.
    save_baseline : Path or None
        Also write the recorded columns as a baseline CSV (see :mod:`ipcosim.harness.baseline`).
    progress : bool
        Show a progress bar on a terminal.
    fmus : str
        FMU flavour: ``python`` (pythonfmu FMUs, default) or ``native`` (C FMUs from
        ``ipcosim build --native``).
    timeout : float or None
        Wall-clock limit [s]: the run stops there with its results so far
        (:class:`ipcosim.harness.master.signals.Interrupted`; the command line exits 124).
    loop : str
        The master's stepping loop: ``auto`` (the C loop where it can run, else the Python
        loop), ``c`` (an error where it cannot run) or ``python`` (see docs/master.md).
    parameter_file : Path or None
        An SSV file of ``component.variable`` values (``ipcosim identify --out``'s ``identified.ssv``),
        applied after the scenario's own sets; ``set`` applies after it (:func:`with_parameter_file`).
    overrun_budget : float or None
        A real-time run's allowed overruns, as a fraction of its steps; beyond it
        ``metrics["overrun_budget_exceeded"]`` is true (the command line warns and exits 3).
        None: ``IPCOSIM_RT_OVERRUN_BUDGET``, else 0.01
        (:data:`ipcosim.harness.master.realtime.DEFAULT_OVERRUN_BUDGET`).
    strict : bool
        Parameters of the scenario that a swapped-in FMU does not have are an error (default:
        ignored, named in one warning line per component).
    live : bool
        Serve a page that shows the run as it happens, with a stop button (docs/live.md); its
        address is printed on stderr when the run starts.
    live_host, live_port, live_token : str, int, str or None
        Where the live page is served (default 127.0.0.1, any free port) and its access token: an
        address other than loopback needs one (``--live-host 0.0.0.0 --live-token T``).
    """

    scenario: str | os.PathLike[str]
    stop_time: float | None = None
    step: float | None = None
    set: dict[str, Any] = field(default_factory=dict)
    swap: dict[str, Any] = field(default_factory=dict)
    parameter_set: str | None = None
    realtime: bool | None = None
    out: Path | None = None
    plot: bool = False
    record: tuple[str, ...] = ()
    algorithm: str = "gauss-seidel"
    fmu_dirs: tuple[Path, ...] = ()
    save_baseline: Path | None = None
    progress: bool = False
    fmus: str = "python"
    timeout: float | None = None
    loop: str = "auto"
    parameter_file: Path | None = None
    overrun_budget: float | None = None
    strict: bool = False
    live: bool = False
    live_host: str = "127.0.0.1"
    live_port: int = 0
    live_token: str | None = None

    def __post_init__(self) -> None:
        if self.loop not in LOOPS:
            raise UsageError(f"--loop {self.loop}: expected one of {', '.join(LOOPS)}")
        if self.fmus not in FLAVOURS:
            raise UsageError(f"--fmus {self.fmus}: expected {' or '.join(FLAVOURS)}")
        if self.algorithm not in ALGORITHMS:
            raise UsageError(f"--algorithm {self.algorithm}: expected one of {', '.join(ALGORITHMS)}")
        if not os.fspath(self.scenario):
            raise UsageError("scenario: empty name")
        if self.live:
            from ipcosim.harness.live.server import check_address

            check_address(self.live_host, self.live_port, self.live_token)
        elif self.live_token is not None or self.live_port or self.live_host != "127.0.0.1":
            raise UsageError("--live-host, --live-port and --live-token: only with --live")

    @classmethod
    def create(cls, scenario: str | os.PathLike[str], *, stop_time: Any = None, step: Any = None,
               set: Mapping[str, Any] | Sequence[str] | None = None,  # noqa: A002 -- the option's name
               swap: Mapping[str, Any] | Sequence[str] | None = None, parameter_set: str | None = None,
               realtime: bool | None = None, out: str | os.PathLike[str] | None = None, plot: bool = False,
               record: Sequence[str] | str | None = None, algorithm: str = "gauss-seidel",
               fmu_dirs: Sequence[str | os.PathLike[str]] | None = None,
               save_baseline: str | os.PathLike[str] | None = None, progress: bool = False,
               fmus: str = "python", timeout: Any = None, loop: str = "auto",
               overrun_budget: Any = None, strict: bool = False,
               parameter_file: str | os.PathLike[str] | None = None, live: bool = False,
               live_host: str = "127.0.0.1", live_port: Any = 0, live_token: str | None = None) -> "RunOptions":
        """Checked options from Python values (numbers or text, mappings or ``"a=b"`` lists).

        Raises
        ------
        UsageError
            A value the command line would reject, with the command line's message.
        """
        if isinstance(record, str):
            record = [record]
        columns = tuple(v.strip() for item in (record or ()) for v in str(item).split(",") if v.strip())
        return cls(scenario=scenario, stop_time=seconds_option("--stop-time", stop_time),
                   step=seconds_option("--step", step),
                   set=with_parameter_file(parameter_file, parse_set(set)),
                   swap=parse_pairs("--swap", swap, "COMPONENT=FMU_OR_ALIAS"),
                   parameter_set=parameter_set,
                   realtime=realtime, out=Path(out) if out is not None else None, plot=plot, record=columns,
                   algorithm=algorithm, fmu_dirs=tuple(Path(d) for d in (fmu_dirs or ())),
                   save_baseline=Path(save_baseline) if save_baseline is not None else None, progress=progress,
                   fmus=fmus, timeout=seconds_option("--timeout", timeout), loop=loop,
                   overrun_budget=fraction_option("--overrun-budget", overrun_budget), strict=strict,
                   parameter_file=Path(parameter_file) if parameter_file is not None else None,
                   live=bool(live), live_host=live_host, live_port=_port_option("--live-port", live_port),
                   live_token=live_token)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "RunOptions":
        """The options of an ``ipcosim run`` command line (default ``--out``: ``out/<scenario>``)."""
        out = Path(args.out) if args.out else Path("out") / scenario_label(args.scenario)
        return cls.create(args.scenario, stop_time=args.stop_time, step=args.step, set=args.set, swap=args.swap,
                          parameter_set=args.parameter_set, realtime=True if args.realtime else None, out=out,
                          plot=args.plot, record=args.record, algorithm=args.algorithm, fmu_dirs=args.fmu_dir,
                          save_baseline=args.save_baseline, progress=not args.quiet,
                          fmus=getattr(args, "fmus", "python"), timeout=getattr(args, "timeout", None),
                          loop=getattr(args, "loop", "auto"), overrun_budget=getattr(args, "overrun_budget", None),
                          strict=getattr(args, "strict", False),
                          parameter_file=getattr(args, "parameter_file", None),
                          live=getattr(args, "live", False), live_host=getattr(args, "live_host", "127.0.0.1"),
                          live_port=getattr(args, "live_port", 0), live_token=getattr(args, "live_token", None))


def _port_option(option: str, value: Any) -> int:
    """A TCP port number 0..65535 (text or number; 0: any free port)."""
    try:
        number = int(value)
    except (TypeError, ValueError):
        raise UsageError(f"{option} {value!r}: expected a port number 0..65535") from None
    if not 0 <= number <= 65535:
        raise UsageError(f"{option} {value}: expected a port number 0..65535 (0: any free port)")
    return number


def with_parameter_file(path: str | os.PathLike[str] | None, values: Mapping[str, Any]) -> dict[str, Any]:
    """The ``component.variable`` values of the SSV file ``path`` (``--parameter-file``) under ``values``
    (the ``--set`` values win), for ``run``, ``sweep`` and ``analyze`` alike."""
    if path is None:
        return dict(values)
    from ipcosim.harness.scenario.ssp import read_parameter_file

    return {**read_parameter_file(path), **values}


def scenario_label(text: str | os.PathLike[str]) -> str:
    """A short name for a scenario given by name or path (``single-mass-lqr``)."""
    p = Path(text)
    if p.name == "SystemStructure.ssd":
        return p.parent.name
    return p.stem if p.suffix == ".ssp" else (p.name or os.fspath(text))
