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
from typing import Any, Callable, Iterable, Iterator, Sequence

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
        ``metrics.json`` content (see DESIGN.md): the task metrics, ``wall_time_s`` (the whole
        run: load, instantiate, initialize, step, write), ``real_time_factor`` (simulated /
        wall_time_s) and ``loop_real_time_factor`` (simulated / stepping-loop seconds).
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

    def plot(self, path: str | Path | None = None) -> Any:
        """The run's figure: reference and cart position(s), pendulum angle, voltage.

        Parameters
        ----------
        path : path, optional
            Write the figure there as PNG and return the path; without it, return the
            matplotlib Figure (to show or save).
        """
        from ipcosim.harness.plot import figure, plot_result

        return figure(self) if path is None else plot_result(self, path)

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
        self.write_metrics(files["metrics"])  # before the plot, which may fail (a missing extra)
        if plot:
            from ipcosim.harness.plot import plot_result

            files["plot"] = plot_result(self, out / "plot.png")
        return files

    def write_metrics(self, path: Path) -> None:
        """Write ``metrics.json``."""
        path.write_text(json.dumps(json_safe(self.metrics), indent=2) + "\n")


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

    Fields keep their types (Real ``f8``, Integer ``i4``, Boolean ``?``, String ``O``). A String
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
        self._spool.write(self._to_spool(block).tobytes())
        if self._csv_fd is not None:
            self._write_csv(csv_text(block, self.csv_columns).encode())
        self.rows += len(block)
        self.last_write = _time.monotonic()

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


def csv_text(data: np.ndarray, columns: Sequence[str]) -> str:
    """CSV lines (no header) of selected fields of a structured array, each column in its type:
    Real with full double precision (``%.17g``), Integer as integers, Boolean as
    ``true``/``false``, String quoted where CSV needs it."""
    if not len(data):
        return ""
    if all(data.dtype[c].kind == "f" for c in columns):
        matrix = np.column_stack([np.asarray(data[c], dtype=float) for c in columns])
        return "\n".join(",".join(map(_fmt, row)) for row in matrix.tolist()) + "\n"
    import csv
    import io

    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(zip(*(_csv_column(data[c]) for c in columns)))
    return buf.getvalue()


def _fmt(x: float) -> str:
    """A float as CSV text with full precision (``%.17g``, as ``write_csv``)."""
    return "%.17g" % x


def write_csv(data: np.ndarray, path: Path, columns: Sequence[str]) -> None:
    """Write selected fields of a structured array as CSV, each column in its type: Real with
    full double precision, Integer as integers, Boolean as ``true``/``false``, String quoted
    where CSV needs it (the field's numpy type says which, see ``execution.COLUMN_DTYPE``)."""
    n = len(data)
    with open(path, "w", newline="") as fh:
        fh.write(",".join(columns) + "\n")
        if n == 0:
            return
        if all(data.dtype[c].kind == "f" for c in columns):
            matrix = np.column_stack([np.asarray(data[c], dtype=float) for c in columns])
            np.savetxt(fh, matrix, fmt="%.17g", delimiter=",")
            return
        import csv

        text = [_csv_column(data[c]) for c in columns]
        csv.writer(fh, lineterminator="\n").writerows(zip(*text))


def _csv_column(values: np.ndarray) -> list[str]:
    kind = values.dtype.kind
    if kind == "f":
        return ["%.17g" % v for v in values]
    if kind == "b":
        return ["true" if v else "false" for v in values]
    if kind in "iu":
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
    out = dict(compute_metrics(np.asarray(data["time"], float), np.asarray(data[pos], float),
                               np.asarray(data[ref], float), np.asarray(data[ang], float),
                               np.asarray(data[volt], float)))
    from ipcosim.harness.metrics import upright_metrics
    out.update(upright_metrics(np.asarray(data["time"], float), np.asarray(data[pos], float),
                               np.asarray(data[ang], float)))
    return out


