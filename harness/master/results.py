"""Results of a run: the recorded trajectories, the metrics and the metadata, and writing them
as ``results.csv`` (columns ``time`` then ``component.variable``), ``metrics.json`` and,
on request, ``plot.png``.
"""
from __future__ import annotations

import fnmatch
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from ipcosim.errors import IpcosimError, UsageError, closest

#: Draws a result's figure: ``plotter(result, path or None)`` (see :attr:`Result.plotter`).
Plotter = Callable[["Result", "Path | None"], Any]


class SimulationError(IpcosimError, RuntimeError):
    """A run that failed; ``result`` holds everything recorded up to the failure."""

    def __init__(self, message: str, result: "Result | None" = None) -> None:
        super().__init__(message)
        self.result = result


@dataclass
class Result:
    """The outcome of one run.

    Attributes
    ----------
    data : numpy structured array
        Field ``time`` [s], then one field ``component.variable`` per recorded connector
        (SI units), then one per other variable the run's ``record`` names (a parameter, a local:
        :func:`~ipcosim.harness.master.layout.named_variables`), one row per recorded
        communication point (row 0 is the initial state).
    metrics : dict
        ``metrics.json`` content (see docs/metrics.md): the task metrics, ``wall_time_s`` (the whole
        run: load, instantiate, initialize, step, write), ``real_time_factor`` (simulated /
        wall_time_s) and ``loop_real_time_factor`` (simulated / stepping-loop seconds).
    metadata : dict
        Scenario, algorithm, step, order, step multiples, FMUs, the ``--set`` values (key ``overrides``),
        swaps, warnings, status and error.
    error : str or None
        One-line description of the failure, None for a complete run.
    plotter : callable, optional
        ``plotter(result, path)`` draws the run's figure (``path`` None: return it; else write
        a PNG there and return the path); set by whoever knows what the run is
        (``ipcosim.harness.api.engine``: :func:`ipcosim.harness.api.plot.plot`).
    """

    data: np.ndarray
    metrics: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    plotter: Plotter | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def columns(self) -> list[str]:
        return list(self.data.dtype.names or ())

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    def select(self, patterns: Sequence[str] | None) -> list[str]:
        """Column names matching ``patterns`` (exact names or shell patterns such as
        ``plant.*``), in result order, ``time`` first. None selects every column.

        Raises
        ------
        UsageError
            If a pattern matches no column.
        """
        return select_columns(self.columns, patterns)

    def plot(self, path: str | Path | None = None) -> Any:
        """The run's figure, drawn by :attr:`plotter`.

        Parameters
        ----------
        path : path, optional
            Write the figure there as PNG and return the path; without it, return the
            matplotlib Figure (to show or save).

        Raises
        ------
        UsageError
            If the result has no plotter.
        """
        if self.plotter is None:
            raise UsageError("this result has no plotter (results of ipcosim.run and Prepared.run have one)")
        return self.plotter(self, Path(path) if path is not None else None)

    def write(self, out: str | Path, variables: Sequence[str] | None = None, plot: bool = False,
              csv: bool = True) -> dict[str, Path]:
        """Write ``results.csv`` (unless ``csv`` is false: already streamed there),
        ``metrics.json`` (and ``plot.png``) into ``out``.

        Returns
        -------
        dict
            What was written (``results``, ``metrics``, ``plot``) -> its path.
        """
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        files = {"results": out / "results.csv", "metrics": out / "metrics.json"}
        if csv:
            write_csv(self.data, files["results"], self.select(variables))
        self.write_metrics(files["metrics"])  # before the plot, which may fail (a missing extra)
        if plot:
            try:
                files["plot"] = self.plot(out / "plot.png")
            except ImportError as exc:  # the plotting extra is missing: the numbers are written, say so
                self.metadata["plot_skipped"] = str(exc)
        return files

    def write_metrics(self, path: Path) -> None:
        """Write ``metrics.json``."""
        path.write_text(json.dumps(json_safe(self.metrics), indent=2) + "\n")


