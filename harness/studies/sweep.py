"""The sweep engine: many runs of one scenario with different parameter values, in parallel.

A sweep is a :class:`~ipcosim.harness.studies.runners.RunSpec` (what one run is; built once per
worker, so a co-simulation's FMUs are extracted and loaded once per worker, not once per
run) and a list of :class:`~ipcosim.harness.studies.vary.Case` (parameter values + seed).

Executors
    :class:`LocalExecutor` -- a pool of worker processes on this machine (the default, one
    per core); :class:`DaskExecutor` -- a ``dask.distributed`` cluster reached at
    ``tcp://HOST:PORT`` (start one with ``dask scheduler`` and ``dask worker ADDR --nthreads 1``).

Results
    One row per run (index, seed, status, success, error message, parameter values, metrics,
    run time), appended to ``DIR/results.csv`` as soon as the run finishes and flushed, so an
    interrupted sweep keeps every finished run. Running the same sweep into the same folder
    again resumes: finished runs are read back and not redone. When the sweep completes, the
    file is rewritten sorted by run index. ``DIR/metadata.json`` holds the scenario hash,
    variations, seeds, executor and package versions.

Failures
    A run that raises (FMU error, bad parameter value) becomes a row with status ``error``
    and its one-line message; a worker process that dies is replaced, the runs it was carrying
    are re-run one at a time, and a run that kills its worker even alone is recorded as
    ``error``. Nothing a single run does stops the sweep.
"""
from __future__ import annotations

import atexit
import concurrent.futures as cf
import csv
import functools
import io
import json
import math
import multiprocessing
import os
import platform
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence, TextIO

from ipcosim.errors import IpcosimError, UsageError
from ipcosim.harness.studies.runners import STATUSES, Runner, RunSpec, stable_hash
from ipcosim.harness.studies.vary import Case, Vary, VaryError, case_seed, make_cases, parse_all, parse_vary

__all__ = ["Case", "Vary", "VaryError", "RunSpec", "SweepResult", "LocalExecutor", "DaskExecutor",
           "SchedulerError", "SweepMismatchError", "open_executor", "run_sweep", "execute_case",
           "parse_vary", "parse_all", "make_cases", "case_seed", "read_results", "package_versions"]

BASE_COLUMNS = ("index", "seed", "status", "success", "error")
TAIL_COLUMNS = ("run_time_s",)
RESULTS_FILE = "results.csv"
METADATA_FILE = "metadata.json"
#: Thread-count variables of the BLAS/OpenMP libraries, set to 1 for local worker processes.
SINGLE_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: Dask retries of a run whose worker died (the local pool re-runs such runs alone instead).
MAX_WORKER_DEATHS = 2


class SchedulerError(IpcosimError, ConnectionError):
    """The Dask scheduler cannot be reached or has no workers."""


class SweepMismatchError(IpcosimError, ValueError):
    """The output folder holds results of a different sweep."""


# --------------------------------------------------------------------------- one run (in a worker)

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


def execute_case(spec: RunSpec, case: Case) -> dict[str, Any]:
    """Run one case and return its row (never raises for a failure of the run itself).

    Parameters
    ----------
    spec : RunSpec
        What a run is; its runner is built once per worker thread and cached.
    case : Case
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
        status = spec.classify(metrics)
    except Exception as exc:  # noqa: BLE001 -- a failed run is a result, not a crash
        status, error = "error", one_line(exc)
    return {"index": case.index, "seed": case.seed, "status": status, "success": status == "ok",
            "error": error, "params": dict(case.params), "metrics": metrics,
            "run_time_s": time.perf_counter() - t0}


def _error_row(case: Case, message: str) -> dict[str, Any]:
    return {"index": case.index, "seed": case.seed, "status": "error", "success": False, "error": message,
            "params": dict(case.params), "metrics": {}, "run_time_s": None}


# --------------------------------------------------------------------------- executors


def _tracked_execute(spec: RunSpec, case: Case, track_dir: str) -> dict[str, Any]:
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
#: growth per run in ``tests/test_sweep_memory.py``).
RECYCLE_RUNS = 50


def _worker_init() -> None:
    # The parent handles Ctrl-C (it stops the pool); workers must not die half-way on it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    atexit.register(_quick_exit)


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
        for name in SINGLE_THREAD_ENV:
            os.environ.setdefault(name, "1")
        self._pool: cf.ProcessPoolExecutor | None = None

    @property
    def description(self) -> str:
        return f"local process pool, {self.workers} worker{'s' if self.workers != 1 else ''}"

    def _ensure_pool(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            self._pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=self._ctx,
                                                initializer=_worker_init)
        return self._pool

    def run(self, spec: RunSpec, cases: Sequence[Case]) -> Iterator[dict[str, Any]]:
        """Yield the row of every case, in completion order.

        When a worker process dies (an FMU that crashes the process), the pool is replaced and
        the runs that were in flight are re-run one at a time; a run that kills its worker when
        it runs alone is recorded as an error, the others go on normally.
        """
        pending = {c.index: c for c in cases}
        suspects: list[int] = []
        track = Path(tempfile.mkdtemp(prefix="ipcosim-sweep-"))
        try:
            while pending:
                if suspects:
                    index = suspects.pop(0)
                    if index not in pending:
                        continue
                    batch = [pending[index]]
                else:
                    batch = list(pending.values())[:max(1, self.workers * self.recycle_runs - self._used)]
                pool = self._ensure_pool()
                self._used += len(batch)
                futures = {pool.submit(_tracked_execute, spec, c, str(track)): c for c in batch}
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
                except BaseException:
                    for fut in futures:
                        fut.cancel()
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
        pool.shutdown(wait=True, cancel_futures=True)

    def abort(self) -> None:
        """Stop at once: cancel queued runs and end the worker processes."""
        self._kill_pool()

    def close(self) -> None:
        """Shut the pool down (waits for nothing: every submitted run has finished)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        self._used = 0


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
        from ipcosim.harness.extras import require

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

    def run(self, spec: RunSpec, cases: Sequence[Case]) -> Iterator[dict[str, Any]]:
        """Yield the row of every case, in completion order."""
        from distributed import as_completed

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


