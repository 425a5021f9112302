"""The sweep engine: many runs of one scenario with different parameter values, in parallel.

A sweep is a :class:`~ipcosim.harness.studies.runners.RunSpec` (what one run is; built once per
worker, so a co-simulation's FMUs are extracted and loaded once per worker, not once per
run) and a list of :class:`~ipcosim.harness.studies.cases.SweepCase` (parameter values + seed).

Executors (:mod:`ipcosim.harness.studies.executors`)
    :class:`LocalExecutor` -- a pool of worker processes on this machine (the default, one
    per core); :class:`DaskExecutor` -- a ``dask.distributed`` cluster reached at
    ``tcp://HOST:PORT`` (start one with ``dask scheduler`` and ``dask worker ADDR --nthreads 1``).

Results (:mod:`ipcosim.harness.studies.store`)
    One row per run (index, seed, status, success, error message, parameter values, metrics,
    run time), appended to ``DIR/results.csv`` as soon as the run finishes and flushed, so an
    interrupted sweep keeps every finished run. Running the same sweep into the same folder
    again resumes: finished runs are read back and not redone. When the sweep completes, the
    file is sorted by run index. ``DIR/metadata.json`` holds the scenario hash,
    variations, seeds, executor and package versions.

Memory
    A sweep into a folder holds none of its rows: a bit per run says which are finished, and the counts
    per status and the first error are kept as the rows pass (:class:`Finished`); the rows are read back
    from the file when asked for (``SweepResult.rows``). A sweep without a folder keeps its rows in memory.

Failures
    A run that raises (FMU error, bad parameter value) becomes a row with status ``error``
    and its one-line message; a worker process that dies is replaced, the runs it was carrying
    are re-run one at a time, and a run that kills its worker even alone is recorded as
    ``error``. Nothing a single run does stops the sweep.
"""
from __future__ import annotations

import functools
import hashlib
import itertools
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence, TextIO

from ipcosim.errors import IpcosimError
from ipcosim.harness.master.results import claim_output
from ipcosim.harness.studies.cases import CaseStream, SweepCase
from ipcosim.harness.studies.executors import Executor, open_executor
from ipcosim.harness.studies.progress import SweepProgress
from ipcosim.harness.studies.runners import STATUSES, RunSpec
from ipcosim.harness.studies.store import (
    BASE_COLUMNS,
    METADATA_FILE,
    RESULTS_FILE,
    TAIL_COLUMNS,
    ResultsWriter,
    flatten,
    iter_results,
    package_versions,
    read_results,
    sort_results,
)

__all__ = ["SweepResult", "SweepMismatchError", "SweepResultsGoneError", "run_sweep", "columns_for", "plan_hash"]


class SweepMismatchError(IpcosimError, ValueError):
    """The output folder holds results of a different sweep."""


class SweepResultsGoneError(IpcosimError, FileNotFoundError):
    """The rows of a sweep with an output folder were asked for after its ``results.csv`` (or the whole
    folder) was removed: they are read back from that file, not held in memory."""