@dataclass(frozen=True)
class RunOutput:
    """What one run's result carries beyond the master's account, and where its files go.

    Attributes
    ----------
    folder : Path or None
        ``--out``: ``results.csv`` streamed there while the run proceeds, ``metrics.json`` written
        once at its end and, with ``plot``, ``plot.png``; None writes nothing.
    variables : sequence of str or None
        Columns of results.csv (names or patterns, :func:`select_columns`); None: every one.
    plot : bool
        Also write ``plot.png`` (with ``plotter``).
    metadata : mapping
        Added to the result's metadata (what the run's figure reads: the parameter set, the swaps...).
    plotter : callable or None
        The result's :attr:`Result.plotter`.
    started : float or None
        :func:`time.perf_counter` when the whole run began (loading included): ``wall_time_s`` and
        ``real_time_factor`` are then the whole run's; None: the execution's own.
    metrics : mapping
        Added to the result's metrics, so ``metrics.json`` records them (the voltage limit ``ipcosim view``
        draws).
    """

    folder: Path | None = None
    variables: Sequence[str] | None = None
    plot: bool = False
    metadata: Mapping[str, Any] = field(default_factory=dict)
    plotter: Plotter | None = None
    started: float | None = None
    metrics: Mapping[str, Any] = field(default_factory=dict)


def matching(names: Sequence[str], pattern: str) -> list[str]:
    """The ``names`` (columns, variables) ``pattern`` selects: the name itself where it is one (also
    one with brackets, ``x[1]``), else every name the shell pattern matches (``plant.*``)."""
    if pattern in names:
        return [pattern]
    return [n for n in names if fnmatch.fnmatchcase(n, pattern)]


def select_columns(columns: Sequence[str], patterns: Sequence[str] | None) -> list[str]:
    """Names of ``columns`` matching ``patterns`` (see :meth:`Result.select`)."""
    cols = list(columns)
    if not patterns:
        return cols
    chosen = {"time"}
    for p in patterns:
        hits = matching(cols, p)
        if not hits:
            raise UsageError(f"--record {p}: no such variable; {closest(p, cols[1:], listing=40)}")
        chosen.update(hits)
    return [c for c in cols if c in chosen]


class OutputFolderError(UsageError, OSError):
    """The output folder cannot be created or written, is another command's, or is in use."""


#: The command whose results an output folder holds, written in it by :func:`claim_output`; a command
#: never writes into another command's folder.
COMMAND_FILE = ".ipcosim-kind"
#: Held (``flock``) by the one process writing into an output folder.
LOCK_FILE = ".ipcosim-lock"
_held: dict[str, Any] = {}  # folder -> open lock file, for the life of the process
#: folder -> (the folders and claim files the claim created, the names in the folder before it, its time)
_made: dict[str, tuple[list[Path], list[str], set[str], float]] = {}


def claim_output(out: str | os.PathLike[str], command: str, what: str = "--out") -> Path:
    """Make ``out`` the output folder of this process for ``command`` (run, sweep, analyze, identify,
    compare, tune), before any work: created, checked writable, the same command's (or new), and
    held by this process alone until it exits.

    Raises
    ------
    OutputFolderError
        One line naming ``what`` and the folder: a file, not writable, holding another command's
        results, or being written by another process.
    """
    out = Path(out)
    key = os.path.abspath(out)
    if key in _held:
        return out
    if out.exists() and not out.is_dir():
        raise OutputFolderError(f"{what} {out}: is a file, not a folder; give a folder")
    new_dirs = [d for d in (out, *out.absolute().parents) if not d.exists()]  # innermost first
    new_files = [name for name in (LOCK_FILE, COMMAND_FILE) if not (out / name).exists()]
    claimed_at = time.time()
    try:
        before = set(os.listdir(out)) if out.is_dir() else set()
    except OSError:
        before = set()
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".ipcosim-write-check-", delete=True)
        probe.write(b"x")
        probe.close()
    except OSError as exc:
        raise OutputFolderError(f"{what} {out}: output folder is not writable ({exc.strerror or exc})") from None
    _check_command(out, command, what)
    lock = open(out / LOCK_FILE, "a+")  # noqa: SIM115 -- held open until the process exits
    if not _try_lock(lock):
        lock.seek(0)
        owner = lock.read().strip() or "?"
        lock.close()
        raise OutputFolderError(f"{what} {out}: another ipcosim process (pid {owner}) is writing there; "
                                f"wait for it or give another {what}")
    lock.seek(0)
    lock.truncate()
    lock.write(str(os.getpid()))
    lock.flush()
    _held[key] = lock
    _made[key] = (new_dirs, new_files, before, claimed_at)
    (out / COMMAND_FILE).write_text(command + "\n")
    return out


