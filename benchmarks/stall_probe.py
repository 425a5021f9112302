"""Host stalls seen by a process with no work: the anchor of the HIL bench's real-time figures.

``python -m benchmarks.stall_probe OUT.json [CPU ...]`` starts one probe per CPU (default: every CPU
the process may run on), each pinned to its CPU under ``SCHED_FIFO`` at priority :data:`PRIORITY`,
above the master's and the rig's real-time priority, so that nothing of the project can delay it.
Each probe sleeps to deadlines :data:`PERIOD_S` apart and records every wake-up more than
:data:`STALL_S` late as a stall ``[deadline, wake-up]``: a time in which that CPU did not run a
ready real-time task, because the host (the hypervisor, another tenant, the kernel) had it. On
SIGTERM the probes stop and OUT.json gets ``{"cpus": {cpu: [[start_ns, end_ns], ...]}, "fifo": bool,
"seconds": float}`` on the monotonic clock every process of the machine shares.

A probe costs one wake-up per millisecond (a few percent of a CPU). Without ``SCHED_FIFO`` (no
CAP_SYS_NICE) a probe would be delayed by the project's own real-time loop, and ``fifo`` is false:
the bench then attributes nothing to the host.
"""
from __future__ import annotations

import json
import multiprocessing as mp
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

#: Above the bench's real-time priority (50): the probes preempt the loop they watch.
PRIORITY = 90
PERIOD_S = 1e-3
#: A wake-up later than this counts as a stall (the kernel's own wake-up latency is 50-100 us here).
STALL_S = 300e-6
NS = 1_000_000_000


def _probe(cpu: int, queue: mp.Queue, stop: mp.Event, ready: mp.Semaphore) -> None:
    fifo = True
    try:
        os.sched_setaffinity(0, {cpu})
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except (OSError, AttributeError):
        fifo = False
    period, stall = int(PERIOD_S * NS), int(STALL_S * NS)
    stalls: list[list[int]] = []
    start = deadline = time.monotonic_ns()
    ready.release()
    while not stop.is_set():
        deadline += period
        now = time.monotonic_ns()
        if deadline > now:
            time.sleep((deadline - now) / NS)
            now = time.monotonic_ns()
        if now - deadline > stall:
            stalls.append([deadline, now])
        if now - deadline > period:     # a long stall: the next deadline is the next one still ahead
            deadline = now
    queue.put((cpu, fifo, stalls, (time.monotonic_ns() - start) / NS))


class StallProbe:
    """Context manager: probes on ``cpus`` while the block runs; :attr:`result` afterwards."""

    def __init__(self, cpus: list[int] | None = None) -> None:
        self.cpus = sorted(os.sched_getaffinity(0)) if cpus is None else cpus
        self.result: dict = {}

    def __enter__(self) -> "StallProbe":
        ctx = mp.get_context("spawn")
        self._queue, self._stop, ready = ctx.Queue(), ctx.Event(), ctx.Semaphore(0)
        self._procs = [ctx.Process(target=_probe, args=(c, self._queue, self._stop, ready), daemon=True)
                       for c in self.cpus]
        for p in self._procs:
            p.start()
        started, end = 0, time.monotonic() + 60
        while started < len(self._procs):   # every probe at its priority and probing before the block begins
            if ready.acquire(timeout=0.1):
                started += 1
            elif time.monotonic() > end or any(p.exitcode is not None for p in self._procs):
                self._stop.set()
                codes = [p.exitcode for p in self._procs]
                raise RuntimeError(f"the host-stall probe did not start (exit codes {codes}; within 60 s)")
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        got = [self._queue.get(timeout=30) for _ in self._procs]
        for p in self._procs:
            p.join(timeout=10)
        self.result = {"cpus": {str(c): s for c, _, s, _ in got}, "fifo": all(f for _, f, _, _ in got),
                       "seconds": min(sec for *_, sec in got)}


def attribute(starts_ns: np.ndarray, lateness_ns: np.ndarray, period_ns: int, stalls: dict) -> dict:
    """Split a paced run's overruns into the host's and the project's own.

    An overrun episode (consecutive steps starting more than half a period late) is the host's when
    the probes saw at least half of its first step's lateness as stall time, on any CPU, while the
    step before it ran: the loop was late because the machine did not run it. Every step of such an
    episode is the host's, including the steps that catch up after the stall; an episode the probes
    cannot explain (a slow step of the loop, a write of results, a pause of the interpreter) is the
    loop's own.

    Parameters
    ----------
    starts_ns, lateness_ns : array of int
        Each step's start and lateness [ns] (``IPCOSIM_RT_TIMELINE``).
    period_ns : int
        The step period [ns].
    stalls : dict
        The probes' result (:class:`StallProbe`).

    Returns
    -------
    dict
        ``steps``, ``overruns``, ``own_overruns``, ``own_episodes``, ``host_overruns``,
        ``host_stall_s`` (stall time of the most stalled CPU while the run ran), ``jitter_p99_own_s``
        (p99 of ``|period - h|`` over the steps outside the host's episodes) and ``behind_step_s`` (median
        time a step takes when the loop runs behind, starting one step right after the other: the
        loop's own cost per step, which decides how fast it catches up).
    """
    late, starts = np.asarray(lateness_ns, dtype=np.int64), np.asarray(starts_ns, dtype=np.int64)
    over = late > period_ns // 2
    spans = sorted((a, b) for v in stalls.get("cpus", {}).values() for a, b in v) if stalls.get("fifo") else []
    lo, hi = np.array([a for a, _ in spans], dtype=np.int64), np.array([b for _, b in spans], dtype=np.int64)

    def stalled(a: int, b: int) -> int:
        return int(np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0, None).sum()) if len(spans) else 0

    host = np.zeros(len(late), dtype=bool)
    own_episodes = 0
    i = 1
    while i < len(late):
        if not over[i]:
            i += 1
            continue
        j = i
        while j < len(late) and over[j]:
            j += 1
        if stalled(int(starts[i - 1]) - period_ns // 5, int(starts[i])) >= 0.5 * late[i]:
            host[i:j] = True
        else:
            own_episodes += 1
        i = j
    period = np.diff(starts)
    jitter = np.abs(period - period_ns)[~host[1:]][1:]
    behind = period[(late[:-1] > period_ns // 10) & (late[1:] > period_ns // 10)]
    run = (int(starts[0]), int(starts[-1])) if len(starts) else (0, 0)
    per_cpu = [sum(max(0, min(run[1], b) - max(run[0], a)) for a, b in v) for v in stalls.get("cpus", {}).values()]
    return {"steps": int(len(late)), "overruns": int(over.sum()), "own_overruns": int((over & ~host).sum()),
            "own_episodes": own_episodes, "host_overruns": int((over & host).sum()),
            "host_stall_s": max(per_cpu, default=0) / NS,
            "jitter_p99_own_s": float(np.percentile(jitter, 99)) / NS if len(jitter) else 0.0,
            "behind_step_s": float(np.median(behind)) / NS if len(behind) else float("nan")}


def main(argv: list[str]) -> int:
    out, cpus = Path(argv[0]), [int(c) for c in argv[1:]] or None
    done = []
    signal.signal(signal.SIGTERM, lambda *_: done.append(1))
    with StallProbe(cpus) as probe:
        while not done:
            time.sleep(0.05)
    out.write_text(json.dumps(probe.result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
