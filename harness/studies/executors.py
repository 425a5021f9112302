"""Where a sweep's runs execute: :class:`LocalExecutor` (a pool of worker processes on this
machine, one per core by default) and :class:`DaskExecutor` (a ``dask.distributed`` cluster
reached at ``tcp://HOST:PORT``; start one with ``dask scheduler`` and ``dask worker ADDR
--nthreads 1``), and what one run is in a worker (:func:`execute_case`: the spec's runner built
once per worker, a failure of the run recorded as its row, never raised).

A worker process that dies is replaced, the runs it was carrying are re-run one at a time, and
a run that kills its worker even alone is recorded as ``error``.
"""
from __future__ import annotations

import atexit
import concurrent.futures as cf
import itertools
import multiprocessing
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any, Iterable, Iterator

from ipcosim.errors import IpcosimError, UsageError
from ipcosim.harness.master import signals
from ipcosim.harness.studies.cases import SweepCase
from ipcosim.harness.studies.runners import Runner, RunSpec
from ipcosim.harness.support.threads import single_threaded

#: Dask retries of a run whose worker died (the local pool re-runs such runs alone instead).
MAX_WORKER_DEATHS = 2


class SchedulerError(IpcosimError, ConnectionError):
    """The Dask scheduler cannot be reached or has no workers."""


_local = threading.local()


_CACHE_SIZE = 4


def _runner_for(spec: RunSpec) -> Runner:
    """The worker's runner for ``spec``: built on first use, then reused (per thread: FMU
    instances are not shared between threads)."""
    cache: OrderedDict[str, Runner] | None = getattr(_local, "runners", None)
    if cache is None:
        cache = _local.runners = OrderedDict()
    key = spec.key
    runner = cache.get(key)
    if runner is None:
        runner = spec.build()
        cache[key] = runner
        while len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return runner


def one_line(exc: BaseException) -> str:
    """An exception as one line: ``Type: first line of message``."""
    text = str(exc).strip()
    first = text.splitlines()[0] if text else ""
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


def execute_case(spec: RunSpec, case: SweepCase) -> dict[str, Any]:
    """Run one case and return its row (never raises for a failure of the run itself).

    Parameters
    ----------
    spec : RunSpec
        What a run is; its runner is built once per worker thread and cached.
    case : SweepCase
        Parameter values and seed.

    Returns
    -------
    dict
        ``index``, ``seed``, ``status``, ``success``, ``error``, ``params`` (dict),
        ``metrics`` (dict) and ``run_time_s``.
    """
    t0 = time.perf_counter()
    metrics: dict[str, Any] = {}
    error = ""
    try:
        runner = _runner_for(spec)
        metrics = dict(runner(dict(case.params), case.seed))
        error = " ".join(str(metrics.pop("error", "") or "").split())  # a run cut short but judged
        status = spec.classify(metrics, case.params)
    except Exception as exc:  # noqa: BLE001 -- a failed run is a result, not a crash
        status, error = "error", one_line(exc)
    return {"index": case.index, "seed": case.seed, "status": status, "success": status == "ok",
            "error": error, "params": dict(case.params), "metrics": metrics,
            "run_time_s": time.perf_counter() - t0}


def _error_row(case: SweepCase, message: str) -> dict[str, Any]:
    return {"index": case.index, "seed": case.seed, "status": "error", "success": False, "error": message,
            "params": dict(case.params), "metrics": {}, "run_time_s": None}


def _tracked_execute(spec: RunSpec, case: SweepCase, track_dir: str) -> dict[str, Any]:
    """``execute_case`` leaving a note of the running case in ``track_dir`` while it runs, so
    that the parent can tell which runs were in flight when a worker process died."""
    note = os.path.join(track_dir, str(os.getpid()))
    with open(note, "w") as fh:
        fh.write(str(case.index))
    row = execute_case(spec, case)
    os.unlink(note)
    return row


