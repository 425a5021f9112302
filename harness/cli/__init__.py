"""The ``ipcosim`` command line.

Each sub-command lives in its own module of this package exposing
``register(subparsers)`` (adds its parser, with ``func`` set to its entry point) and an
entry point ``main(args) -> int``. A failure is reported as one line on stderr naming what
is wrong and where, with a non-zero exit status; ``--debug`` shows the traceback instead.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import sys
from pathlib import Path
from typing import Sequence

from ipcosim.errors import UsageError
from ipcosim.harness.master.signals import TIMEOUT_STATUS

#: Exit statuses of every command (docs/robustness.md): the work done; it failed (one line says why);
#: the command line was wrong (an unknown option or name, a bad value, an unusable --out: nothing was
#: done); a real-time run finished but missed deadlines beyond its budget; the --timeout wall-clock
#: limit stopped it; a signal stopped it (128 + the signal's number: 130 SIGINT, 143 SIGTERM).
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_REALTIME_DEGRADED, EXIT_TIMEOUT = 0, 1, 2, 3, TIMEOUT_STATUS

#: Sub-command modules, in the order ``ipcosim --help`` lists them.
COMMAND_MODULES = ("build", "list_", "describe", "run", "export", "linearize", "analyze", "rig", "compare", "sweep",
                   "tune", "identify", "view")
#: Each command's name on the command line (``list``), by its module's name (``list_``).
COMMANDS = {module.rstrip("_"): module for module in COMMAND_MODULES}
#: Commands that have closed every file they wrote when they return: the ``ipcosim`` command leaves after them
#: without the interpreter's teardown (:func:`leave`).
LEAVE_AT_ONCE = frozenset({"run"})
#: Commands whose start (their modules loaded, the parser built, the run prepared) makes many objects that live to
#: the end and little cyclic garbage: the ``ipcosim`` command starts them with the cyclic garbage collector off
#: and turns it on when their work begins (:func:`collector_on`).
COLLECT_AFTER_START = frozenset({"run"})
_COLLECTOR_PAUSED: list[bool] = []  # [True] while main has the collector off


def add_study_fmus_option(p: argparse.ArgumentParser) -> None:
    """``--fmus`` of the studies (sweep, tune, compare): ``auto`` by default
    (``ipcosim.harness.studies.specs.study_spec``)."""
    from ipcosim.harness.scenario.flavour import STUDY_FLAVOURS

    p.add_argument("--fmus", choices=STUDY_FLAVOURS, default=STUDY_FLAVOURS[0],
                   help="FMU flavour: auto (default: the native C FMUs when `ipcosim build --native` has built "
                        "them and they can run this study, else python), python, or native")


def add_parameter_file_option(p: argparse.ArgumentParser) -> None:
    """``--parameter-file`` of sweep and analyze, as ``ipcosim run`` has it
    (``ipcosim.harness.api.options.with_parameter_file``)."""
    from ipcosim.harness.api.options import PARAMETER_FILE_HELP

    p.add_argument("--parameter-file", metavar="FILE.ssv", help=PARAMETER_FILE_HELP)


class Parser(argparse.ArgumentParser):
    """An argument parser whose invalid choices (sub-command, plant kind, flavour) answer with the
    closest known ones; sub-command parsers are of this class too."""

    def _check_value(self, action: argparse.Action, value: object) -> None:
        from ipcosim.errors import closest

        if action.choices is not None and value not in action.choices:
            raise argparse.ArgumentError(action, f"invalid choice {value!r}; {closest(str(value), action.choices)}")


class _Version(argparse.Action):
    """``--version``: the installed distribution's version (``paths.distribution_version``), read only
    when asked for (reading the metadata costs every other command 20-25 ms)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        from ipcosim.harness.support.paths import distribution_version

        print(f"ipcosim {distribution_version()}")
        parser.exit()


