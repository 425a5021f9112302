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

Nor is :class:`Interrupted` raised inside a compiled module's initialization (a command loads
its libraries as it goes): one cut short turns the exception into ``ImportError: initialization
failed`` and has been seen to crash the interpreter at exit. A signal that arrives there is
delivered again as soon as that initialization is over (milliseconds, as a rule). The same holds
for an :class:`Interrupted` that Python could not raise (one met inside a ``__del__`` or a callback
from C code, which Python reports as ignored): the signal is delivered again, so the command still
stops.

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
import time
from importlib.machinery import ExtensionFileLoader
from types import FrameType
from typing import Any, Iterator

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
    redelivering = False  # the next signal is the first one, delivered again (:func:`_deliver_again`)
    previous_hook = staticmethod(sys.unraisablehook)
    done: threading.Event | None = None  # set when the active block ends (stops its wall-clock limit)


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


#: The import system's calls that run a compiled module's initialization: a signal is not raised
#: while one is on the stack.
_EXTENSION_INIT = frozenset({ExtensionFileLoader.create_module.__code__, ExtensionFileLoader.exec_module.__code__})
#: How often the main thread is looked at while a signal waits to be raised [s].
RAISE_POLL_S = 0.01


def _cannot_raise(frame: FrameType | None) -> bool:
    """Whether an exception raised in ``frame`` would not reach the command as itself: it or a
    caller is a compiled module's initialization (:data:`_EXTENSION_INIT`) or Python's report of
    an exception it could not raise (:func:`_unraisable`)."""
    while frame is not None:
        code = frame.f_code
        if code in _EXTENSION_INIT or code is _unraisable.__code__:
            return True
        frame = frame.f_back
    return False


def _deliver_again(signum: int) -> None:
    """Send ``signum`` to the main thread again once it can be raised there (a thread of its own)."""
    main = threading.main_thread().ident
    while _State.active and _State.pending == signum:
        if not _cannot_raise(sys._current_frames().get(main)):
            _State.redelivering = True
            signal.pthread_kill(main, signum)
            return
        time.sleep(RAISE_POLL_S)


def _later(signum: int) -> None:
    threading.Thread(target=_deliver_again, args=(signum,), daemon=True, name="ipcosim-signal").start()


def _handler(signum: int, frame: FrameType | None) -> None:
    if _State.pending is None or (_State.redelivering and _State.pending == signum):
        _State.pending, _State.redelivering = signum, False
        if _State.immediate and not _State.holding:
            if _cannot_raise(frame):
                _later(signum)
                return
            raise Interrupted(signum)
        return
    status = 128 + signum
    if _State.critical:
        _State.exit_after_critical = status
    else:
        _force_exit(status)


def _unraisable(unraisable: Any) -> None:
    """``sys.unraisablehook`` inside :func:`deferred`: a swallowed :class:`Interrupted` is
    delivered again; every other exception goes to the hook that was there before."""
    exc = unraisable.exc_value
    if isinstance(exc, Interrupted) and _State.active and _State.pending == exc.signum:
        _later(exc.signum)
        return
    _State.previous_hook(unraisable)


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


def start_limit(timeout: float, grace: float = 2.0) -> None:
    """Start the wall-clock limit of the active :func:`deferred` block now (as its ``timeout`` does at
    its start): the command line enters the block before it has read ``--timeout``. Outside an active
    block (or off the main thread) a no-op."""
    if not _State.active or _State.done is None or threading.current_thread() is not threading.main_thread():
        return
    threading.Thread(target=_watchdog, args=(timeout, grace, _State.done), daemon=True,
                     name="ipcosim-timeout").start()


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
    _State.active, _State.pending, _State.exit_after_critical, _State.redelivering = True, None, None, False
    _State.immediate, _State.holding, _State.kept = immediate, 0, None
    done = _State.done = threading.Event()
    for s in HANDLED:
        signal.signal(s, _handler)
    _State.previous_hook, sys.unraisablehook = sys.unraisablehook, _unraisable
    if timeout is not None:
        start_limit(timeout, grace)
    try:
        yield
    finally:
        done.set()
        for s, h in previous.items():
            signal.signal(s, h)
        sys.unraisablehook = _State.previous_hook
        _State.active = _State.immediate = False
        _State.pending = None