def _read_tracks(track_dir: Path) -> list[int]:
    """Indices of the runs noted in flight (and clear the notes)."""
    indices = []
    for note in track_dir.iterdir():
        try:
            indices.append(int(note.read_text()))
        except (OSError, ValueError):
            pass
        note.unlink(missing_ok=True)
    return sorted(indices)


def _quick_exit() -> None:
    """Leave a worker process without the interpreter's teardown (registered first, so it runs
    after every other exit handler, e.g. the runners' FMU release). A worker has nothing left
    to tear down once its results are sent, and unloading FMUs during the teardown has been
    seen to abort ("corrupted double-linked list") after many runs in one process."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(0)


#: Runs per worker, on average, before the local pool is replaced (bounded memory; measured
#: a worker that runs this many co-simulations grows by less than 5 MB).
RECYCLE_RUNS = 50


def _worker_init() -> None:
    # The parent handles Ctrl-C (it stops the pool); workers must not die half-way on it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # The parent stops its workers with SIGTERM: leave at once, without the run's temporary folders.
    signal.signal(signal.SIGTERM, _terminated)
    atexit.register(_quick_exit)


def _terminated(signum: int, frame: object) -> None:
    signals.exit_now(128 + signum)


class LocalExecutor:
    """A pool of worker processes on this machine.

    Each instantiation of a pythonfmu FMU leaves memory behind in its process (pythonfmu
    0.7.0 re-imports the FMU script and keeps the new class; see ``docs/studies.md``), so the
    pool is replaced after ``workers * recycle_runs`` runs: no worker process runs more than
    that many, and its resident memory stays bounded whatever the length of the sweep.

    Parameters
    ----------
    workers : int, optional
        Number of processes (default: the number of CPU cores).
    recycle_runs : int
        Runs per worker (on average) before the pool is replaced by fresh processes.
    """

    def __init__(self, workers: int | None = None, recycle_runs: int = RECYCLE_RUNS) -> None:
        if workers is not None and workers < 1:
            raise UsageError(f"--workers {workers}: need at least one worker")
        self.workers = int(workers or os.cpu_count() or 1)
        self.recycle_runs = int(recycle_runs)
        self._used = 0  # runs submitted to the current pool
        self._ctx = multiprocessing.get_context("spawn")
        # One BLAS/OpenMP thread per worker process, as Dask's nanny does: a run's small matrix
        # products gain nothing from threads, and W workers x C BLAS threads on C cores
        # oversubscribe the machine (measured: 2-worker scaling 1.4x instead of 1.85x). The
        # variables must be in the environment the workers are spawned with (this process has
        # loaded its BLAS already and is not affected); values the user set are kept.
        single_threaded()
        self._pool: cf.ProcessPoolExecutor | None = None

    @property
    def description(self) -> str:
        return f"local process pool, {self.workers} worker{'s' if self.workers != 1 else ''}"

    def _ensure_pool(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            self._pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=self._ctx,
                                                initializer=_worker_init)
        return self._pool

    def run(self, spec: RunSpec, cases: Iterable[SweepCase]) -> Iterator[dict[str, Any]]:
        """Yield the row of every case, in completion order.

        The cases are taken from ``cases`` as the pool needs them, at most one pool's share
        (``workers * recycle_runs``) ahead, so a stream of cases is never held whole.

        When a worker process dies (an FMU that crashes the process), the pool is replaced and
        the runs that were in flight are re-run one at a time; a run that kills its worker when
        it runs alone is recorded as an error, the others go on normally.
        """
        source = iter(cases)
        pending: dict[int, SweepCase] = {}

        def take(n: int) -> None:  # at least n cases pending, while the source lasts
            for case in itertools.islice(source, max(0, n - len(pending))):
                pending[case.index] = case

        suspects: list[int] = []
        track = Path(tempfile.mkdtemp(prefix="ipcosim-sweep-"))
        try:
            take(1)
            while pending:
                if suspects:
                    index = suspects.pop(0)
                    if index not in pending:
                        continue
                    batch = [pending[index]]
                else:
                    size = max(1, self.workers * self.recycle_runs - self._used)
                    take(size)
                    batch = list(itertools.islice(pending.values(), size))
                pool = self._ensure_pool()
                self._used += len(batch)
                # Submitting spawns the pool's workers: a signal half-way through a spawn would leave a worker
                # the pool does not know, blocked on its start-up pipe for ever; it is taken once they all are.
                with signals.holding():
                    futures = {pool.submit(_tracked_execute, spec, c, str(track)): c for c in batch}
                signals.check()
                broken = False
                try:
                    for fut in cf.as_completed(futures):
                        case = futures[fut]
                        try:
                            row = fut.result()
                        except cf.process.BrokenProcessPool:
                            broken = True
                            continue
                        except Exception as exc:  # noqa: BLE001 -- e.g. the spec cannot be pickled
                            row = _error_row(case, one_line(exc))
                        pending.pop(case.index, None)
                        yield row
                    take(1)
                except GeneratorExit:  # the caller has the rows it wanted: the pool stays for its next runs
                    for fut in futures:
                        fut.cancel()
                    raise
                except BaseException:  # a signal, an error of the caller: stop the workers now
                    self.abort()
                    raise
                if not broken and self._used >= self.workers * self.recycle_runs:
                    self.close()  # fresh worker processes for the next runs
                if broken:
                    self._kill_pool()
                    in_flight = _read_tracks(track)
                    if len(batch) == 1:  # it ran alone and took its worker down: its own fault
                        case = batch[0]
                        pending.pop(case.index, None)
                        yield _error_row(case, "worker process died during the run (crashed twice, "
                                               "once when run alone)")
                        take(1)
                    else:
                        suspects = [i for i in in_flight if i in pending]
        finally:
            shutil.rmtree(track, ignore_errors=True)

    def _kill_pool(self) -> None:
        pool, self._pool = self._pool, None
        self._used = 0
        if pool is None:
            return
        processes = list((getattr(pool, "_processes", None) or {}).values())
        for p in processes:
            try:
                p.terminate()
            except Exception:  # noqa: BLE001
                pass
        for p in processes:  # a worker inside a long native call: kill it after a moment
            p.join(timeout=0.5)
            if p.is_alive():
                p.kill()
                p.join(timeout=1.0)
        pool.shutdown(wait=True)  # its futures fail as broken: cancelling them races the pool's own thread
        from ipcosim.harness.api.engine import remove_stale_extractions

        remove_stale_extractions()  # the FMU folders of workers killed before their clean-up

    def abort(self) -> None:
        """Stop at once: cancel queued runs and end the worker processes."""
        self._kill_pool()
        _stop_resource_tracker()

    def close(self) -> None:
        """Shut the pool down (waits for nothing: every submitted run has finished)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        self._used = 0
        _stop_resource_tracker()