def abandon_outputs() -> list[Path]:
    """Undo the claims of this process on folders it wrote nothing into (a command refused or stopped before
    writing: no name in the folder but those there before the claim and the claim's own, none of those changed
    since): the claim's files it created are removed, then the folders it created, innermost first, each only
    while empty. A folder that was there before stays, and so does everything else in it. Returns the folders
    removed."""
    removed: list[Path] = []
    for key in list(_held):
        folder = Path(key)
        new_dirs, new_files, before, claimed_at = _made.get(key, ([], [], set(), 0.0))
        claim = {LOCK_FILE, COMMAND_FILE}
        try:
            names = set(os.listdir(folder)) - claim
            untouched = names <= before and all((folder / n).lstat().st_mtime < claimed_at for n in names)
        except OSError:
            continue
        if not untouched:
            continue  # the command wrote something: its claim stays until the process ends
        for name in new_files:
            try:
                (folder / name).unlink()
            except OSError:
                pass
        release_output(folder)
        for d in new_dirs:
            try:
                d.rmdir()
            except OSError:
                break  # not empty (or gone): it, and the folders above it, stay
            removed.append(d)
    return removed


def held_outputs() -> list[Path]:
    """The output folders this process holds."""
    return [Path(key) for key in _held]


def release_output(out: str | os.PathLike[str]) -> None:
    """Let another process write into ``out`` (a claim otherwise lasts until this process exits)."""
    _made.pop(os.path.abspath(out), None)
    lock = _held.pop(os.path.abspath(out), None)
    if lock is not None:
        lock.close()


def _try_lock(fh: Any) -> bool:
    try:
        import fcntl
    except ImportError:  # not POSIX: no advisory locks; the command check still holds
        return True
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def _check_command(out: Path, command: str, what: str) -> None:
    """Refuse a folder that holds another command's results: its command file says so, or (a folder
    written before commands were recorded) a run's ``metrics.json`` or the first column of its
    ``results.csv`` (``time``: a run's, ``index``: a sweep's)."""
    try:
        found = (out / COMMAND_FILE).read_text().strip()
    except OSError:
        found = ""
    if not found and (out / "metrics.json").exists():
        found = "run"
    if not found:
        try:
            with (out / "results.csv").open(encoding="utf-8", errors="replace") as fh:
                first = fh.readline().split(",", 1)[0].strip()
        except OSError:
            first = ""
        found = {"time": "run", "index": "sweep"}.get(first, "")
    if found and found != command:
        raise OutputFolderError(f"{what} {out}: holds the results of another command ({found}, not {command}); "
                                f"give another {what}")


#: The files a run writes into its output folder (:meth:`Result.write`).
RUN_FILES = ("results.csv", "metrics.json", "plot.png")


def open_output(out: str | Path, what: str = "--out") -> Path:
    """Create ``out`` and check that files can be written there (before a run starts).

    A previous run's files there (:data:`RUN_FILES`) are removed first, so that no stale figure
    or metrics sit beside the new results; other files are left as they are. A ``results.csv``
    that is not a run's (its first column is not ``time``: a sweep's, say) is never replaced.

    Raises
    ------
    OutputFolderError
        Naming the folder and the reason.
    """
    out = Path(out)
    _refuse_foreign_results(out / "results.csv", what)
    claim_output(out, "run", what)
    try:
        for name in RUN_FILES if out.is_dir() else ():
            (out / name).unlink(missing_ok=True)
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".ipcosim-write-check-", delete=True)
        probe.write(b"x")
        probe.flush()
        probe.close()
    except OSError as exc:
        raise OutputFolderError(f"{what} {out}: output folder is not writable ({exc.strerror or exc})") from None
    return out


def _refuse_foreign_results(csv: Path, what: str) -> None:
    """OutputFolderError if ``csv`` exists and is not a run's results (the first column is ``time``)."""
    try:
        with csv.open(encoding="utf-8", errors="replace") as fh:
            first = fh.readline()
    except (FileNotFoundError, NotADirectoryError):
        return
    except OSError as exc:
        raise OutputFolderError(f"{what} {csv.parent}: cannot read its results.csv ({exc.strerror or exc})") from None
    if first and first.split(",", 1)[0].strip() != "time":
        raise OutputFolderError(f"{what} {csv.parent}: its results.csv is not a run's (first column "
                                f"{first.split(',', 1)[0].strip()!r}, not 'time'); give another folder")


