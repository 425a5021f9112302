"""The host's arrangements for a paced loop: the collector kept out of it, CPU affinity, SCHED_FIFO, the fair
scheduler's slice and the timer slack, each asked for by an environment variable (``IPCOSIM_RT_*``, documented in
:mod:`ipcosim.harness.master.realtime`) and undone when the run ends. :func:`realtime_setup` applies them all and
reports what was applied; the rig's server applies some of them itself (``ipcosim rig serve``).
"""
from __future__ import annotations

import gc
import os
import sys
from typing import Any, Callable

from ipcosim.errors import IpcosimError


def env_number(name: str, kind: type, lo: float, hi: float) -> Any:
    """An optional numeric environment variable in [lo, hi] (None if unset)."""
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not (lo <= value <= hi):   # NaN fails too
        raise RealtimeSetupError(f"{name}={text}: expected a number in [{lo:g}, {hi:g}]")
    return value


class RealtimeSetupError(IpcosimError, ValueError):
    """A real-time option (environment variable) with a bad value."""


def realtime_setup() -> tuple[dict[str, str], Callable[[], None]]:
    """Arrange the process for pacing: GC out of the loop, CPU affinity and SCHED_FIFO if asked for.

    Returns
    -------
    report : dict
        ``{"gc": ..., "cpu_affinity": ..., "sched_fifo": ..., "timer_slack": ...}``, each ``applied ...`` or
        ``not applied: why`` (``not requested`` when the option is not set).
    undo : callable
        Restores what was changed (called when the run ends).
    """
    cpu = env_number("IPCOSIM_RT_CPU", int, 0, 4095)
    priority = env_number("IPCOSIM_RT_PRIORITY", int, 1, 99)
    slice_us = slice_request()
    undo: list[Callable[[], None]] = []
    report: dict[str, str] = {}
    # A full collection of a process holding numpy, fmpy and the FMUs takes milliseconds: collect
    # once now, freeze what exists (never scanned again) and keep the collector off while paced.
    gc.collect()
    gc.freeze()
    if gc.isenabled():
        gc.disable()
        undo.append(gc.enable)
    undo.append(gc.unfreeze)
    report["gc"] = "applied: collected and frozen before the loop, disabled during it"
    report["cpu_affinity"] = apply_cpu_affinity(cpu, undo)
    report["sched_fifo"] = apply_sched_fifo(priority, undo)
    report["sched_slice"] = apply_sched_slice(slice_us, undo)
    report["timer_slack"] = apply_timer_slack(TIMER_SLACK_NS, undo)

    def restore() -> None:
        for fn in reversed(undo):
            try:
                fn()
            except OSError:
                pass
    return report, restore


def apply_cpu_affinity(cpu: int | None, undo: list[Callable[[], None]]) -> str:
    """Pin this process to CPU ``cpu`` (None: not requested); appends the undo to ``undo``; returns the outcome."""
    if cpu is None:
        return "not requested (IPCOSIM_RT_CPU)"
    if not hasattr(os, "sched_setaffinity"):
        return "not applied: the OS has no CPU affinity call"
    try:
        before = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {cpu})
    except OSError as exc:
        return f"not applied: CPU {cpu}: {exc.strerror or exc}"
    undo.append(lambda: os.sched_setaffinity(0, before))
    return f"applied: CPU {cpu}"


def apply_sched_fifo(priority: int | None, undo: list[Callable[[], None]]) -> str:
    """SCHED_FIFO at ``priority`` (None: not requested); appends the undo to ``undo``; returns the outcome."""
    if priority is None:
        return "not requested (IPCOSIM_RT_PRIORITY)"
    if not hasattr(os, "sched_setscheduler"):
        return "not applied: the OS has no SCHED_FIFO"
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return f"not applied: SCHED_FIFO priority {priority}: {exc.strerror or exc} (needs CAP_SYS_NICE or rtprio)"
    undo.append(lambda: os.sched_setscheduler(0, policy, param))
    return f"applied: SCHED_FIFO priority {priority}"