def _stop_resource_tracker() -> None:
    """End (and wait for) the helper process multiprocessing starts beside a pool, which would
    otherwise outlive this process by a moment, unwaited for; it is started again if needed. Left
    running while another pool's workers live: they hold its pipe, so waiting for it would never end."""
    import gc
    import multiprocessing
    from multiprocessing import resource_tracker

    if multiprocessing.active_children():
        return
    gc.collect()  # the pool's semaphores released and unregistered first: no "leaked semaphore" warning
    tracker = resource_tracker._resource_tracker  # noqa: SLF001 -- no public way
    with tracker._lock:  # noqa: SLF001
        fd, pid = getattr(tracker, "_fd", None), getattr(tracker, "_pid", None)
        if fd is None or pid is None:
            return
        os.close(fd)  # closing its "alive" pipe ends the tracker, once no other process holds the pipe
        tracker._fd = tracker._pid = None  # noqa: SLF001 -- started again if needed
    _reap(pid, TRACKER_WAIT_S)


#: Seconds the resource tracker is waited for once its pipe is closed: it ends at once, unless a process
#: this one does not know of (a worker whose start a signal cut short) holds the pipe; it is then left to
#: end with that process, instead of waiting for it for ever as multiprocessing's own stop would.
TRACKER_WAIT_S = 2.0


