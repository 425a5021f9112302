"""The live feed: an observer that hands a run's values to the process serving the live view.

The stepping loop must not pay for a viewer. :class:`LiveFeed` asks the master for a tick only
every ``1 / rate`` simulated seconds (:data:`LIVE_RATE_HZ`, about the page's refresh rate), and
at such a tick it copies the recorded columns' current values into one row of a
:class:`SampleRing` -- a preallocated array (in shared memory, :mod:`ipcosim.harness.live.session`)
written by the loop's thread alone and read by the serving process without a lock (the row count
is published after the row is written; a reader that fell a whole ring behind skips ahead and
counts what it lost). Nothing else happens in the run's process: the serving process turns rows
into JSON, polls a rig, talks to browsers.

The feed knows no plant: it samples every Real, Integer and Boolean column of the run's
:class:`~ipcosim.harness.master.layout.Layout` by name (what the page draws is the scene's
business, :mod:`ipcosim.harness.live.scene`), the pacing of a paced run (late steps against the
overrun budget, from the master's :class:`~ipcosim.harness.master.realtime.RealtimePacer`) and
how the run ended. A stop asked for by the page (:meth:`LiveFeed.request_stop`) ends the run at
the feed's next tick the way SIGINT does (:class:`~ipcosim.harness.master.signals.Interrupted`):
every FMU terminated and freed -- a HIL adapter writes 0 V -- and the results so far written.
"""
from __future__ import annotations

import math
import signal
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ipcosim.harness.master.observers import Observer
from ipcosim.harness.master.realtime import RealtimePacer
from ipcosim.harness.master.signals import Interrupted

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.execution import Execution

#: Samples per simulated second the feed takes (a paced run: per wall-clock second).
LIVE_RATE_HZ = 30.0
#: Rows the ring holds: at 30 samples a second, over half an hour of a run.
RING_ROWS = 1 << 16
#: What the page is told when its stop button ended the run.
STOP_MESSAGE = "stopped from the live view"


class SampleRing:
    """A bounded single-writer, single-reader buffer of fixed-width rows of floats.

    The writer (:meth:`append`) fills row ``count % capacity`` and only then advances ``count``;
    a reader (:meth:`read`) copies the rows it has not seen and checks afterwards that the writer
    did not overwrite them meanwhile, so neither side ever waits for the other.

    Parameters
    ----------
    width : int
        Values per row.
    capacity : int
        Rows kept (the oldest are overwritten).
    """

    def __init__(self, width: int, capacity: int = RING_ROWS, buffer: Any = None, counter: Any = None) -> None:
        if capacity < 1 or width < 1:
            raise ValueError(f"a ring of {capacity} rows of {width} values")
        self.rows = (np.zeros((capacity, width)) if buffer is None
                     else np.ndarray((capacity, width), dtype=np.float64, buffer=buffer))
        self.capacity = capacity
        self._count = np.zeros(1, dtype=np.int64) if counter is None else counter

    @staticmethod
    def nbytes(width: int, capacity: int = RING_ROWS) -> int:
        """Bytes of the rows of a ring (for a buffer of its own)."""
        return 8 * width * capacity

    @property
    def count(self) -> int:
        """Rows written so far."""
        return int(self._count[0])

    def append(self, row: Sequence[float] | np.ndarray) -> None:
        """Write one row (the writer's thread only)."""
        n = int(self._count[0])
        self.rows[n % self.capacity] = row
        self._count[0] = n + 1  # published after the row is complete

    def read(self, since: int, limit: int | None = None) -> tuple[np.ndarray, int, int]:
        """The rows written from number ``since`` on.

        Returns
        -------
        rows : ndarray
            A copy, oldest first (at most ``limit`` rows when given).
        next : int
            The number to ask for next time.
        lost : int
            Rows that were overwritten before this reader got to them.
        """
        end = self.count
        start = max(since, end - self.capacity, 0)
        if limit is not None:
            end = min(end, start + limit)
        idx = np.arange(start, end) % self.capacity
        out = self.rows[idx].copy()
        overwritten = self.count - self.capacity - start  # rows the writer reused while we copied
        if overwritten > 0:
            out, start = out[overwritten:], start + overwritten
        return out, end, start - max(since, 0)


#: A feed's states, by their number on the :class:`Board`.
STATES = ("waiting", "running", "finished", "failed", "stopped")