def streamed_task_metrics(chunks: Callable[[], Iterable[np.ndarray]], columns: Sequence[str]) -> dict[str, Any]:
    """:func:`task_metrics` computed in two passes over the rows, a chunk at a time, so that
    the metrics of a run of any length need no more memory than one chunk.

    Parameters
    ----------
    chunks : callable
        ``chunks()`` -> iterable of structured arrays (consecutive rows; called twice).
    columns : sequence of str
        The field names.

    Returns
    -------
    dict
        The same keys and values as :func:`task_metrics` on the whole arrays
        (``compute_metrics`` and ``upright_metrics``; an empty dict when the columns are
        missing or there are < 2 rows).
    """
    from ipcosim.harness import metrics as m

    pos, ang = first_column(columns, POSITION_COLUMNS), first_column(columns, ANGLE_COLUMNS)
    ref, volt = first_column(columns, REFERENCE_COLUMNS), first_column(columns, VOLTAGE_COLUMNS)
    if None in (pos, ang, ref, volt):
        return {}
    a = _first_pass(chunks, pos, ang, ref, volt)
    if a["n"] < 2:
        return {}
    if not a["t_ok"]:
        raise m.MetricsError("metrics: time must be finite and strictly increasing")
    result: dict[str, Any] = {
        "settling_time_s": None, "overshoot_m": None, "steady_state_error_m": None,
        "max_abs_angle_rad": a["max_angle"] if a["th_finite"] else None,
        "peak_voltage_V": a["peak_v"] if a["v_finite"] else None,
        "rms_voltage_V": math.sqrt(a["sum_v2"] / a["n"]) if a["v_finite"] else None,
        "upright": bool(a["finite"] and a["max_angle"] < m.UPRIGHT_LIMIT_RAD)}
    if a["finite"]:
        result.update(_second_pass(chunks, a, pos, ref, m.SETTLING_BAND, m.STEADY_STATE_FRACTION))
    result.update(_upright_pass(chunks, pos, ang))
    return result


def _first_pass(chunks: Callable[[], Iterable[np.ndarray]], pos: str, ang: str, ref: str, volt: str) -> dict[str, Any]:
    """Counts, finiteness, extremes, the first and last samples."""
    a: dict[str, Any] = {"n": 0, "t_ok": True, "th_finite": True, "v_finite": True, "finite": True,
                         "max_angle": 0.0, "peak_v": 0.0, "sum_v2": 0.0, "t_prev": None}
    for c in chunks():
        if not len(c):
            continue
        t, x, r, th, v = (np.asarray(c[k], float) for k in ("time", pos, ref, ang, volt))
        if a["n"] == 0:
            a["t0"], a["x0"] = float(t[0]), float(x[0])
        prev = a["t_prev"]
        a["t_ok"] &= bool(np.all(np.isfinite(t)) and np.all(np.diff(t) > 0) and (prev is None or t[0] > prev))
        a["t_prev"], a["t_end"], a["r_final"] = float(t[-1]), float(t[-1]), float(r[-1])
        a["th_finite"] &= bool(np.all(np.isfinite(th)))
        a["v_finite"] &= bool(np.all(np.isfinite(v)))
        a["finite"] &= bool(np.all(np.isfinite(x)) and np.all(np.isfinite(r)))
        if a["th_finite"]:
            a["max_angle"] = max(a["max_angle"], float(np.max(np.abs(th))))
        if a["v_finite"]:
            a["peak_v"] = max(a["peak_v"], float(np.max(np.abs(v))))
            a["sum_v2"] += float(np.sum(v * v))
        a["n"] += len(c)
    a["finite"] = a["finite"] and a["th_finite"] and a["v_finite"]
    if not a["th_finite"]:
        a["max_angle"] = math.inf
    return a