def build_parser(only: str | None = None, listed: bool = True) -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered (``only=None``), or with the command
    ``only`` registered whole and every other one by its name and one line of help (``listed``: what the
    top-level help lists; without it, the other commands are left out, their modules not loaded).

    A command registers its options in its module's ``register``, which may load what the options
    are made of (the run options load numpy); its one line of help is the module's ``HELP``. So
    ``ipcosim --version`` (``only=""``) and each command load only what that command runs.
    """
    parser = Parser(
        prog="ipcosim",
        description="FMI co-simulation of the Quanser IP02 inverted pendulum (single and double mass).",
        allow_abbrev=False)
    parser.add_argument("--debug", action="store_true", help="show the full traceback on errors")
    parser.add_argument("--version", action=_Version, help="print the installed ipcosim's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS.items():
        if not (listed or only is None or name == only):
            continue
        module = importlib.import_module(f"ipcosim.harness.cli.{module_name}")
        if only is None or name == only:
            module.register(sub)
        else:
            sub.add_parser(name, help=module.HELP)
    for each in parsers(parser):
        each.allow_abbrev = False  # options are never abbreviated: `--token` is not `--token-file`
    return parser


def parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """``parser`` and every sub-command parser below it (``ipcosim rig status`` too), depth first."""
    out = [parser]
    for action in parser._actions:  # noqa: SLF001 -- argparse offers no public walk
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            for child in dict.fromkeys(action.choices.values()):
                out.extend(parsers(child))
    return out


def _negative_values(parser: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """``--step -1e-3`` as ``--step=-1e-3``: argparse takes a token that starts with ``-`` and is
    not a plain decimal for an option, so a negative value in exponent form would print a
    usage block instead of reaching the value check that names it."""
    takes_value = {option for p in parsers(parser) for action in p._actions  # noqa: SLF001
                   if action.option_strings and action.nargs is None for option in action.option_strings}
    out: list[str] = []
    args = list(argv)
    i = 0
    while i < len(args):
        token = args[i]
        if token in takes_value and i + 1 < len(args) and args[i + 1].startswith("-") and _is_number(args[i + 1]):
            out.append(f"{token}={args[i + 1]}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


def _unknown_option(parser: argparse.ArgumentParser, argv: Sequence[str], unknown: Sequence[str]) -> None:
    """Exit 2 naming the first unknown argument, with the closest option of the sub-command it was
    given to (``--stop-tim``: did you mean '--stop-time'?). Options are never abbreviated, so a
    prefix is not taken for the option; it is only suggested."""
    from ipcosim.errors import closest

    words = [a for a in argv if not a.startswith("-")]
    command = parser
    for each in parsers(parser):  # the deepest sub-command named on the line: `rig serve`, not `rig`
        path = each.prog.split()[1:]
        if path and path == words[:len(path)] and len(path) > len(command.prog.split()) - 1:
            command = each
    first = unknown[0]
    if not first.startswith("-"):
        command.error(f"unexpected argument {first!r}")
    given = first.partition("=")[0]
    options = [o for action in command._actions for o in action.option_strings]  # noqa: SLF001
    longer = [o for o in options if o.startswith(given)]  # an abbreviation: the options it abbreviates
    command.error(f"unknown option {given}; {closest(given, longer or options)}")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status.

    SIGINT and SIGTERM stop every command at once, except inside a run's FMU calls, where they
    wait for the master's next check (:mod:`ipcosim.harness.master.signals`): the command's
    clean-up runs (worker processes stopped, temporary folders removed), what it finished stays
    on disk and is named in one line, and the status is ``128 + signal number``. The ``ipcosim``
    command then leaves without the interpreter's teardown: everything was cleaned up on the way
    out, and a library's exit handlers interrupted half-way have been seen to crash it.
    """
    from ipcosim.harness.master import signals

    console = argv is None  # the `ipcosim` command itself, not a call from Python
    argv = sys.argv[1:] if argv is None else argv
    command = command_named(argv)
    if console and command in COLLECT_AFTER_START and gc.isenabled():
        gc.disable()
        _COLLECTOR_PAUSED.append(True)
    # Entered before the parser is built (a command's options may load numpy: a moment in which the default
    # disposition would end the process without a word), left only when the command has ended.
    with signals.deferred(immediate=True):
        try:
            args = _parse(argv, command)
            status = _command(args, console)
        except signals.Interrupted as exc:  # while the parser was built, or while a failure was reported
            return _interrupted(command, exc, console, removed=_abandon_outputs())
    if console and command in LEAVE_AT_ONCE:
        leave(status)
    return status