class Board:
    """What a feed says besides its rows, in a buffer another process can share: the rows written, the
    state, the pacing counts, the page's stop request, whether the run's end is published, the message.

    Parameters
    ----------
    buffer : writable buffer, optional
        :data:`Board.SIZE` bytes (default: its own).
    """

    FIELDS = ("count", "state", "steps", "late_steps", "stop", "closed", "message_bytes")
    SIZE = 8 * 8 + 1024

    def __init__(self, buffer: Any = None) -> None:
        buffer = bytearray(self.SIZE) if buffer is None else buffer
        self.ints = np.ndarray((8,), dtype=np.int64, buffer=buffer)
        self.text = np.ndarray((self.SIZE - 64,), dtype=np.uint8, buffer=buffer, offset=64)

    def __getitem__(self, name: str) -> int:
        return int(self.ints[self.FIELDS.index(name)])

    def __setitem__(self, name: str, value: int) -> None:
        self.ints[self.FIELDS.index(name)] = value

    @property
    def counter(self) -> np.ndarray:
        """The ring's row count, in place."""
        return self.ints[0:1]

    @property
    def state(self) -> str:
        return STATES[self["state"]]

    @state.setter
    def state(self, value: str) -> None:
        self["state"] = STATES.index(value)

    @property
    def message(self) -> str:
        return bytes(self.text[:self["message_bytes"]]).decode("utf-8", "replace")

    @message.setter
    def message(self, value: str) -> None:
        data = value.encode("utf-8")[:len(self.text)]
        self.text[:len(data)] = np.frombuffer(data, dtype=np.uint8)
        self["message_bytes"] = len(data)


#: ``allocate(names, info, nbytes) -> (buffer, publish)``: a writable buffer of ``nbytes`` for a feed's board
#: and ring (shared with the process that serves the page), called once the sampled columns are known, and
#: ``publish()``, called at the feed's first tick after the start (never inside the run's start-up step,
#: when real-time components anchor their clocks: a page's first requests then made a HIL adapter's
#: sample instants start late), which tells the serving process where the buffer is.
Allocate = Any