def _reap(pid: int, wait_s: float) -> bool:
    """Wait up to ``wait_s`` for the child ``pid`` to end (and collect it); False if it is still running."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            if os.waitpid(pid, os.WNOHANG)[0]:
                return True
        except ChildProcessError:  # already collected
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)


_ADDRESS = re.compile(r"^(tcp|tls|ws|wss|ucx|inproc)://\S+$")


class DaskExecutor:
    """Runs on a ``dask.distributed`` cluster.

    Parameters
    ----------
    scheduler : str or distributed.Client
        Scheduler address ``tcp://HOST:PORT`` (or an existing client, not closed by ``close``).
    timeout : float
        Seconds to wait for the scheduler (and for at least one worker).
    """

    def __init__(self, scheduler: Any, timeout: float = 5.0) -> None:
        from ipcosim.harness.support.extras import require

        require("distributed")
        from distributed import Client

        self._own = not isinstance(scheduler, Client)
        if self._own:
            address = str(scheduler)
            if not _ADDRESS.match(address):
                raise SchedulerError(f"--scheduler {address!r}: expected an address like tcp://HOST:PORT")
            try:
                self.client = Client(address, timeout=f"{timeout}s", set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise SchedulerError(f"cannot reach the Dask scheduler at {address}: "
                                     f"{one_line(exc).split(': ', 1)[-1]}") from None
        else:
            self.client = scheduler
        self.address = self.client.scheduler.address
        try:
            self.client.wait_for_workers(1, timeout=timeout)
        except (TimeoutError, OSError):
            self.close()
            raise SchedulerError(f"the Dask scheduler at {self.address} has no workers "
                                 f"(waited {timeout:g} s)") from None
        self._futures: list[Any] = []

    @property
    def workers(self) -> int:
        info = self.client.scheduler_info()
        return sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()) or 1

    @property
    def description(self) -> str:
        n = len(self.client.scheduler_info().get("workers", {}))
        return f"dask cluster at {self.address}, {n} worker{'s' if n != 1 else ''}"

    def run(self, spec: RunSpec, cases: Iterable[SweepCase]) -> Iterator[dict[str, Any]]:
        """Yield the row of every case, in completion order (the cases are all submitted at once)."""
        from distributed import as_completed

        cases = list(cases)
        if not cases:
            return
        spec_future = self.client.scatter(spec, broadcast=True, hash=False)
        futures = self.client.map(execute_case, [spec_future] * len(cases), list(cases), pure=False,
                                  retries=MAX_WORKER_DEATHS)
        self._futures = futures
        by_key = {f.key: c for f, c in zip(futures, cases)}
        try:
            for fut in as_completed(futures, loop=self.client.loop):
                case = by_key[fut.key]
                try:
                    row = fut.result()
                except Exception as exc:  # noqa: BLE001 -- worker died, task could not be unpickled...
                    row = _error_row(case, one_line(exc))
                fut.release()
                yield row
        except BaseException:
            self.abort()
            raise
        finally:
            self._futures = []

    def abort(self) -> None:
        """Cancel every queued or running run of this executor."""
        if self._futures:
            try:
                self.client.cancel(self._futures)
            except Exception:  # noqa: BLE001
                pass

    def close(self) -> None:
        """Disconnect (the cluster itself keeps running)."""
        if self._own:
            try:
                self.client.close()
            except Exception:  # noqa: BLE001
                pass


Executor = LocalExecutor | DaskExecutor


def open_executor(workers: int | None = None, scheduler: Any = None) -> Executor:
    """A :class:`DaskExecutor` when ``scheduler`` is given, else a :class:`LocalExecutor`."""
    if scheduler:
        return DaskExecutor(scheduler)
    return LocalExecutor(workers)