class Finished:
    """The finished runs of a sweep, in memory independent of its size: which ones (a bit per run number
    for a :class:`CaseStream`, else a set of the indices), how many of each status, the error of the
    lowest-numbered failed run and, with ``keep_rows``, the rows themselves."""

    def __init__(self, cases: Sequence[SweepCase], keep_rows: bool) -> None:
        self._bits = bytearray((len(cases) + 7) // 8) if isinstance(cases, CaseStream) else None
        self._set: set[int] = set()
        self.count = 0
        self.counts = {s: 0 for s in STATUSES}
        self.first_error: tuple[int, str] | None = None
        self.rows: dict[int, dict[str, Any]] | None = {} if keep_rows else None

    def __contains__(self, index: int) -> bool:
        if self._bits is not None:
            return 0 <= index < 8 * len(self._bits) and bool(self._bits[index >> 3] & (1 << (index & 7)))
        return index in self._set

    def __len__(self) -> int:
        return self.count

    def add(self, flat: Mapping[str, Any]) -> None:
        """Count a finished run's flat row (once per index)."""
        index, status = flat["index"], flat["status"]
        if index in self:
            return
        if self._bits is not None:
            self._bits[index >> 3] |= 1 << (index & 7)
        else:
            self._set.add(index)
        self.count += 1
        self.counts[status] = self.counts.get(status, 0) + 1
        if status == "error" and (self.first_error is None or index < self.first_error[0]):
            self.first_error = (index, str(flat.get("error") or ""))
        if self.rows is not None:
            self.rows[index] = dict(flat)


@dataclass
class SweepResult:
    """The outcome of :func:`run_sweep`.

    Attributes
    ----------
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
    counts : dict
        Runs per status.
    first_error : str or None
        The error message of the lowest-numbered failed run.
    held : list of dict or None
        The rows of an in-memory sweep (None: they are in ``path``).
    """

    columns: list[str]
    metadata: dict[str, Any]
    path: Path | None = None
    resumed: int = 0
    elapsed_s: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    first_error: str | None = None
    held: list[dict[str, Any]] | None = None

    @property
    def rows(self) -> list[dict[str, Any]]:
        """One flat row per run (``flatten``), sorted by index: read from ``path`` when the sweep wrote one
        (a list of every row: for a large sweep, read the file a row at a time with ``store.iter_results``).

        Raises
        ------
        SweepResultsGoneError
            ``path`` was removed (with the sweep's folder) since the sweep wrote it."""
        if self.held is not None:
            return self.held
        if self.path is None:
            return []
        try:
            return read_results(self.path)[1]
        except FileNotFoundError:
            gone = "the sweep's folder is gone" if not self.path.parent.is_dir() else "the file is gone"
            raise SweepResultsGoneError(
                f"{self.path}: cannot read the sweep's rows back: {gone} (a sweep with an output folder keeps "
                f"its rows there, not in memory: read them before the folder is removed)") from None

    @property
    def runs(self) -> int:
        """Number of runs with a row."""
        return sum(self.counts.values())

    def failure(self) -> str | None:
        """The error when every run failed (None otherwise: some ran, or there were none)."""
        errors = self.counts.get("error", 0)
        if errors and errors == self.runs:
            return f"all {errors} runs failed; first error: {self.first_error}"
        return None

    @property
    def success_rate(self) -> float:
        """Fraction of runs with status ``ok``."""
        return self.counts.get("ok", 0) / self.runs if self.runs else math.nan


def columns_for(spec: RunSpec, cases: Sequence[SweepCase]) -> list[str]:
    """Columns of a sweep's results: base, parameters (in first-seen order), metrics, run time."""
    params: dict[str, None] = {}
    if isinstance(cases, CaseStream):  # every run sets the same parameters
        params = dict.fromkeys(cases.param_names) if len(cases) else {}
    else:
        for case in cases:
            for name in case.params:
                params.setdefault(name, None)
    return [*BASE_COLUMNS, *params, *spec.metric_names, *TAIL_COLUMNS]


def plan_hash(spec: RunSpec, cases: Sequence[SweepCase]) -> str:
    """Identity of a sweep: the spec and every case's parameters and seed.

    The :func:`~ipcosim.harness.studies.runners.stable_hash` of ``{"spec": ..., "cases": [[index,
    seed, sorted params], ...]}``, its JSON text hashed a case at a time (no list of the cases)."""
    dumps = functools.partial(json.dumps, sort_keys=True, default=repr, separators=(",", ":"))
    digest = hashlib.sha256(b'{"cases":[')
    for i, c in enumerate(cases):
        digest.update((("," if i else "") + dumps([c.index, c.seed, sorted(c.params.items())])).encode())
    digest.update(('],"spec":' + dumps(spec.key) + "}").encode())
    return digest.hexdigest()[:16]


def run_sweep(spec: RunSpec, cases: Sequence[SweepCase], *, out: str | os.PathLike | None = None,
              executor: Executor | None = None, workers: int | None = None, scheduler: Any = None,
              resume: bool = True, progress: bool | TextIO = False,
              extra_metadata: Mapping[str, Any] | None = None) -> SweepResult:
    """Run every case of a sweep in parallel and collect one row per run.

    Parameters
    ----------
    spec : RunSpec
        What one run is.
    cases : sequence of SweepCase
        The runs (unique indices).
    out : path, optional
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
        Reuse finished runs found in ``out`` (an interrupted earlier run of the same sweep).
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
        ``out`` holds results of another sweep (different scenario, variations or seeds).
    SchedulerError
        The Dask scheduler cannot be reached.
    KeyboardInterrupt
        After stopping the workers; every finished run is in ``out``.
    """
    t_start = time.monotonic()
    indices: range | set[int]
    if isinstance(cases, CaseStream):  # runs 0..n-1 by construction, none held
        indices = range(len(cases))
    else:
        indices = {c.index for c in cases}
        if len(indices) != len(cases):
            raise ValueError("sweep cases must have unique indices")
    columns = columns_for(spec, cases)
    meta = _start_metadata(spec, cases, extra_metadata)
    path = Path(out) / RESULTS_FILE if out is not None else None
    done = Finished(cases, keep_rows=path is None)
    writer = _open_results(path, meta, columns, done, indices if resume else None) if path is not None else None
    resumed = len(done)
    _run_missing(spec, cases, done, columns, meta, writer, executor=executor, workers=workers,
                 scheduler=scheduler, progress=progress)
    _close_results(done, meta, time.monotonic() - t_start, path)
    return SweepResult(columns=columns, metadata=meta, path=path, resumed=resumed, elapsed_s=meta["elapsed_s"],
                       counts=dict(done.counts), first_error=done.first_error[1] if done.first_error else None,
                       held=sorted(done.rows.values(), key=lambda r: r["index"]) if done.rows is not None else None)


def _close_results(done: Finished, meta: dict[str, Any], elapsed: float, path: Path | None) -> None:
    """Record the counts per status in ``meta`` (with the end time and ``elapsed`` [s]); with a
    results file, sort it by case (the finished runs' rows only) and write the final ``metadata.json``."""
    meta.update({"finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "elapsed_s": elapsed, "counts": dict(done.counts),
                 "success_rate": done.counts.get("ok", 0) / len(done) if len(done) else None})
    if path is not None:
        sort_results(path, keep=done.__contains__)
        (path.parent / METADATA_FILE).write_text(json.dumps(meta, indent=2, default=repr) + "\n")


#: Seeds of the first runs that ``metadata.json`` lists.
RECORDED_SEEDS = 10000


def _start_metadata(spec: RunSpec, cases: Sequence[SweepCase], extra: Mapping[str, Any] | None) -> dict[str, Any]:
    """What ``metadata.json`` records at the start: the scenario, the plan's identity, the seeds
    (the first :data:`RECORDED_SEEDS`), package versions, the start time and ``extra``."""
    return {"scenario": spec.name, "scenario_hash": spec.key, "plan_hash": plan_hash(spec, cases),
            "spec": spec.identity(), "runs": len(cases),
            "seeds": {"cases": [c.seed for c in itertools.islice(cases, RECORDED_SEEDS)]},
            "packages": package_versions(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **dict(extra or {})}


def _open_results(path: Path, meta: dict[str, Any], columns: list[str], done: Finished,
                  wanted: range | set[int] | None) -> ResultsWriter:
    """Open a sweep's ``results.csv`` for appending and write its ``metadata.json``; with
    ``wanted`` (the case indices; None: start afresh), count into ``done`` the rows of those cases an
    earlier, interrupted run of the same sweep finished, read a row at a time (recorded as ``resumed_runs``).

    Raises
    ------
    SweepMismatchError
        The folder holds results of another sweep (other plan hash or columns).
    """
    claim_output(path.parent, "sweep")
    meta_path = path.parent / METADATA_FILE
    existing = wanted is not None and path.exists() and path.stat().st_size > 0
    if existing:
        old_meta: dict[str, Any] = {}
        if meta_path.exists():
            try:
                old_meta = json.loads(meta_path.read_text())
            except json.JSONDecodeError:
                old_meta = {}
        old_columns, old_rows = iter_results(path)
        if old_meta.get("plan_hash") != meta["plan_hash"] or old_columns != columns:
            old_rows.close()
            raise SweepMismatchError(
                f"{path} holds results of a different sweep (scenario, settings, --vary, --samples or "
                f"--seed differ); choose another --out or start afresh with --fresh")
        for row in old_rows:
            if row["index"] in wanted:
                done.add(row)
        meta["resumed_runs"] = len(done)
    writer = ResultsWriter(path, columns)
    writer.open(existing=existing)
    meta_path.write_text(json.dumps(meta, indent=2, default=repr) + "\n")
    return writer


def _run_missing(spec: RunSpec, cases: Sequence[SweepCase], done: Finished, columns: list[str],
                 meta: dict[str, Any], writer: ResultsWriter | None, *, executor: Executor | None,
                 workers: int | None, scheduler: Any, progress: bool | TextIO) -> None:
    """Run the cases not in ``done`` on ``executor`` (or one opened from ``workers`` /
    ``scheduler`` and closed here, aborted on an exception), adding each finished row to
    ``done`` and appending it to ``writer``, with a progress bar over all ``cases``."""
    todo = (c for c in cases if c.index not in done)  # fed to the executor as it takes them
    own_executor = executor is None
    bar = SweepProgress(len(cases), done=len(done), enabled=bool(progress),
                   stream=progress if hasattr(progress, "write") else None)
    bar.counts.update({s: n for s, n in done.counts.items() if n})
    bar.show()
    try:
        if len(cases) > len(done):
            if executor is None:
                executor = open_executor(workers, scheduler)
            meta["executor"] = executor.description
            for row in executor.run(spec, todo):
                flat = flatten(row)
                flat = {**{c: flat.get(c) for c in columns}, **flat}
                done.add(flat)
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