#: The time slice a paced loop asks the fair scheduler for [us] (IPCOSIM_RT_SLICE_US).
DEFAULT_SLICE_US = 700
#: sched_setattr / sched_getattr by machine (Linux; Python's os module has neither).
_SCHED_ATTR_CALLS = {"x86_64": (314, 315), "aarch64": (274, 275), "riscv64": (274, 275)}
_SCHED_ATTR = "IIQiIQQQII"      # struct sched_attr (56 bytes): size, policy, flags, nice, priority, runtime, ...


def _sched_attr_calls() -> tuple[int, int] | None:
    import platform

    return _SCHED_ATTR_CALLS.get(platform.machine()) if sys.platform.startswith("linux") else None


def _sched_runtime(set_ns: int | None = None) -> int:
    """This thread's fair-scheduler slice request [ns] (0: the default), after setting it to ``set_ns``."""
    import ctypes
    import struct

    calls = _sched_attr_calls()
    assert calls is not None
    syscall = ctypes.CDLL(None, use_errno=True).syscall
    buf = ctypes.create_string_buffer(struct.calcsize(_SCHED_ATTR))
    if syscall(calls[1], 0, buf, len(buf), 0) != 0:
        raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()))
    attr = list(struct.unpack(_SCHED_ATTR, buf.raw))
    if set_ns is not None:
        attr[0], attr[5] = len(buf), set_ns        # the policy, nice and priority stay as they are
        new = ctypes.create_string_buffer(struct.pack(_SCHED_ATTR, *attr), len(buf))
        if syscall(calls[0], 0, new, 0) != 0:
            raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()))
    return attr[5]


def slice_request() -> int | None:
    """``IPCOSIM_RT_SLICE_US`` [us] (None when unset)."""
    return env_number("IPCOSIM_RT_SLICE_US", int, 0, 100_000)


def apply_sched_slice(slice_us: int | None, undo: list[Callable[[], None]]) -> str:
    """Ask the fair scheduler for a ``slice_us`` time slice (None: :data:`DEFAULT_SLICE_US`, 0: leave it);
    only under the default policy (a real-time policy has no slice); appends the undo; returns the outcome."""
    slice_us = DEFAULT_SLICE_US if slice_us is None else slice_us
    if slice_us == 0:
        return "not requested (IPCOSIM_RT_SLICE_US=0)"
    if _sched_attr_calls() is None:
        return "not applied: Linux on x86_64, aarch64 or riscv64 only"
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            return "not applied: the loop runs under a real-time policy"
        _sched_runtime(slice_us * 1000)
    except OSError as exc:
        return f"not applied: sched_setattr: {exc.strerror or exc} (Linux 6.12 or later takes a slice)"
    undo.append(lambda: _sched_runtime(0))     # 0: the scheduler's own slice again
    return f"applied: {slice_us} us"


#: The timer slack of a paced process under the default policy [ns] (Linux's default is 50 us; a
#: real-time policy has none).
TIMER_SLACK_NS = 1_000
_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30


def apply_timer_slack(slack_ns: int, undo: list[Callable[[], None]]) -> str:
    """Linux's timer slack of this thread cut to ``slack_ns`` (a sleep may end that much after its
    deadline, 50 us by default); appends the undo to ``undo``; returns the outcome."""
    if not sys.platform.startswith("linux"):
        return "not applied: Linux only"
    import ctypes
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
        before = prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
        if before < 0 or prctl(_PR_SET_TIMERSLACK, slack_ns, 0, 0, 0) != 0:
            return f"not applied: prctl: {os.strerror(ctypes.get_errno())}"
    except (OSError, AttributeError) as exc:
        return f"not applied: {exc}"
    undo.append(lambda: prctl(_PR_SET_TIMERSLACK, before, 0, 0, 0))
    return f"applied: {slack_ns} ns (was {before} ns)"