def leave(status: int) -> None:
    """End the process with ``status`` as the interpreter would, without its teardown: the exit handlers run
    (temporary folders removed), the standard streams are flushed, and the objects, which hold nothing
    unwritten, are not freed one by one (about 35 ms of CPU after a 10 s single-mass run: an eighth of
    its whole process). Returns (to a normal exit) while a thread other than the daemon ones still runs."""
    import atexit
    import os
    import threading

    if any(not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        return
    atexit._run_exitfuncs()  # noqa: SLF001 -- what the interpreter's exit runs first
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader gone away, a stream closed: nothing more to say
            pass
    os._exit(status)


def collector_on() -> None:
    """The start of a command is over: turn the cyclic garbage collector on again where :func:`main` turned it off
    (:data:`COLLECT_AFTER_START`), everything made so far moved out of its reach first (``gc.freeze``: it lives to
    the end, and going through it in the collections of the start cost a 10 s native run about 9 ms of CPU,
    a twentieth of its process). Nothing where main did not turn it off."""
    if _COLLECTOR_PAUSED:
        _COLLECTOR_PAUSED.clear()
        gc.freeze()
        gc.enable()


def command_named(argv: Sequence[str]) -> str:
    """The command ``argv`` names (its first word that is not an option: the top-level options take no
    value), or ``""`` when it names none of :data:`COMMANDS` (``--version``, ``--help``, a misspelt
    command, which the parser then answers)."""
    word = next((a for a in argv if not a.startswith("-")), "")
    return word if word in COMMANDS else ""


def _parse(argv: Sequence[str], command: str) -> argparse.Namespace:
    """The command line's arguments (exits 2 with one line on an unknown option, as argparse does),
    with only ``command``'s options built (:func:`build_parser`)."""
    from ipcosim.harness.support.threads import single_threaded

    single_threaded()  # before a command's options load numpy
    before = argv[:list(argv).index(command)] if command else argv  # the top-level options
    parser = build_parser(command, listed=not command or any(a in ("-h", "--help") for a in before))
    argv = _negative_values(parser, argv)
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        _unknown_option(parser, argv, unknown)
    return args


def _command(args: argparse.Namespace, console: bool) -> int:
    """Run the parsed command inside :func:`main`'s signal handling; returns the exit status."""
    from ipcosim.harness.master import signals

    try:
        limit = getattr(args, "timeout", None)
        if limit is not None:
            from ipcosim.harness.api.options import seconds_option

            signals.start_limit(seconds_option("--timeout", limit))
        try:
            status = int(args.func(args) or 0)
            signals.check()  # a signal during the last writes: report it after them
            if status:
                _abandon_outputs()
            return status
        except signals.Interrupted as exc:
            return _interrupted(args.command, exc, console, removed=_abandon_outputs())
    except signals.Interrupted as exc:  # a signal during the report of the first one
        return _interrupted(args.command, exc, console, removed=_abandon_outputs())
    except KeyboardInterrupt:
        _abandon_outputs()
        print("ipcosim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`ipcosim list | head`): nothing to report
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # noqa: BLE001 -- the CLI's one-line error contract
        behind = _interruption_behind(exc)
        if behind is not None:  # a library turned the signal into an error of its own
            return _interrupted(args.command, behind, console, removed=_abandon_outputs())
        _abandon_outputs()
        if args.debug:
            raise
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"ipcosim {args.command}: error: {message}", file=sys.stderr)
        return EXIT_USAGE if isinstance(exc, UsageError) else EXIT_FAILURE


def _interruption_behind(exc: BaseException) -> BaseException | None:
    """The signal's :class:`~ipcosim.harness.master.signals.Interrupted` that ``exc`` was raised
    from or while handling (its cause or context, at any depth), or None."""
    from ipcosim.harness.master.signals import Interrupted

    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, Interrupted):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return None


def _abandon_outputs() -> list[Path]:
    """A command that failed or was stopped before writing anything leaves no folder of its own behind
    (``ipcosim.harness.master.results.abandon_outputs``). Returns the folders removed."""
    from ipcosim.harness.master.results import abandon_outputs

    try:
        return abandon_outputs()
    except OSError:
        return []


def _interrupted(command: str, exc: BaseException, console: bool = False, removed: Sequence[Path] = ()) -> int:
    """Report a command stopped by a signal (or its wall-clock limit) in one line: the signal and
    what was kept (nothing, when what the command meant to keep names a folder in ``removed``, given up
    empty); the exit status (``128 + signal number``). With ``console`` (the ``ipcosim`` command itself)
    the process leaves at once with that status (``signals.exit_now``)."""
    import os

    from ipcosim.harness.master import signals

    partial = getattr(exc, "result", None)
    text = partial.error if partial is not None and partial.error else getattr(exc, "message", "interrupted")
    kept = signals.kept()
    if kept and any(str(d) in kept or os.path.relpath(d) in kept for d in removed):
        kept = "nothing was written"
    if kept is None and partial is None:
        kept = "nothing was written"
    print(f"ipcosim{' ' + command if command else ''}: error: {text}" + (f"; {kept}" if kept else ""),
          file=sys.stderr)
    status = int(getattr(exc, "exit_status", 130))
    if console:
        sys.stdout.flush()
        sys.stderr.flush()
        signals.exit_now(status)
    return status


if __name__ == "__main__":
    sys.exit(main())