def _second_pass(chunks: Callable[[], Iterable[np.ndarray]], a: dict[str, Any], pos: str, ref: str,
                 band_fraction: float, tail_fraction: float) -> dict[str, Any]:
    """Overshoot, steady-state error and settling time, once the final reference is known."""
    r_final, step = a["r_final"], a["r_final"] - a["x0"]
    direction = 1.0 if step >= 0 else -1.0
    band = band_fraction * abs(step)
    t_start = a["t_end"] - tail_fraction * (a["t_end"] - a["t0"])
    over, tail_sum, tail_n = -math.inf, 0.0, 0
    last_out, last_outside = -1, False      # index of the last sample outside the band
    last_change_t = a["t0"]                 # time of the last reference change seen so far
    t_ref_at_entry = a["t0"]                # time of the last change at or before the entry
    first, r_prev = 0, None
    for c in chunks():
        if not len(c):
            continue
        t, x, r = (np.asarray(c[k], float) for k in ("time", pos, ref))
        over = max(over, float(np.max(direction * (x - r_final))))
        tail = t >= t_start
        tail_sum += float(np.sum(x[tail] - r[tail]))
        tail_n += int(tail.sum())
        prev = np.concatenate(([r[0] if r_prev is None else r_prev], r[:-1]))
        changes = np.flatnonzero(r != prev)
        outside = np.abs(x - r_final) > band
        out_idx = np.flatnonzero(outside)
        if out_idx.size:  # entry candidate: the sample after the last outside one
            last_out = first + int(out_idx[-1])
            entry_local = int(out_idx[-1]) + 1
            before = changes[changes <= entry_local]
            t_ref_at_entry = float(t[before[-1]]) if before.size else last_change_t
            if entry_local == len(c):  # the entry sample is in the next chunk: its change counts too
                t_ref_at_entry = None
        elif t_ref_at_entry is None:  # entry was the first sample of this chunk
            t_ref_at_entry = float(t[0]) if changes.size and changes[0] == 0 else last_change_t
        if changes.size:
            last_change_t = float(t[changes[-1]])
        last_outside = bool(outside[-1])
        r_prev = float(r[-1])
        first += len(c)
    out: dict[str, Any] = {"overshoot_m": max(0.0, over), "steady_state_error_m": abs(tail_sum / tail_n)}
    if step != 0.0 and not last_outside:
        entry_t = _time_of_row(chunks, last_out + 1)
        out["settling_time_s"] = float(entry_t - (t_ref_at_entry if t_ref_at_entry is not None else last_change_t))
    else:
        out["settling_time_s"] = None
    return out


class _LastRow:
    """The last row (absolute number) where a condition held, and the time of the row after it."""

    def __init__(self) -> None:
        self.row, self.t_after, self.pending = -1, None, False

    def see(self, first: int, t: np.ndarray, mask: np.ndarray) -> None:
        if self.pending and len(t):
            self.t_after, self.pending = float(t[0]), False
        hits = np.flatnonzero(mask)
        if hits.size:
            k = int(hits[-1])
            self.row = first + k
            self.pending = k + 1 == len(t)
            self.t_after = None if self.pending else float(t[k + 1])


def _upright_pass(chunks: Callable[[], Iterable[np.ndarray]], pos: str, ang: str) -> dict[str, Any]:
    """``ipcosim.harness.metrics.upright_metrics`` (time to upright, track used, the tap
    metrics) in one pass over the rows."""
    from ipcosim.harness import metrics as m

    down, outside = _LastRow(), _LastRow()   # |angle| not below the limit; outside the recovery band
    n, t0, th0, k0, t_k0 = 0, None, None, None, None
    x_finite, th_finite, track, peak = True, True, 0.0, 0.0
    for c in chunks():
        if not len(c):
            continue
        t, x = np.asarray(c["time"], float), np.asarray(c[pos], float)
        th = m.wrapped(np.asarray(c[ang], float))
        if t0 is None:
            t0, th0 = float(t[0]), float(th[0])
        x_finite &= bool(np.all(np.isfinite(x)))
        th_finite &= bool(np.all(np.isfinite(th)))
        if x_finite:
            track = max(track, float(np.max(np.abs(x))))
        down.see(n, t, ~(np.abs(th) < m.UPRIGHT_LIMIT_RAD))
        start = 0
        if k0 is None:
            moved = np.flatnonzero(np.abs(th - th0) > 1e-6)
            if moved.size:
                start = int(moved[0])
                k0, t_k0 = n + start, float(t[start])
        if k0 is not None and th_finite:
            rest = np.abs(th[start:])
            peak = max(peak, float(np.max(rest)))
            outside.see(n + start, t[start:], rest >= m.RECOVERY_BAND_RAD)
        n += len(c)
    t_up = t0 if down.row < 0 else (None if down.row == n - 1 else down.t_after)
    out: dict[str, Any] = {"time_to_upright_s": t_up, "track_used_m": track if x_finite else None}
    if k0 is None or not th_finite:
        out.update(peak_angle_after_tap_rad=None, recovery_time_s=None)
        return out
    rec = 0.0 if outside.row < 0 else (None if outside.row == n - 1 else outside.t_after - t_k0)
    out.update(peak_angle_after_tap_rad=peak, recovery_time_s=rec)
    return out


def _time_of_row(chunks: Callable[[], Iterable[np.ndarray]], row: int) -> float:
    first = 0
    for c in chunks():
        if row < first + len(c):
            return float(c["time"][row - first])
        first += len(c)
    raise IndexError(row)