class LiveFeed(Observer):
    """Observer sampling a run's columns into a :class:`SampleRing` for the live view.

    Parameters
    ----------
    rate : float
        Samples per simulated second (at least one per communication step at most).
    allocate : callable, optional
        :data:`Allocate`: where the board and the ring live (default: this process's memory).

    Attributes
    ----------
    names : list of str
        The sampled columns: ``time``, then ``component.variable`` (Real, Integer, Boolean).
    board : Board
        The state (``waiting``, ``running``, ``finished``, ``failed``, ``stopped``), the message
        (the run's error, or :data:`STOP_MESSAGE`), the pacing counts and the page's stop request.
    ring : SampleRing or None
        The samples (from :meth:`start` on).
    info : dict
        ``step``, ``start_time``, ``stop_time``, ``paced`` and, for a paced run, ``overrun_budget``
        and ``tolerance_s`` (what counts as a late step).
    """

    def __init__(self, rate: float = LIVE_RATE_HZ, allocate: Allocate = None) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"live feed rate {rate}: must be a positive number of samples per second")
        self.rate = rate
        self.allocate = allocate
        self.names: list[str] = []
        self.board = Board()
        self.ring: SampleRing | None = None
        self.info: dict[str, Any] = {}
        self._every = 1
        self._pacer: RealtimePacer | None = None
        self._late_seen = 0
        self._earliest = 1 << 62
        self._tolerance_ns = 0
        self._real: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._ints = np.zeros(0, dtype=int)
        self._row = np.zeros(1)
        self._publish: Any = None

    @property
    def state(self) -> str:
        return self.board.state

    @property
    def message(self) -> str:
        return self.board.message

    def request_stop(self) -> None:
        """Ask the run to stop at the feed's next tick (any thread; the serving process writes the board)."""
        self.board["stop"] = 1

    # ------------------------------------------------------------------ the loop's side
    def start(self, execution: "Execution") -> None:
        layout = execution.layout
        real = [(n, slot, src) for n, slot, src in layout.columns]
        ints = [(n, slot) for n, kind, slot, _ in layout.typed_columns if kind in ("integer", "boolean")]
        self.names = ["time"] + [n for n, _, _ in real] + [n for n, _ in ints]
        # a connected input's column is what its connection delivers: factor * source + offset
        slots = np.array([src[0] if src else slot for _, slot, src in real], dtype=int)
        factor = np.array([src[1] if src else 1.0 for _, _, src in real])
        offset = np.array([src[2] if src else 0.0 for _, _, src in real])
        self._real = (layout.values, slots, factor, offset)
        self._ints = np.array([slot for _, slot in ints], dtype=int)
        self._layout_ints = layout.ints
        self._row = np.zeros(len(self.names))
        self._time = execution.time_of
        self._every = max(1, int(round(1.0 / (self.rate * execution.step_size))))
        self._pacer = next((o for o in execution.observers if isinstance(o, RealtimePacer)), None)
        self.info = {"step": execution.step_size, "start_time": execution.start_time,
                     "stop_time": execution.stop_time, "paced": self._pacer is not None}
        if self._pacer is not None:
            tolerance = self._pacer.tolerance if self._pacer.tolerance is not None else execution.step_size / 2
            self._tolerance_ns = int(round(tolerance * 1e9))
            self.info.update(overrun_budget=self._pacer.overrun_budget, tolerance_s=tolerance)
        width = len(self.names)
        if self.allocate is not None:
            buffer, self._publish = self.allocate(self.names, self.info, Board.SIZE + SampleRing.nbytes(width))
            stop = self.board["stop"]
            self.board = Board(buffer[:Board.SIZE])
            self.board["stop"] = stop
            self.ring = SampleRing(width, buffer=buffer[Board.SIZE:], counter=self.board.counter)
        else:
            self.ring = SampleRing(width, counter=self.board.counter)
        self.board.state = "running"
        self._sample(0)

    def next_tick(self, n: int) -> int | None:
        return (n // self._every + 1) * self._every

    def step(self, execution: "Execution", n: int) -> None:
        if self._publish is not None:
            self._publish, publish = None, self._publish
            publish()
        self._sample(n)
        if self._pacer is not None:
            self._count_late()
        if self.board["stop"]:
            raise Interrupted(signal.SIGINT, STOP_MESSAGE)

    def _sample(self, n: int) -> None:
        """One row: the time after ``n`` ticks and every sampled column's value now."""
        assert self._real is not None and self.ring is not None
        values, slots, factor, offset = self._real
        row, k = self._row, len(slots)
        row[0] = self._time(n)
        row[1:k + 1] = values[slots] * factor + offset
        row[k + 1:] = self._layout_ints[self._ints]
        self.ring.append(row)

    def _count_late(self) -> None:
        """Late steps so far: those that started more than the pacer's tolerance after their deadline,
        lateness counted from the earliest-running step (as the pacer's own account does: a HIL card's
        clock adds a constant offset that is not lateness). The count is redone only when a step ran
        earlier than every one before it."""
        pacer = self._pacer.pacer if self._pacer is not None else None
        if pacer is None:
            return
        new = np.asarray(pacer.lateness_since(max(self._late_seen, 1)), dtype=np.int64)  # step 0: start-up
        if not new.size:
            return
        self._late_seen = max(self._late_seen, 1) + new.size
        late = self.board["late_steps"]
        if new.min() < self._earliest:
            self._earliest = int(new.min())
            new = np.asarray(pacer.lateness_since(1), dtype=np.int64)
            late = 0
        self.board["late_steps"] = late + int(np.count_nonzero(new - self._earliest > self._tolerance_ns))
        self.board["steps"] = self._late_seen

    def finish(self, execution: "Execution", error: BaseException | None) -> None:
        board = self.board
        if self.ring is not None and execution.tick and board.state == "running":
            try:
                self._sample(execution.tick)
            except Exception:  # noqa: BLE001 -- the last row is a courtesy, never a failure
                pass
        if self._pacer is not None and self._pacer.pacer is not None:
            st = self._pacer.pacer.stats()
            board["steps"], board["late_steps"] = st.steps, st.overruns
        if error is None:
            board.state = "finished"
        elif isinstance(error, Interrupted) and error.message == STOP_MESSAGE:
            board.message, board.state = STOP_MESSAGE, "stopped"
        else:
            text = str(error).strip()
            board.message = text.splitlines()[0] if text else type(error).__name__
            board.state = "failed"