# --------------------------------------------------------------------------- results file


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return " ".join(value.split())
    return str(value)


def _parse(column: str, text: str) -> Any:
    if column in ("status", "error"):
        return text
    if column in ("index", "seed"):
        return int(text)
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    try:
        return float(text)
    except ValueError:
        return text


def flatten(row: Mapping[str, Any]) -> dict[str, Any]:
    """A result row as one flat dict (parameters and metrics as columns)."""
    flat = {k: row.get(k) for k in BASE_COLUMNS}
    flat.update(row.get("params", {}))
    flat.update(row.get("metrics", {}))
    flat["run_time_s"] = row.get("run_time_s")
    return flat


def read_results(path: str | os.PathLike) -> tuple[list[str], list[dict[str, Any]]]:
    """Read a results CSV: (columns, rows as typed flat dicts). A trailing incomplete line (a
    sweep killed while writing) is ignored."""
    text = Path(path).read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    try:
        columns = next(reader)
    except StopIteration:
        return [], []
    rows = []
    for record in reader:
        if len(record) != len(columns):
            continue
        rows.append({c: _parse(c, v) for c, v in zip(columns, record)})
    return columns, rows


class ResultsWriter:
    """Appends rows to a CSV file, one flushed line per finished run."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path = path
        self.columns = list(columns)
        self._fh: TextIO | None = None

    def open(self, existing: bool) -> None:
        if existing:
            data = self.path.read_bytes()
            if data and not data.endswith(b"\n"):  # drop a half-written last line
                with open(self.path, "r+b") as fh:
                    fh.truncate(data.rfind(b"\n") + 1)
            self._fh = open(self.path, "a", newline="")
        else:
            self._fh = open(self.path, "w", newline="")
            csv.writer(self._fh).writerow(self.columns)
            self._fh.flush()

    def append(self, flat: Mapping[str, Any]) -> None:
        assert self._fh is not None
        csv.writer(self._fh).writerow([_format(flat.get(c)) for c in self.columns])
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def rewrite_sorted(self, rows: Iterable[Mapping[str, Any]]) -> None:
        """Replace the file atomically by the given rows sorted by index."""
        self.close()
        tmp = self.path.with_suffix(".csv.tmp")
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(self.columns)
            for row in sorted(rows, key=lambda r: r["index"]):
                w.writerow([_format(row.get(c)) for c in self.columns])
        os.replace(tmp, self.path)


# --------------------------------------------------------------------------- progress


class Progress:
    """A one-line progress bar on stderr (redrawn in place on a terminal; on a pipe, a line
    every 10 % or 30 s)."""

    def __init__(self, total: int, done: int = 0, stream: TextIO | None = None, enabled: bool = True,
                 label: str = "sweep") -> None:
        self.total, self.done, self.label = total, done, label
        self.stream = stream or sys.stderr
        self.enabled = enabled and total > 0
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.counts = {s: 0 for s in STATUSES}
        self.start = time.monotonic()
        self.new = 0
        self._last_print = 0.0
        self._last_decile = -1

    def update(self, status: str) -> None:
        self.done += 1
        self.new += 1
        self.counts[status] = self.counts.get(status, 0) + 1
        if not self.enabled:
            return
        now = time.monotonic()
        decile = int(10 * self.done / self.total)
        if self.tty:
            if now - self._last_print > 0.1 or self.done == self.total:
                self._draw(end="\r")
                self._last_print = now
        elif decile != self._last_decile or now - self._last_print > 30:
            self._draw(end="\n")
            self._last_print, self._last_decile = now, decile

    def _draw(self, end: str) -> None:
        width = 24
        filled = int(width * self.done / self.total)
        elapsed = time.monotonic() - self.start
        rate = 60.0 * self.new / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / (rate / 60.0) if rate > 0 else math.nan
        eta = f"{int(left // 60)}:{int(left % 60):02d}" if math.isfinite(left) else "--:--"
        counts = " ".join(f"{s} {n}" for s, n in self.counts.items() if n)
        self.stream.write(f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} "
                          f"{counts}  {rate:.1f} runs/min  eta {eta}   {end}")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


# --------------------------------------------------------------------------- the sweep


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages a run's results depend on."""
    return dict(_package_versions())


