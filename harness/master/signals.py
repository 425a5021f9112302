"""SIGINT and SIGTERM for every command: at once outside FMU calls, deferred to the master inside them.

The command line enters :func:`deferred` with ``immediate=True`` around every command: a
SIGINT or SIGTERM then raises :class:`Interrupted` at once wherever the command is (waiting for a
sweep's workers, fitting, building an FMU), so it unwinds through the command's clean-up (worker
processes stopped, temporary folders removed, finished results kept) within a second. Inside a
run (the master enters :func:`deferred` again, which nests as a *holding* section) the signal is
never delivered into an FMU: it is only recorded. The master
calls :func:`check` between FMU calls (between chunks of steps, between the components'
instantiation, initialization and clean-up calls); :func:`check` raises :class:`Interrupted`
there, so the execution ends the way a failure does: results so far on disk, every FMU
terminated and freed, temporary folders removed. The command line then exits with
``128 + signal number``; what a command kept is said by the line it registers with :func:`keep`.
An FMU's own code (a Python FMU runs in the same interpreter) never
sees an exception it did not raise.

A second signal while the first is being handled forces the exit at once (status
``128 + signal number``): the temporary folders registered with :func:`register_temp` are
removed, and a results chunk being written is completed first (:func:`critical`), so what is
on disk stays well-formed.

A wall-clock limit (:func:`deferred` with ``timeout``) works the same way: at the limit the
run is stopped at the next check, and if it does not get there within ``grace`` seconds (an
FMU that hangs) the process exits with status :data:`TIMEOUT_STATUS` after the same
forced clean-up.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import threading
from typing import Iterator

#: Exit status of a run stopped by its wall-clock limit (the one ``timeout(1)`` uses).
TIMEOUT_STATUS = 124
HANDLED = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A run stopped by a signal or its wall-clock limit, raised by :func:`check` in the master."""

    def __init__(self, signum: int, message: str | None = None) -> None:
        self.signum = signum
        self.message = message or f"interrupted by {signal.Signals(signum).name}"
        super().__init__(self.message)

    @property
    def exit_status(self) -> int:
        return TIMEOUT_STATUS if self.signum == signal.SIGALRM else 128 + self.signum


class _State:
    active = False
    immediate = False  # raise at the signal outside holding sections (the command line)
    holding = 0  # nesting depth of holding sections (a run's FMU calls)
    kept: str | None = None
    pending: int | None = None
    critical = 0
    exit_after_critical: int | None = None
    temp_dirs: list[str] = []
    lock = threading.Lock()


def register_temp(path: str | os.PathLike[str]) -> None:
    """Remove ``path`` also on a forced exit."""
    _State.temp_dirs.append(os.fspath(path))


def unregister_temp(path: str | os.PathLike[str]) -> None:
    with contextlib.suppress(ValueError):
        _State.temp_dirs.remove(os.fspath(path))


def keep(text: str | None) -> None:
    """Say what an interrupted command has kept (``"finished runs in DIR/results.csv"``);
    the command line prints it after the signal's name. None: nothing kept."""
    _State.kept = text


def kept() -> str | None:
    """What the running command said it keeps when interrupted (:func:`keep`), or None."""
    return _State.kept


def pending() -> int | None:
    """The signal received and not yet acted on, or None."""
    return _State.pending


def check() -> None:
    """Raise :class:`Interrupted` if a signal (or the wall-clock limit) is pending."""
    signum = _State.pending
    if signum is not None:
        if signum == signal.SIGALRM:
            raise Interrupted(signum, "stopped: wall-clock limit (--timeout) reached")
        raise Interrupted(signum)


@contextlib.contextmanager
def critical() -> Iterator[None]:
    """A section a forced exit waits for (writing one chunk of results)."""
    _State.critical += 1
    try:
        yield
    finally:
        _State.critical -= 1
        if _State.critical == 0 and _State.exit_after_critical is not None:
            _force_exit(_State.exit_after_critical)


def _force_exit(status: int, message: str = "second signal: exiting without finishing the clean-up") -> None:
    for path in list(_State.temp_dirs):
        shutil.rmtree(path, ignore_errors=True)
    try:
        sys.stderr.write(f"ipcosim: {message}\n")
        sys.stderr.flush()
    finally:
        os._exit(status)


def exit_now(status: int) -> None:
    """Leave the process at once with ``status``, removing the registered temporary folders
    (a sweep's worker process stopped by its parent)."""
    for path in list(_State.temp_dirs):
        shutil.rmtree(path, ignore_errors=True)
    os._exit(status)


def _handler(signum: int, frame: object) -> None:
    if _State.pending is None:
        _State.pending = signum
        if _State.immediate and not _State.holding:
            raise Interrupted(signum)
        return
    status = 128 + signum
    if _State.critical:
        _State.exit_after_critical = status
    else:
        _force_exit(status)


def _watchdog(timeout: float, grace: float, done: threading.Event) -> None:
    if done.wait(timeout):
        return
    if _State.pending is None:
        _State.pending = signal.SIGALRM
    if done.wait(grace):
        return
    # the master did not get back from an FMU call: leave now
    _force_exit(TIMEOUT_STATUS, f"error: wall-clock limit of {timeout:g} s reached and an FMU call did not return "
                                f"within {grace:g} s; results up to the last written chunk are on disk")


@contextlib.contextmanager
def holding() -> Iterator[None]:
    """A section (a run's FMU calls) where a signal is only recorded, for :func:`check` (the
    master's, or the command line's after the command). Outside :func:`deferred` (and off the
    main thread) a no-op."""
    if not _State.active or threading.current_thread() is not threading.main_thread():
        yield
        return
    _State.holding += 1
    try:
        yield
    finally:
        _State.holding -= 1


@contextlib.contextmanager
def deferred(timeout: float | None = None, grace: float = 2.0, immediate: bool = False) -> Iterator[None]:
    """Defer SIGINT and SIGTERM to :func:`check` (main thread only; elsewhere a no-op).

    Nested in an active block (a run inside a command), the block is a holding section: the
    signal is recorded, never raised inside it.

    Parameters
    ----------
    timeout : float, optional
        Wall-clock limit [s] for the block: then :func:`check` raises :class:`Interrupted`
        with ``signum == SIGALRM``.
    grace : float
        Seconds the master has to reach a check after the limit before the process exits.
    immediate : bool
        Raise :class:`Interrupted` at the signal itself, except inside nested (holding)
        blocks: what the command line does, so that every command stops at once.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _State.active:
        with holding():
            yield
        return
    previous = {s: signal.getsignal(s) for s in HANDLED}
    _State.active, _State.pending, _State.exit_after_critical = True, None, None
    _State.immediate, _State.holding, _State.kept = immediate, 0, None
    done = threading.Event()
    for s in HANDLED:
        signal.signal(s, _handler)
    if timeout is not None:
        threading.Thread(target=_watchdog, args=(timeout, grace, done), daemon=True, name="ipcosim-timeout").start()
    try:
        yield
    finally:
        done.set()
        for s, h in previous.items():
            signal.signal(s, h)
        _State.active = _State.immediate = False
        _State.pending = None
