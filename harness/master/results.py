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
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ipcosim.harness.errors import IpcosimError, UsageError

#: Plant outputs that the metrics read, by preference: the motor-driven cart's position.
POSITION_COLUMNS = ("plant.cart_position", "plant.active_cart_position")
ANGLE_COLUMNS = ("plant.pendulum_angle",)
REFERENCE_COLUMNS = ("setpoint.reference", "controller.reference")
VOLTAGE_COLUMNS = ("controller.voltage", "plant.voltage")


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
        (SI units), one row per recorded communication point (row 0 is the initial state).
    metrics : dict
        ``metrics.json`` content (see DESIGN.md), plus ``wall_time_s`` and ``real_time_factor``.
    metadata : dict
        Scenario, algorithm, step, order, step multiples, FMUs, overrides, swaps, warnings,
        status and error.
    error : str or None
        One-line description of the failure, None for a complete run.
    """

    data: np.ndarray
    metrics: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    error: str | None = None

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

    def write(self, out_dir: str | Path, variables: Sequence[str] | None = None, plot: bool = False,
              csv: bool = True) -> dict[str, Path]:
        """Write ``results.csv`` (unless ``csv`` is false: already streamed there),
        ``metrics.json`` (and ``plot.png``) into ``out_dir``.

        Returns
        -------
        dict
            File kind -> path written.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = {"results": out / "results.csv", "metrics": out / "metrics.json"}
        if csv:
            write_csv(self.data, files["results"], self.select(variables))
        write_text_atomic(files["metrics"], json.dumps(json_safe(self.metrics), indent=2) + "\n")
        if plot:
            from ipcosim.harness.plot import plot_result

            files["plot"] = plot_result(self, out / "plot.png")
        return files


def select_columns(columns: Sequence[str], patterns: Sequence[str] | None) -> list[str]:
    """Names of ``columns`` matching ``patterns`` (see :meth:`Result.select`)."""
    cols = list(columns)
    if not patterns:
        return cols
    chosen = {"time"}
    for p in patterns:
        hits = [c for c in cols if fnmatch.fnmatchcase(c, p)]
        if not hits:
            raise UsageError(f"--record {p}: no such variable (recorded: {', '.join(cols[1:])})")
        chosen.update(hits)
    return [c for c in cols if c in chosen]


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename, so
    that an interrupted write never leaves a truncated file."""
    tmp = path.with_name(f".{path.name}.partial")
    try:
        with open(tmp, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


class OutputFolderError(IpcosimError, OSError):
    """The output folder cannot be created or written."""


def open_output(out_dir: str | Path, what: str = "--out") -> Path:
    """Create ``out_dir`` and check that files can be written there (before a run starts).

    Raises
    ------
    OutputFolderError
        Naming the folder and the reason.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".ipcosim-write-check-", delete=True)
        probe.write(b"x")
        probe.flush()
        probe.close()
    except OSError as exc:
        raise OutputFolderError(f"{what} {out}: output folder is not writable ({exc.strerror or exc})") from None
    return out


