"""The record of one run: the rows the stepping loop copies the value vectors into, checked for
non-finite outputs, handed to the writer a chunk at a time (memory stays bounded), and the
:class:`~ipcosim.harness.master.results.Result` assembled from them at the end.

The record buffer holds at most a chunk of rows: row ``r`` of the run (absolute numbers, row 0
the start time) sits at buffer row ``r - base_row``; the loops write there through the
addresses of :meth:`Recorder.addresses`, the recorder turns the rows into structured arrays of
:meth:`~ipcosim.harness.master.layout.Layout.row_fields` (connected inputs: what their
connection delivers) and hands them to the writer.
"""
from __future__ import annotations

import ctypes
import time as _time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.harness.master import integers
from ipcosim.harness.master.algorithm import TimeBase
from ipcosim.harness.master.layout import Layout
from ipcosim.harness.master.plan import TypedRecord
from ipcosim.harness.master.results import Result, RowWriter, SimulationError
from ipcosim.harness.support.paths import distribution_version

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.execution import Execution

#: The task's metrics of a run: ``task_metrics(chunks, names) -> dict``, where ``chunks()``
#: iterates over the recorded rows (structured arrays, a chunk at a time; it may be called more
#: than once) and ``names`` are the fields. Given by whoever knows the scenario (the master
#: knows no task): ``ipcosim.harness.api.engine`` gives ``ipcosim.fmus.metrics.streamed_task_metrics``.
TaskMetrics = Callable[[Callable[[], Iterable[np.ndarray]], Sequence[str]], Mapping[str, Any]]


class NonFiniteError(SimulationError, FloatingPointError):
    """A component produced a NaN or infinite output."""


class TickFailure(SimulationError):
    """A failure inside the stepping loop, with the number of complete record rows (internal
    to the master: the run reports ``cause``)."""

    def __init__(self, message: str, rows: int, cause: BaseException | None = None) -> None:
        super().__init__(message)
        self.rows = rows
        self.cause = cause