@functools.lru_cache(maxsize=1)
def _package_versions() -> tuple[tuple[str, str], ...]:
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("ipcosim", "numpy", "scipy", "control", "fmpy", "pythonfmu", "dask", "distributed"):
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return tuple(versions.items())


@dataclass
class SweepResult:
    """The outcome of :func:`run_sweep`.

    Attributes
    ----------
    rows : list of dict
        One flat row per run (``flatten``), sorted by index.
    columns : list of str
        Column order of the results file.
    metadata : dict
        What ``metadata.json`` holds.
    path : Path or None
        The results CSV (None for an in-memory sweep).
    resumed : int
        Runs read back from an earlier, interrupted sweep.
    elapsed_s : float
        Wall time of this call.
    """

    rows: list[dict[str, Any]]
    columns: list[str]
    metadata: dict[str, Any]
    path: Path | None = None
    resumed: int = 0
    elapsed_s: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def success_rate(self) -> float:
        """Fraction of runs with status ``ok``."""
        return sum(1 for r in self.rows if r["status"] == "ok") / len(self.rows) if self.rows else math.nan


def columns_for(spec: RunSpec, cases: Sequence[Case]) -> list[str]:
    """Columns of a sweep's results: base, parameters (in first-seen order), metrics, run time."""
    params: dict[str, None] = {}
    for case in cases:
        for name in case.params:
            params.setdefault(name, None)
    return [*BASE_COLUMNS, *params, *spec.metric_names, *TAIL_COLUMNS]


def plan_hash(spec: RunSpec, cases: Sequence[Case]) -> str:
    """Identity of a sweep: the spec and every case's parameters and seed."""
    return stable_hash({"spec": spec.key,
                        "cases": [[c.index, c.seed, sorted(c.params.items())] for c in cases]})


def run_sweep(spec: RunSpec, cases: Sequence[Case], *, out_dir: str | os.PathLike | None = None,
              executor: Executor | None = None, workers: int | None = None, scheduler: Any = None,
              resume: bool = True, progress: bool | TextIO = False,
              extra_metadata: Mapping[str, Any] | None = None) -> SweepResult:
    """Run every case of a sweep in parallel and collect one row per run.

    Parameters
    ----------
    spec : RunSpec
        What one run is.
    cases : sequence of Case
        The runs (unique indices).
    out_dir : path, optional
        Folder for ``results.csv`` and ``metadata.json``; rows are appended as runs finish.
        Without it the sweep is kept in memory only.
    executor : LocalExecutor or DaskExecutor, optional
        An open executor to use (kept open); otherwise one is opened from ``workers`` /
        ``scheduler`` and closed at the end.
    workers : int, optional
        Local worker processes (default: CPU cores).
    scheduler : str or distributed.Client, optional
        Run on this Dask cluster instead of local processes.
    resume : bool
        Reuse finished runs found in ``out_dir`` (an interrupted earlier run of the same sweep).
        With False, existing results there are replaced.
    progress : bool or stream
        Show a progress bar (on stderr, or the given stream).
    extra_metadata : mapping, optional
        Recorded in ``metadata.json`` (e.g. the command line's variations).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepMismatchError
        ``out_dir`` holds results of another sweep (different scenario, variations or seeds).
    SchedulerError
        The Dask scheduler cannot be reached.
    KeyboardInterrupt
        After stopping the workers; every finished run is in ``out_dir``.
    """
    t_start = time.monotonic()
    indices = [c.index for c in cases]
    if len(set(indices)) != len(indices):
        raise ValueError("sweep cases must have unique indices")
    columns = columns_for(spec, cases)
    meta = _start_metadata(spec, cases, extra_metadata)
    path = Path(out_dir) / RESULTS_FILE if out_dir is not None else None
    done, writer = (_open_results(path, meta, columns, set(indices) if resume else None) if path is not None
                    else ({}, None))
    resumed = len(done)
    _run_missing(spec, cases, done, columns, meta, writer, executor=executor, workers=workers,
                 scheduler=scheduler, progress=progress)

    rows = sorted(done.values(), key=lambda r: r["index"])
    counts = _close_results(rows, meta, time.monotonic() - t_start, writer, path)
    return SweepResult(rows=rows, columns=columns, metadata=meta, path=path, resumed=resumed,
                       elapsed_s=meta["elapsed_s"], counts=counts)


