"""The stepping phase of a run, a base of :class:`~ipcosim.harness.master.execution.Execution`: every
tick in chunks between the manipulators' and observers' ticks, the rows of each chunk written and pending
signals looked at in between; and what the stepping loop's stop is -- the run's end, when a component ended
the simulation itself (with the row of its last successful time), or its failure, naming the component,
the call and the time.
"""
from __future__ import annotations

import ctypes
import time as _time
from typing import TYPE_CHECKING, Any, Sequence

from ipcosim.harness.master import signals
from ipcosim.harness.master.integers import CarryError
from ipcosim.harness.master.recorder import TickFailure
from ipcosim.harness.master.slave import DISCARD, TERMINATE

if TYPE_CHECKING:
    from ipcosim.harness.master.manipulators import Manipulator
    from ipcosim.harness.master.observers import Observer

#: At most this many ticks run between two looks at the record for non-finite values, at
#: pending signals, and two writes of the results.
CHUNK = 512
#: Wall-clock seconds a chunk of ticks aims at (fewer ticks per chunk for slow FMUs), so rows
#: reach the disk several times a second.
CHUNK_SECONDS = 0.2


class Stepping:
    """The stepping phase of an :class:`~ipcosim.harness.master.execution.Execution` (its base): the
    slaves, blocks, recorder, observers, manipulators and the tick it works on are the execution's."""

    def _step_all(self) -> None:
        """Run every tick in chunks between observer/manipulator events, writing the rows of
        each chunk and looking at pending signals in between."""
        N, every = self.n_ticks, self.record_every
        va = ctypes.addressof(self.layout.values_c)
        due_man = {id(m): m.next_tick(-1) for m in self.manipulators}
        due_obs = {id(o): o.next_tick(0) for o in self.observers}
        n, chunk = 0, min(CHUNK, 16)
        while n < N:
            signals.check()
            self._call_due(self.manipulators, due_man, n)
            target = min(N, n + chunk, self.recorder.write_tick(n),
                         *(k for k in (*due_man.values(), *due_obs.values()) if k is not None and k > n))
            t0 = _time.perf_counter()
            if not self._run_chunk(n, target, va):
                return  # a component ended the simulation
            rows = target // every + 1
            self.recorder.check_finite(n // every + 1, rows)
            chunk = _next_chunk(chunk, target - n, _time.perf_counter() - t0)
            # observers that need every tick make chunks of one tick
            if self.recorder.due(rows, chunk):
                self.recorder.emit(rows)
            n = self.tick = target
            self._call_due(self.observers, due_obs, n)
        self.recorder.emit(N // every + 1)

    def _call_due(self, hooks: Sequence[Manipulator | Observer], due: dict[int, int | None], n: int) -> None:
        """``step`` every manipulator or observer due at tick ``n``; note when each is due next."""
        for hook in hooks:
            if due[id(hook)] == n:
                hook.step(self, n)
                due[id(hook)] = hook.next_tick(n)

    def _run_chunk(self, n: int, target: int, va: int) -> bool:
        """Ticks ``n .. target-1`` in the stepping loop; False when a component ended the
        simulation within them (the run then ends normally at ``self.tick``)."""
        rb, rbi = self.recorder.addresses()
        marks = [s.errors_logged for s in self.slaves]
        try:
            failure = self._run_loop(n, target, rb, va, self.recorder.row_bytes, rbi)
        except CarryError as exc:
            self._carry_failed(exc)
        if failure is None:
            return True
        self._loop_failed(failure, marks)
        return False

    def _carry_failed(self, exc: CarryError) -> None:
        """After a connection could not deliver a value in tick ``exc.tick``: write the rows up
        to there and raise the failure, naming the connection, the value and the time."""
        fn = int(exc.tick or 0)
        self.tick = fn
        rows = fn // self.record_every + 1
        self.recorder.check_finite(self.recorder.base_row, rows)
        self.recorder.emit(rows)
        err = CarryError(f"{exc} (in the step from t = {self.time_of(fn):.6g} s)", fn)
        raise TickFailure(str(err), rows, err)

    def _loop_failed(self, failure: tuple[int, int, str, int], marks: Sequence[int]) -> None:
        """After the loop stopped on a status > fmi2Warning at tick ``failure[0]``: write the
        rows up to there, then return when the component ended the simulation (and logged no
        error since ``marks``), else raise the component's failure."""
        fn, idx, function, status = failure
        self.tick = fn
        rows = fn // self.record_every + 1
        self.recorder.check_finite(self.recorder.base_row, rows)
        self.recorder.emit(rows)
        slave = self.slaves[idx]
        logged_error = slave.errors_logged > marks[idx]
        if not logged_error and self._ended_by_fmu(idx, function, status):
            self._record_last_successful(slave)
            return
        err = slave.fail(function, status, self.time_of(fn))
        if status == DISCARD and function == "fmi2DoStep":
            ended, query = slave.terminated()
            why = ("but it logged an error in that step: a failure" if ended and logged_error
                   else "the FMU did not end the simulation")
            err = type(err)(f"{err} ({query}, {why})", err.component, err.function, err.status, err.time)
        raise TickFailure(str(err), rows, err)

    def _ended_by_fmu(self, idx: int, function: str, status: int) -> bool:
        """Whether a failed ``do_step`` is a component ending the simulation itself (FMI 2.0:
        fmi2Discard and fmi2GetBooleanStatus(fmi2Terminated) true; FMI 3.0: terminateSimulation).
        The run then ends normally at ``self.tick``, the last communication point every component
        reached; the metadata names the component."""
        if function != "fmi2DoStep" or status not in (DISCARD, TERMINATE):
            return False
        slave = self.slaves[idx]
        ended, query = slave.terminated()
        if not ended:
            return False
        t, t_next = self.time_of(self.tick), self.time_of(self.tick + 1)
        self.terminated_by = {"component": slave.name, "model": slave.model_name, "time": t,
                              "note": f"component {slave.label()} ended the simulation in its step from "
                                      f"t = {t:.6g} s to {t_next:.6g} s ({query}); the run ends at t = {t:.6g} s"}
        return True

    def _record_last_successful(self, slave: Any) -> None:
        """After a component ended the simulation within its step: the row at the time it reached
        there (its last successful time, when past the last full row), with every component's
        outputs as they are then -- the row FMPy's ``simulate_fmu`` records."""
        t, t_next = self.time_of(self.tick), self.time_of(self.tick + 1)
        t_last = slave.last_successful_time()
        if t_last is None or not t + 1e-12 * max(1.0, abs(t)) < t_last <= t_next:
            return
        for b in self.blocks:
            self._get_outputs(b, t_last)
        self.recorder.append_at(t_last)
        assert self.terminated_by is not None
        self.terminated_by.update(last_successful_time=t_last, note=self.terminated_by["note"].replace(
            f"the run ends at t = {t:.6g} s", f"recorded up to its last successful time t = {t_last:.6g} s"))


def _next_chunk(chunk: int, ticks: int, seconds: float) -> int:
    """Ticks for the next chunk so that it lasts about CHUNK_SECONDS (between 1 and CHUNK)."""
    if ticks < chunk or seconds <= 0:
        return chunk
    return int(max(1, min(CHUNK, ticks * CHUNK_SECONDS / seconds)))