class Recorder:
    """The rows of one run, from the value vectors of ``layout``.

    Parameters
    ----------
    layout : Layout
        Where the values are (and the columns they fill).
    timebase : TimeBase
        The run's integer time base (the rows' times).
    record_every : int
        A row every n-th communication point.
    order : sequence of int
        The components' step order (a non-finite value is blamed on the earliest).
    capacity : int
        Rows the buffer holds (at least a chunk of ticks' rows and one).
    flush_seconds : float
        Wall-clock seconds after which :meth:`due` asks for a write whatever the buffer holds.

    Attributes
    ----------
    max_pending_rows : int or None
        When set, :meth:`due` also asks for a write once this many rows wait: a paced run
        (:class:`ipcosim.harness.master.realtime.RealtimePacer`) writes a few rows at a time,
        since results.csv costs about 10 us a row and 0.2 s of rows at 1 kHz written at once
        made the steps after them start milliseconds late.
    """

    def __init__(self, layout: Layout, timebase: TimeBase, record_every: int, order: Sequence[int],
                 capacity: int, flush_seconds: float) -> None:
        self.layout = layout
        self.timebase = timebase
        self.record_every = record_every
        self.order = list(order)
        self.capacity = capacity
        self.flush_seconds = flush_seconds
        self.max_pending_rows: int | None = None
        #: Wall-clock seconds spent handing rows to the writer (results.csv): not the loop's.
        self.write_seconds = 0.0
        self.writer: RowWriter | None = None

    def open(self, writer: RowWriter | None) -> None:
        """Allocate the buffer; rows go to ``writer`` (default: a spool file only)."""
        lay = self.layout
        self.writer = writer or RowWriter(lay.row_fields())
        self.record = np.zeros((self.capacity, max(lay.n_values, 1)))
        self.record_i = np.zeros((self.capacity, max(lay.n_ints, 1)), dtype=np.int64)
        self.record_s: dict[int, tuple] = {}  # String rows by (absolute) row number
        self.base_row = 0
        self._last_emit = _time.monotonic()
        self.write_seconds = 0.0

    @property
    def row_bytes(self) -> int:
        """Bytes of one row of the Real buffer (the whole value vector)."""
        return self.record.shape[1] * 8

    def addresses(self) -> tuple[int, int]:
        """Addresses the loops write absolute row ``r`` at (``+ r * row bytes``), Real and
        Integer/Boolean rows: the buffer's first row is the first row not yet written."""
        return (self.record.ctypes.data - self.base_row * self.row_bytes,
                self.record_i.ctypes.data - self.base_row * self.record_i.shape[1] * self.record_i.itemsize)

    def typed_record(self) -> TypedRecord | None:
        """Where the Python loop records the non-Real values (None: a Real-only system)."""
        lay = self.layout
        if not lay.n_ints and not lay.string_slots:
            return None
        slots = lay.string_slots
        return TypedRecord(int_row_bytes=ctypes.sizeof(ctypes.c_int64) * lay.n_ints if lay.n_ints else 0,
                           int_vector=ctypes.addressof(lay.ints_c),
                           strings=self.record_s if slots else None,
                           snapshot=lay.snapshot_strings if slots else None)

    # ------------------------------------------------------------------ rows
    def start(self) -> None:
        """Row 0: the values at the start time, after initialization, checked and written."""
        self._capture(0)
        self.check_finite(0, 1)
        self.emit(1)

    def append_at(self, t: float) -> None:
        """One more row, of the values as they are now, at time ``t`` [s] (a component's last
        successful time, when it ended the simulation within a step), checked and written."""
        self._capture(self.base_row)
        row = self.rows(self.base_row, 1)
        row["time"] = t
        self.check_finite(self.base_row, self.base_row + 1)
        assert self.writer is not None
        self.writer.append(row)
        self.base_row += 1

    def _capture(self, row: int) -> None:
        """Copy the value vectors into the buffer's first row (absolute row ``row``)."""
        lay = self.layout
        self.record[0, :lay.n_values] = lay.values
        self.record_i[0, :lay.n_ints] = lay.ints
        if lay.string_slots:
            self.record_s[row] = lay.snapshot_strings()

    def due(self, rows: int, ticks: int) -> bool:
        """Whether to write now, with ``rows`` rows recorded and a chunk of ``ticks`` next: when
        that chunk might not fit in the buffer, at least every ``flush_seconds``, and when
        ``max_pending_rows`` rows wait."""
        pending = rows - self.base_row
        return (pending + ticks // self.record_every + 1 > len(self.record)
                or (self.max_pending_rows is not None and pending >= self.max_pending_rows)
                or _time.monotonic() - self._last_emit >= self.flush_seconds)

    def write_tick(self, n: int) -> int:
        """The first tick after ``n`` at whose end ``max_pending_rows`` rows wait (a chunk ending there is
        written whole; very far when there is no such limit)."""
        if self.max_pending_rows is None:
            return n + (1 << 62)
        return max(n + 1, (self.base_row + self.max_pending_rows - 1) * self.record_every)

    def emit(self, rows: int) -> None:
        """Hand the buffer rows ``base_row .. rows-1`` (absolute numbers) to the writer.

        Raises
        ------
        TickFailure
            A row holds a value a connection cannot deliver (:meth:`_integer_column`): the rows
            before it are written, it and the rest are not.
        """
        t0 = _time.perf_counter()
        k = rows - self.base_row
        if k > 0:
            assert self.writer is not None
            try:
                block = self.rows(self.base_row, k)
            except integers.CarryError as exc:
                bad = exc.row if exc.row is not None else self.base_row
                if bad > self.base_row:
                    self.writer.append(self.rows(self.base_row, bad - self.base_row))
                self.base_row = rows  # the rest is never written
                raise TickFailure(str(exc), bad, exc) from None
            self.writer.append(block)
            if self.record_s:
                for row in range(self.base_row, rows):
                    self.record_s.pop(row, None)
            self.base_row = rows
        self._last_emit = _time.monotonic()
        self.write_seconds += _time.perf_counter() - t0

    def flush_pending(self, tick: int) -> None:
        """After an interruption at ``tick``: write the rows of the completed chunks still in the buffer."""
        if self.base_row > 0:  # stepping had started (row 0 written)
            try:
                self.emit(tick // self.record_every + 1)
            except Exception:  # noqa: BLE001 -- the first error is the one reported
                pass

    def check_finite(self, row0: int, row1: int) -> None:
        """Raise for the first non-finite output in rows ``row0 .. row1-1`` (absolute numbers,
        ``row0`` being the first row held in the buffer); the rows before it are handed to the
        writer first."""
        lay = self.layout
        if row1 <= row0 or not len(lay.output_slots):
            return
        block = self.record[row0 - self.base_row:row1 - self.base_row][:, lay.output_slots]
        if np.isfinite(block).all():
            return
        bad = ~np.isfinite(block)
        bad_row = int(np.argmax(bad.any(axis=1)))
        row = row0 + bad_row
        # of the outputs that went bad in that row, blame the one of the earliest component in
        # step order (the others most likely computed theirs from it)
        rank = {idx: pos for pos, idx in enumerate(self.order)}
        slots = [int(lay.output_slots[c]) for c in np.flatnonzero(bad[bad_row])]
        slot = min(slots, key=lambda s: (rank[lay.output_at(s)[0]], s))
        k, var = lay.output_at(slot)
        inst = lay.instances[k]
        t = self.timebase.time(row * self.record_every)
        msg = (f"component {inst.name} ({inst.model.name}): output {inst.name}.{var} = "
               f"{float(self.record[row - self.base_row, slot])} at t = {t:.6g} s (non-finite value)")
        self.emit(row + 1)  # the bad row too: it shows what went wrong
        raise TickFailure(msg, row + 1, NonFiniteError(msg))

    def rows(self, first_row: int, rows: int) -> np.ndarray:
        """Buffer rows ``0 .. rows-1`` (absolute ``first_row ..``) as a structured array of the
        row fields."""
        rec = self.record[:rows]
        data = np.zeros(rows, dtype=self.layout.row_fields())
        tb = self.timebase
        ticks = (first_row + np.arange(rows)) * self.record_every
        if tb.step_ns is not None:
            data["time"] = (tb.start_ns + ticks * tb.step_ns) / 1e9
        else:
            data["time"] = tb.start + ticks * tb.step
        data["time"][ticks >= tb.ticks] = tb.time(tb.ticks)
        for name, slot, link in self.layout.columns:
            if link is None:
                data[name] = rec[:, slot]
            else:
                src, factor, offset = link
                data[name] = factor * rec[:, src] + offset
        self._typed_rows(data, first_row)
        return data

    def _typed_rows(self, data: np.ndarray, first_row: int) -> None:
        """Fill the Integer, Boolean and String columns of buffer rows ``0 .. len(data)-1``
        (absolute ``first_row ..``); a connected input: what its connection delivers, i.e. the
        source's value through the mapping."""
        rows = len(data)
        ints = self.record_i[:rows]
        strings = [self.record_s.get(first_row + r) for r in range(rows)] if self.layout.string_slots else []
        for name, value_type, slot, link in self.layout.typed_columns:
            src, mapping = link if link is not None else (slot, {})
            if value_type == "string":
                values = [row[src].decode("utf-8", "replace") if row is not None else ""
                          for row in strings]
                data[name] = np.array(values, dtype=object) if rows else values
                continue
            col = ints[:, src]
            if value_type == "integer":
                data[name] = self._integer_column(col, src, slot, mapping, first_row)
                continue
            if mapping:
                col = np.array([mapping.get(int(x), int(x)) for x in col], dtype=np.int64)
            data[name] = col.astype(bool)

    def _integer_column(self, held: np.ndarray, src: int, slot: int, mapping: dict[int, int],
                        first_row: int) -> np.ndarray:
        """An Integer column's values from the ``int64`` rows of slot ``src`` (the column's own
        slot ``slot``, or its connection's source): in the column's type, and, for a connected
        input whose type cannot hold every source value or with a mapping, what the connection
        delivers, each value checked (CarryError at the first that does not fit: never wrapped)."""
        lay = self.layout
        src_t, dst_t = lay.int_types[src][0], lay.int_types[slot][0]
        values = integers.column(held, src_t)
        if src == slot or (not mapping and not integers.narrowing(src_t, dst_t)):
            return values.astype(integers.DTYPE[dst_t])
        carrier = integers.Carrier(src_t, dst_t, mapping, f"{lay.int_types[src][1]} -> {lay.int_types[slot][1]}")
        out = []
        for r, x in enumerate(values.tolist()):
            try:
                out.append(carrier.deliver(x))
            except integers.CarryError as exc:
                t = self.timebase.time((first_row + r) * self.record_every)
                raise integers.CarryError(f"{exc} (at t = {t:.6g} s)", row=first_row + r) from None
        return np.array(out, dtype=integers.DTYPE[dst_t])

    # ------------------------------------------------------------------ result
    def result(self, execution: "Execution", error: BaseException | None, wall: float, wall_loop: float,
               task_metrics: TaskMetrics | None) -> Result:
        """The run's Result: every written row, the metrics (the task's of the rows, timing,
        the observers') and the metadata (what ran, how, how it ended)."""
        task = self._task_metrics(task_metrics)
        assert self.writer is not None
        data = self.writer.finish()
        simulated = float(data["time"][-1] - data["time"][0]) if len(data) else 0.0
        metrics: dict[str, Any] = dict(task)
        metrics.update(timing_metrics(simulated, wall, wall_loop))
        metrics["ipcosim_version"] = distribution_version()
        for obs in execution.observers:
            try:
                metrics.update(obs.metrics())
            except Exception as exc:  # noqa: BLE001
                metrics.setdefault("observer_errors", []).append(str(exc))
        message = _one_line(error) if error is not None else None
        metadata = self._metadata(execution, data, message, wall, wall_loop, simulated)
        return Result(data=data, metrics=metrics, metadata=metadata, error=message)

    def _task_metrics(self, task_metrics: TaskMetrics | None) -> dict[str, Any]:
        """The task metrics from the rows written (a chunk at a time: bounded memory)."""
        if task_metrics is None:
            return {}
        assert self.writer is not None
        try:
            return dict(task_metrics(self.writer.chunks, list(self.layout.column_types)))
        except Exception as exc:  # noqa: BLE001 -- metrics must not hide the run's result
            return {"metrics_error": str(exc)}

    def _metadata(self, ex: "Execution", data: np.ndarray, message: str | None, wall: float, wall_loop: float,
                  simulated: float) -> dict[str, Any]:
        """What ran (scenario, algorithm, times, order, components, ``set`` values), how long
        it took and how it ended."""
        sc = ex.system.scenario
        metadata: dict[str, Any] = {
            "scenario": sc.name, "origin": sc.origin, "algorithm": ex.algorithm,
            "start_time": ex.start_time, "stop_time": ex.stop_time, "step": ex.step_size,
            "ticks": ex.n_ticks,
            "ticks_done": ex.tick if message is not None or ex.terminated_by else ex.n_ticks,
            "record_every": self.record_every, "loop": ex.loop_used or None, "order": ex.component_order,
            "step_multiples": dict(ex.multiples),
            "initialization_iterations": ex.init_iterations,
            "components": {i.name: {"model": i.model.name, "guid": i.model.guid,
                                    "fmu": str(i.model.path) if i.model.path else None,
                                    "swapped_from": i.swapped_from} for i in ex.instances},
            # The run's ``set`` is stored under "overrides": a metadata.json key that tests, baselines and
            # other tools read, so it keeps that name.
            "overrides": {f"{c}.{v}": x for (c, v), x in ex.set.items()},
            "warnings": list(ex.system.warnings), "notes": list(ex.system.notes),
            "wall_time_s": wall, "loop_wall_time_s": wall_loop, "write_wall_time_s": self.write_seconds,
            "simulated_s": simulated,
            "status": "ok" if message is None else "failed", "error": message,
            "end_time": float(data["time"][-1]) if len(data) else None, "terminated_by": ex.terminated_by,
            "fmu_messages": {s.name: s.messages()[-5:] for s in ex.slaves if s.messages()},
        }
        if ex.terminated_by:
            metadata["notes"].append(ex.terminated_by["note"])
        return metadata


def timing_metrics(simulated: float, wall: float, loop: float) -> dict[str, float | None]:
    """``wall_time_s``, ``real_time_factor`` (simulated / wall) and ``loop_real_time_factor``
    (simulated / stepping-loop seconds) of a run that simulated ``simulated`` seconds."""
    return {"wall_time_s": wall, "real_time_factor": simulated / wall if wall > 0 else None,
            "loop_real_time_factor": simulated / loop if loop > 0 else None}


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