def _close_results(rows: list[dict[str, Any]], meta: dict[str, Any], elapsed: float,
                   writer: ResultsWriter | None, path: Path | None) -> dict[str, int]:
    """Count the rows by status into ``meta`` (with the end time and ``elapsed`` [s]); with a
    results file, rewrite it sorted by case and write the final ``metadata.json``. Returns the counts."""
    counts = {s: 0 for s in STATUSES}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    meta.update({"finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "elapsed_s": elapsed, "counts": counts,
                 "success_rate": counts.get("ok", 0) / len(rows) if rows else None})
    if writer is not None and path is not None:
        writer.rewrite_sorted(rows)
        (path.parent / METADATA_FILE).write_text(json.dumps(meta, indent=2, default=repr) + "\n")
    return counts


def _start_metadata(spec: RunSpec, cases: Sequence[Case], extra: Mapping[str, Any] | None) -> dict[str, Any]:
    """What ``metadata.json`` records at the start: the scenario, the plan's identity, the seeds
    (the first 10 000), package versions, the start time and ``extra``."""
    return {"scenario": spec.name, "scenario_hash": spec.key, "plan_hash": plan_hash(spec, cases),
            "spec": spec.describe(), "runs": len(cases), "seeds": {"cases": [c.seed for c in cases][:10000]},
            "packages": package_versions(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **dict(extra or {})}


def _open_results(path: Path, meta: dict[str, Any], columns: list[str],
                  wanted: set[int] | None) -> tuple[dict[int, dict[str, Any]], ResultsWriter]:
    """Open a sweep's ``results.csv`` for appending and write its ``metadata.json``; with
    ``wanted`` (the case indices; None: start afresh), the rows of those cases an earlier,
    interrupted run of the same sweep finished, by index (recorded as ``resumed_runs``).

    Raises
    ------
    SweepMismatchError
        The folder holds results of another sweep (other plan hash or columns).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    meta_path = path.parent / METADATA_FILE
    done: dict[int, dict[str, Any]] = {}
    existing = wanted is not None and path.exists() and path.stat().st_size > 0
    if existing:
        old_meta: dict[str, Any] = {}
        if meta_path.exists():
            try:
                old_meta = json.loads(meta_path.read_text())
            except json.JSONDecodeError:
                old_meta = {}
        old_columns, old_rows = read_results(path)
        if old_meta.get("plan_hash") != meta["plan_hash"] or old_columns != columns:
            raise SweepMismatchError(
                f"{path} holds results of a different sweep (scenario, settings, --vary, --samples or "
                f"--seed differ); choose another --out or start afresh with --fresh")
        done = {r["index"]: r for r in old_rows if r["index"] in wanted}
        meta["resumed_runs"] = len(done)
    writer = ResultsWriter(path, columns)
    writer.open(existing=existing)
    meta_path.write_text(json.dumps(meta, indent=2, default=repr) + "\n")
    return done, writer


def _run_missing(spec: RunSpec, cases: Sequence[Case], done: dict[int, dict[str, Any]], columns: list[str],
                 meta: dict[str, Any], writer: ResultsWriter | None, *, executor: Executor | None,
                 workers: int | None, scheduler: Any, progress: bool | TextIO) -> None:
    """Run the cases not in ``done`` on ``executor`` (or one opened from ``workers`` /
    ``scheduler`` and closed here, aborted on an exception), adding each finished row to
    ``done`` and appending it to ``writer``, with a progress bar over all ``cases``."""
    todo = [c for c in cases if c.index not in done]
    own_executor = executor is None
    bar = Progress(len(cases), done=len(done), enabled=bool(progress),
                   stream=progress if hasattr(progress, "write") else None)
    for row in done.values():
        bar.counts[row["status"]] = bar.counts.get(row["status"], 0) + 1
    try:
        if todo:
            if executor is None:
                executor = open_executor(workers, scheduler)
            meta["executor"] = executor.description
            for row in executor.run(spec, todo):
                flat = flatten(row)
                flat = {**{c: flat.get(c) for c in columns}, **flat}
                done[flat["index"]] = flat
                if writer is not None:
                    writer.append(flat)
                bar.update(flat["status"])
    finally:
        bar.close()
        if own_executor and executor is not None:
            if sys.exc_info()[0] is not None:
                executor.abort()
            executor.close()
        if writer is not None:
            writer.close()