class RowWriter:
    """Where the rows of a run go while it runs: an anonymous spool file that backs
    :attr:`Result.data` (memory stays bounded whatever the run's length) and, when given,
    ``results.csv``, appended chunk by chunk with unbuffered writes (a killed process loses
    only the chunk being computed; the execution keeps chunks under a fraction of a second).

    Fields keep their types (Real ``f8``, Integer ``i4`` or its FMI 3.0 type's, Boolean ``?``, String ``O``). A String
    field is spooled as the number of its value in a table of the distinct values seen, so the
    memory a run holds grows with the distinct strings, not with its length.

    Parameters
    ----------
    fields : sequence of str or of (name, numpy type)
        ``time`` then ``component.variable``; a bare name is a Real (``f8``) field.
    csv_path : path, optional
        ``results.csv`` to stream to (created now, header written: an unwritable folder fails
        before the run).
    csv_columns : sequence of str, optional
        The columns of ``results.csv`` (default: all).
    in_memory_limit : int
        Results up to this many bytes are read back into memory at the end; larger ones (without
        String fields) stay a read-only memory map of the spool file.
    """

    def __init__(self, fields: Sequence[str] | Sequence[tuple[str, str]], csv_path: str | Path | None = None,
                 csv_columns: Sequence[str] | None = None, in_memory_limit: int = 16 * 1024 ** 2) -> None:
        pairs = [(f, "f8") if isinstance(f, str) else (str(f[0]), str(f[1])) for f in fields]
        self.dtype = np.dtype(pairs)
        self._strings = [n for n, t in pairs if np.dtype(t).kind == "O"]
        self._spool_dtype = np.dtype([(n, "i4" if n in self._strings else t) for n, t in pairs])
        self._table: list[str] = []
        self._number: dict[str, int] = {}
        self.rows = 0
        self.in_memory_limit = in_memory_limit
        self.csv_path = Path(csv_path) if csv_path is not None else None
        names = [n for n, _ in pairs]
        self.csv_columns = list(csv_columns) if csv_columns else names
        self._csv_fd: int | None = None
        self._spool = tempfile.TemporaryFile(prefix="ipcosim-rows-")  # unlinked at once: nothing left behind
        if self.csv_path is not None:
            try:
                self._csv_fd = os.open(self.csv_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
            except OSError as exc:
                self._spool.close()
                raise OutputFolderError(f"{self.csv_path}: cannot write results ({exc.strerror})") from None
            self._write_csv((",".join(self.csv_columns) + "\n").encode())

    def _write_csv(self, data: bytes) -> None:
        from ipcosim.harness.master import signals

        view = memoryview(data)
        with signals.critical():  # a forced exit waits for the chunk: no half-written line
            while view:
                try:
                    n = os.write(self._csv_fd, view)  # type: ignore[arg-type]
                except OSError as exc:
                    raise OutputFolderError(f"{self.csv_path}: cannot write results ({exc.strerror}); "
                                            f"{self.rows} rows written") from None
                view = view[n:]

    def append(self, block: np.ndarray) -> None:
        """Append rows (a structured array of :attr:`dtype`)."""
        if not len(block):
            return
        self._spool.write(self._to_spool(block).tobytes())
        if self._csv_fd is not None:
            self._write_csv(csv_bytes(block, self.csv_columns))
        self.rows += len(block)

    def _to_spool(self, block: np.ndarray) -> np.ndarray:
        if not self._strings:
            return np.ascontiguousarray(block, dtype=self.dtype)
        out = np.zeros(len(block), dtype=self._spool_dtype)
        for name in self.dtype.names or ():
            if name not in self._strings:
                out[name] = block[name]
                continue
            numbers = out[name]
            for i, value in enumerate(block[name]):
                k = self._number.get(value)
                if k is None:
                    k = self._number[value] = len(self._table)
                    self._table.append(value)
                numbers[i] = k
        return out

    def _from_spool(self, raw: np.ndarray) -> np.ndarray:
        if not self._strings:
            return raw
        out = np.zeros(len(raw), dtype=self.dtype)
        table = np.array(self._table + [""], dtype=object)
        for name in self.dtype.names or ():
            out[name] = table[raw[name]] if name in self._strings else raw[name]
        return out

    def chunks(self, rows: int = 8192) -> Iterator[np.ndarray]:
        """The rows written so far, ``rows`` at a time, read from the spool file (so that a pass
        over a long run does not map it into memory). Valid until :meth:`finish`."""
        self._spool.flush()
        fd = self._spool.fileno()
        size = self._spool_dtype.itemsize
        for first in range(0, self.rows, rows):
            n = min(rows, self.rows - first)
            raw = np.frombuffer(os.pread(fd, n * size, first * size), dtype=self._spool_dtype)
            yield self._from_spool(raw)

    def finish(self) -> np.ndarray:
        """Stop writing; the rows as a structured array (in memory, or memory-mapped if large)."""
        self.close_csv()
        self._spool.flush()
        nbytes = self.rows * self._spool_dtype.itemsize
        if nbytes == 0:
            self._spool.close()
            return np.zeros(0, dtype=self.dtype)
        if nbytes <= self.in_memory_limit or self._strings:
            self._spool.seek(0)
            raw = np.frombuffer(bytearray(self._spool.read(nbytes)), dtype=self._spool_dtype)
            self._spool.close()
            return self._from_spool(raw)
        return np.memmap(self._spool, dtype=self.dtype, mode="r", shape=(self.rows,))

    def close_csv(self) -> None:
        if self._csv_fd is not None:
            os.close(self._csv_fd)
            self._csv_fd = None

    def close(self) -> None:
        """Release the files (after :meth:`finish`, the memory map keeps the spool alive)."""
        self.close_csv()


def csv_bytes(data: np.ndarray, columns: Sequence[str]) -> bytes | bytearray:
    """:func:`csv_text` encoded; Real columns only are formatted in C where it can be
    (:mod:`~ipcosim.harness.master.cformat`: the same bytes)."""
    if len(data) and all(data.dtype[c].kind == "f" for c in columns):
        from ipcosim.harness.master import cformat

        fast = cformat.lines([np.asarray(data[c], dtype=float) for c in columns])
        if fast is not None:
            return fast
    return csv_text(data, columns).encode()


def csv_text(data: np.ndarray, columns: Sequence[str]) -> str:
    """CSV lines (no header) of selected fields of a structured array, each column in its type:
    Real with full double precision (``%.17g``), Integer as integers, Boolean as
    ``true``/``false``, String quoted where CSV needs it."""
    if not len(data):
        return ""
    if all(data.dtype[c].kind == "f" for c in columns):
        formatted: dict[bytes, list[str]] = {}  # a column recorded twice (an output, the input it feeds): once
        texts = []
        for c in columns:
            values = np.asarray(data[c], dtype=float)
            key = values.tobytes()
            if key not in formatted:
                formatted[key] = list(map("%.17g".__mod__, values.tolist()))
            texts.append(formatted[key])
        return "\n".join(map(",".join, zip(*texts))) + "\n"
    import csv
    import io

    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(zip(*(_csv_column(data[c]) for c in columns)))
    return buf.getvalue()


def write_csv(data: np.ndarray, path: Path, columns: Sequence[str]) -> None:
    """Write selected fields of a structured array as CSV, each column in its type: Real with
    full double precision, Integer as integers, Boolean as ``true``/``false``, String quoted
    where CSV needs it (the field's numpy type says which, see ``layout.COLUMN_DTYPE``)."""
    with open(path, "w", newline="") as fh:
        fh.write(",".join(columns) + "\n" + csv_text(data, columns))


def _csv_column(values: np.ndarray) -> list[str]:
    code = values.dtype.kind  # numpy's type code: f float, b bool, i/u integer, O object
    if code == "f":
        return ["%.17g" % v for v in values]
    if code == "b":
        return ["true" if v else "false" for v in values]
    if code in "iu":
        return [str(int(v)) for v in values]
    return [str(v) for v in values]


def json_safe(value: Any) -> Any:
    """A JSON-serializable copy: numpy scalars as Python numbers, non-finite floats as null."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Path):
        return str(value)
    return value