class RowWriter:
    """Where the rows of a run go while it runs: an anonymous spool file that backs
    :attr:`Result.data` (memory stays bounded whatever the run's length) and, when given,
    ``results.csv``, appended chunk by chunk with unbuffered writes (a killed process loses
    only the chunk being computed; the execution keeps chunks under a fraction of a second).

    Parameters
    ----------
    names : sequence of str
        Field names: ``time`` then ``component.variable``.
    csv_path : path, optional
        ``results.csv`` to stream to (created now, header written: an unwritable folder fails
        before the run).
    csv_columns : sequence of str, optional
        The columns of ``results.csv`` (default: all).
    in_memory_limit : int
        Results up to this many bytes are read back into memory at the end; larger ones stay
        a read-only memory map of the spool file.
    """

    def __init__(self, names: Sequence[str], csv_path: str | Path | None = None,
                 csv_columns: Sequence[str] | None = None, in_memory_limit: int = 64 * 1024 ** 2) -> None:
        self.dtype = np.dtype([(n, "f8") for n in names])
        self.rows = 0
        self.in_memory_limit = in_memory_limit
        self.csv_path = Path(csv_path) if csv_path is not None else None
        self.csv_columns = list(csv_columns) if csv_columns else list(names)
        self._csv_fd: int | None = None
        self._spool = tempfile.TemporaryFile(prefix="ipcosim-rows-")  # unlinked at once: nothing left behind
        if self.csv_path is not None:
            try:
                self._csv_fd = os.open(self.csv_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
            except OSError as exc:
                self._spool.close()
                raise OutputFolderError(f"{self.csv_path}: cannot write results ({exc.strerror})") from None
            self._write_csv((",".join(self.csv_columns) + "\n").encode())
        self.last_write = _time.monotonic()

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
        self._spool.write(np.ascontiguousarray(block, dtype=self.dtype).tobytes())
        if self._csv_fd is not None:
            matrix = np.column_stack([block[c] for c in self.csv_columns])
            lines = "\n".join(",".join(map(_fmt, row)) for row in matrix.tolist()) + "\n"
            self._write_csv(lines.encode())
        self.rows += len(block)
        self.last_write = _time.monotonic()

    def finish(self) -> np.ndarray:
        """Stop writing; the rows as a structured array (in memory, or memory-mapped if large)."""
        self.close_csv()
        self._spool.flush()
        nbytes = self.rows * self.dtype.itemsize
        if nbytes == 0:
            self._spool.close()
            return np.zeros(0, dtype=self.dtype)
        if nbytes <= self.in_memory_limit:
            self._spool.seek(0)
            data = np.frombuffer(bytearray(self._spool.read(nbytes)), dtype=self.dtype)
            self._spool.close()
            return data
        return np.memmap(self._spool, dtype=self.dtype, mode="r", shape=(self.rows,))

    def close_csv(self) -> None:
        if self._csv_fd is not None:
            os.close(self._csv_fd)
            self._csv_fd = None

    def close(self) -> None:
        """Release the files (after :meth:`finish`, the memory map keeps the spool alive)."""
        self.close_csv()


def _fmt(x: float) -> str:
    """A float as CSV text with full precision (``%.17g``, as ``write_csv``)."""
    return "%.17g" % x


def write_csv(data: np.ndarray, path: Path, columns: Sequence[str]) -> None:
    """Write selected fields of a structured array as CSV with full double precision."""
    n = len(data)
    with open(path, "w", newline="") as fh:
        fh.write(",".join(columns) + "\n")
        if n == 0:
            return
        matrix = np.column_stack([np.asarray(data[c], dtype=float) for c in columns])
        np.savetxt(fh, matrix, fmt="%.17g", delimiter=",")


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


def first_column(columns: Sequence[str], candidates: Sequence[str]) -> str | None:
    for c in candidates:
        if c in columns:
            return c
    return None


def task_metrics(data: np.ndarray) -> dict[str, Any]:
    """The DESIGN.md metrics of a pendulum run (``ipcosim.harness.metrics.compute_metrics``), from the
    plant's motor-cart position and angle, the reference and the controller's voltage; an
    empty dict when the result lacks those columns or has fewer than two rows."""
    cols = list(data.dtype.names or ())
    pos, ang = first_column(cols, POSITION_COLUMNS), first_column(cols, ANGLE_COLUMNS)
    ref, volt = first_column(cols, REFERENCE_COLUMNS), first_column(cols, VOLTAGE_COLUMNS)
    if None in (pos, ang, ref, volt) or len(data) < 2:
        return {}
    try:
        from ipcosim.harness.metrics import compute_metrics
    except ImportError:
        return {}
    return dict(compute_metrics(np.asarray(data["time"], float), np.asarray(data[pos], float),
                                np.asarray(data[ref], float), np.asarray(data[ang], float),
                                np.asarray(data[volt], float)))
