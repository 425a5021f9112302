"""The options of one run: the single object behind ``ipcosim run`` and :func:`ipcosim.run`.

Each option is declared once, as a field of :class:`RunOptions` carrying its :class:`Option`: the
command-line flag, its help, and the check that turns a given value (text from the command line,
or a Python value) into the field's value. The command line's parser is built from the fields
(:func:`add_run_arguments`), its arguments become the object (:meth:`RunOptions.from_args`), and
:func:`ipcosim.run`'s keywords become the same object through the same checks; both hand it to
:func:`ipcosim.harness.api.engine.run_with`. A check that fails names the option the way the command
line spells it (``--stop-time -1: must be a positive number of seconds``), so the API raises the
same one-line message the command line prints.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from ipcosim.errors import UsageError
from ipcosim.harness.api.grammar import parse_pairs, parse_set
from ipcosim.harness.master.algorithm import ALGORITHMS
from ipcosim.harness.master.cloop import LOOPS
from ipcosim.harness.scenario.flavour import FLAVOURS
from ipcosim.harness.support.paths import BUILD_DIR, BUILD_FMU_DIR


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


#: ``--parameter-file``'s help, for ``run``, ``sweep`` and ``analyze`` alike (:func:`with_parameter_file`).
PARAMETER_FILE_HELP = ("SSV file of COMP.VAR values (e.g. `ipcosim identify --out DIR`'s DIR/identified.ssv), "
                       "applied after the scenario's own sets; --set values apply after it")


@dataclass(frozen=True)
class Option:
    """How one run option is given and checked (the metadata of a :class:`RunOptions` field).

    Attributes
    ----------
    flag : str
        The command line's spelling: ``--stop-time``, or a name without dashes for a positional
        argument; empty: an option of the Python API only.
    help : str
        The command line's help, also the field's description in :class:`RunOptions`'s docstring.
    check : callable
        ``check(flag, value) -> value``: the field's value from a given one (text or a Python
        value); raises UsageError naming ``flag`` and the value.
    metavar, action, choices : optional
        As :meth:`argparse.ArgumentParser.add_argument` takes them.
    dest : str
        The parser's name of the argument when it is not the field's (``--quiet`` stores ``progress``).
    command_default : callable, optional
        ``command_default(args)``: the command line's value when the flag is absent and the
        argument holds None (``--out``: ``out/<scenario>``).
    stage : str
        Who takes it (:data:`STAGES`): ``load``, the prepared scenario (:func:`~ipcosim.harness.api.engine.prepare`);
        ``run``, each run of it (:meth:`~ipcosim.harness.api.engine.Prepared.run`); ``command``, the one
        run of ``ipcosim run`` and :func:`ipcosim.run` around it (:func:`~ipcosim.harness.api.engine.run_with`).
    """

    flag: str
    help: str
    check: Callable[[str, Any], Any]
    metavar: str | None = None
    action: str | None = None
    choices: tuple[str, ...] | None = None
    dest: str | None = None
    command_default: Callable[[argparse.Namespace], Any] | None = None
    stage: str = "run"

    def __post_init__(self) -> None:
        if self.stage not in STAGES:  # a field of no stage would be taken by nobody
            raise ValueError(f"run option {self.flag or '(API only)'}: stage {self.stage!r}, "
                             f"expected one of {', '.join(STAGES)}")


#: Who takes a run option: the prepared scenario, each run of it, or the command around one run.
STAGES = ("load", "run", "command")


def option(default: Any = None, *, flag: str = "", help: str,  # noqa: A002 -- argparse's word
           check: Callable[[str, Any], Any] | None = None, **how: Any) -> Any:
    """A field of :class:`RunOptions` declaring its :class:`Option`."""
    return field(default=default, metadata={"option": Option(flag, help, check or _as_given, **how)})


def _as_given(flag: str, value: Any) -> Any:
    return value


def _flag(flag: str, value: Any) -> bool:
    return bool(value)


def _path(flag: str, value: Any) -> Path | None:
    return None if value is None else Path(value)


def _choice(values: Sequence[str], joined: str = "one of ") -> Callable[[str, Any], str]:
    """A check that ``value`` is one of ``values`` (``--loop fast: expected one of auto, c, python``)."""
    def check(flag: str, value: Any) -> str:
        if value not in values:
            listed = ", ".join(values) if joined else " or ".join(values)
            raise UsageError(f"{flag} {value}: expected {joined}{listed}")
        return value
    return check


def _scenario(flag: str, value: Any) -> Any:
    if not os.fspath(value):
        raise UsageError("scenario: empty name")
    return value


def _columns(flag: str, value: Any) -> tuple[str, ...]:
    """``--record`` items, each possibly ``a,b``: the column names or patterns."""
    items = [value] if isinstance(value, str) else (value or ())
    return tuple(v.strip() for item in items for v in str(item).split(",") if v.strip())


def _folders(flag: str, value: Any) -> tuple[Path, ...]:
    return tuple(Path(d) for d in (value or ()))


def _realtime(flag: str, value: Any) -> bool | None:
    return value if value is None else bool(value)


def _port(flag: str, value: Any) -> int:
    return _port_option(flag, value)


def _default_out(args: argparse.Namespace) -> Path:
    return Path("out") / scenario_label(args.scenario)


@dataclass(frozen=True)
class RunOptions:
    """Everything that defines one run of a scenario (see ``ipcosim run --help``); the attributes
    below are written from the fields' declarations.

    Every field is checked when the object is made (``RunOptions("single-mass-lqr", stop_time="2")``
    holds ``stop_time=2.0``), whatever the caller gave: text as on the command line, or Python values
    (numbers, mappings or ``"a=b"`` lists, paths).
    """

    scenario: str | os.PathLike[str] = option(
        flag="scenario", metavar="SCENARIO|PATH", check=_scenario, stage="load",
        help="scenario name (see `ipcosim list`), scenario folder, SystemStructure.ssd or .ssp archive")
    stop_time: float | None = option(flag="--stop-time", metavar="S", check=seconds_option,
                                     help="simulated time [s] (default: the scenario's, 10 s)")
    step: float | None = option(flag="--step", metavar="H", check=seconds_option,
                                help="communication step [s] (default: the scenario's, 0.001 s)")
    set: dict[str, Any] = option(  # type: ignore[assignment]  -- None: no value; checked into a dict
        flag="--set", action="append", metavar="COMP.VAR=VALUE", check=lambda flag, v: parse_set(v),
        help="override a parameter or input start value, e.g. --set plant.Mp=0.2 (repeatable)")
    swap: dict[str, Any] = option(  # type: ignore[assignment]
        flag="--swap", action="append", metavar="COMPONENT=FMU_OR_ALIAS", stage="load",
        check=lambda flag, v: parse_pairs(flag, v, "COMPONENT=FMU_OR_ALIAS"),
        help="replace a component by another FMU with compatible connectors, e.g. --swap plant=hil")
    parameter_set: str | None = option(
        flag="--parameter-set", metavar="NAME", stage="load",
        help="bind this parameter set of the scenario (thesis, tuned...) instead of the default")
    realtime: bool | None = option(flag="--realtime", action="store_const", check=_realtime,
                                   help="pace the run to wall-clock time")
    out: Path | None = option(flag="--out", metavar="DIR", check=_path, command_default=_default_out,
                              help="output folder (default: out/<scenario>)")
    plot: bool = option(False, flag="--plot", action="store_true", help="also write DIR/plot.png")
    record: tuple[str, ...] = option(  # type: ignore[assignment]
        flag="--record", action="append", metavar="VAR[,VAR...]", check=_columns,
        help="columns of results.csv: names or patterns like 'plant.*' (default: every connector); a "
             "parameter or local by name, e.g. plant.Mp, is read from the FMU after every step")
    algorithm: str = option(
        ALGORITHMS[0], flag="--algorithm", choices=ALGORITHMS, check=_choice(ALGORITHMS), stage="load",
        help="co-simulation algorithm (default gauss-seidel, ordered by the FMUs' dependencies)")
    fmu_dirs: tuple[Path, ...] = option(  # type: ignore[assignment]
        flag="--fmu-dir", action="append", metavar="DIR", dest="fmu_dir", check=_folders, stage="load",
        help=f"extra folder to look for FMUs in (also IPCOSIM_FMU_PATH); the built ones are in "
             f"{BUILD_FMU_DIR} (build/ of a source checkout, else the per-user cache)")
    save_baseline: Path | None = option(
        flag="--save-baseline", metavar="FILE", check=_path, stage="command",
        help="also write the recorded columns (see --record) as a baseline CSV for assert_close_to")
    progress: bool = option(False, flag="--quiet", action="store_false", dest="quiet", check=_flag,
                            help="print nothing but errors")
    fmus: str = option(FLAVOURS[0], flag="--fmus", choices=FLAVOURS, check=_choice(FLAVOURS, ""), stage="load",
                       help=f"FMU flavour: python (default, in {BUILD_FMU_DIR}) or native (C, from `ipcosim "
                            f"build --native`, in {BUILD_DIR / 'fmus-native'})")
    timeout: float | None = option(
        flag="--timeout", metavar="S", check=seconds_option, stage="command",
        help="wall-clock limit [s]: stop the run there with its results so far (exit status 124)")
    loop: str = option(LOOPS[0], flag="--loop", choices=LOOPS, check=_choice(LOOPS),
                       help="the master's stepping loop: auto (default: compiled C where it can run, else "
                            "Python), c (an error where it cannot run) or python")
    overrun_budget: float | None = option(
        flag="--overrun-budget", metavar="FRACTION", check=fraction_option,
        help="a real-time run's allowed late steps, as a fraction of its steps (default: "
             "IPCOSIM_RT_OVERRUN_BUDGET, else 0.01); a run beyond it warns and exits with status 3")
    strict: bool = option(False, flag="--strict", action="store_true", stage="load",
                          help="parameters of the scenario that a swapped-in FMU does not have are an error "
                               "(default: ignored, named in one warning line)")
    parameter_file: Path | None = option(flag="--parameter-file", metavar="FILE.ssv", check=_path,
                                         help=PARAMETER_FILE_HELP)
    live: bool = option(False, flag="--live", action="store_true", check=_flag, stage="command",
                        help="serve a page showing the run as it happens, with a stop button (its address is "
                             "printed)")
    live_host: str = option("127.0.0.1", flag="--live-host", metavar="ADDRESS", stage="command",
                            help="where the live page listens (default 127.0.0.1; another address needs "
                                 "--live-token)")
    live_port: int = option(0, flag="--live-port", metavar="N", check=_port, stage="command",
                            help="the live page's port (default 0: any free port)")
    live_token: str | None = option(flag="--live-token", metavar="TOKEN", stage="command",
                                    help="access token the live page asks every request for")
    # Options of the Python API only, checked by the execution (``check_times``) as it takes them:
    start_time: float | None = option(help="the run's start time [s] (default: the scenario's)")
    record_every: int = option(1, help="record every n-th communication point (default 1: each)")
    max_init_iterations: int = option(20, help="the most passes that propagate the outputs to the "
                                                              "inputs during initialization (default 20)")

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            how: Option = f.metadata["option"]
            object.__setattr__(self, f.name, how.check(how.flag or f.name, getattr(self, f.name)))
        if self.parameter_file is not None:  # the --set values win over the file's
            object.__setattr__(self, "set", with_parameter_file(self.parameter_file, self.set))
        if self.live:
            from ipcosim.harness.live.server import check_address

            check_address(self.live_host, self.live_port, self.live_token)
        elif self.live_token is not None or self.live_port or self.live_host != "127.0.0.1":
            raise UsageError("--live-host, --live-port and --live-token: only with --live")

    @classmethod
    def create(cls, scenario: str | os.PathLike[str], **options: Any) -> "RunOptions":
        """The checked options (the same as ``RunOptions(scenario, **options)``).

        Raises
        ------
        UsageError
            A value the command line would reject, with the command line's message.
        """
        return cls(scenario, **options)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "RunOptions":
        """The options of an ``ipcosim run`` command line (:func:`add_run_arguments`)."""
        values = {}
        for f in dataclasses.fields(cls):
            how: Option = f.metadata["option"]
            if not how.flag:  # an option of the Python API only: its default
                continue
            value = getattr(args, how.dest or f.name)
            values[f.name] = how.command_default(args) if value is None and how.command_default else value
        return cls(**values)


def run_options() -> list[tuple[str, Option]]:
    """Every run option: the field's name and its :class:`Option`, in declaration order."""
    return [(f.name, f.metadata["option"]) for f in dataclasses.fields(RunOptions)]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Add every run option with a flag to ``parser`` (``ipcosim run``'s), from the fields."""
    for name, how in run_options():
        if not how.flag:
            continue
        kwargs: dict[str, Any] = {"help": how.help}
        if how.action == "store_const":
            kwargs.update(action="store_const", const=True)
        elif how.action:
            kwargs["action"] = how.action
        if how.action == "append":
            kwargs["default"] = []
        if how.metavar:
            kwargs["metavar"] = how.metavar
        if how.choices:
            kwargs.update(choices=how.choices, default=_default(name))
        elif how.action is None and _default(name) is not None:
            kwargs["default"] = _default(name)
        if how.flag.startswith("-"):
            kwargs["dest"] = how.dest or name
        parser.add_argument(how.flag, **kwargs)


def _default(name: str) -> Any:
    return RunOptions.__dataclass_fields__[name].default


def _attributes() -> str:
    """The numpydoc Attributes section of :class:`RunOptions`, from the fields' help."""
    lines = ["", "    Attributes", "    ----------"]
    for name, how in run_options():
        given = how.flag if how.flag.startswith("-") else "positional" if how.flag else "Python API only"
        lines.append(f"    {name} : {given}" + (" (its inverse)" if how.action == "store_false" else ""))
        lines.append(f"        {how.help[0].upper()}{how.help[1:]}.")
    return "\n".join(lines) + "\n"


RunOptions.__doc__ = (RunOptions.__doc__ or "").rstrip() + "\n" + _attributes()


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
    from ipcosim.harness.scenario.ssv import read_parameter_file

    return {**read_parameter_file(path), **values}


def scenario_label(text: str | os.PathLike[str]) -> str:
    """A short name for a scenario given by name or path (``single-mass-lqr``)."""
    p = Path(text)
    if p.name == "SystemStructure.ssd":
        return p.parent.name
    return p.stem if p.suffix == ".ssp" else (p.name or os.fspath(text))
