"""Manipulators: what changes an execution from outside its components (start-value
``--set`` values, scheduled changes, disturbances). Structural changes (``--swap``) happen before
anything runs, in :func:`ipcosim.harness.scenario.binding.bind`.

Interface (subclass :class:`Manipulator`)::

    initialize(execution)       after the parameter bindings, before initialization mode:
                                set start values with execution.set_start(comp, var, value)
    next_tick(n) -> int | None  the next tick count (> n) before which step is to be called
    step(execution, n)          before tick n is stepped (time execution.time_of(n)); change
                                values with execution.set_real(comp, var, value)
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.execution import Execution


class Manipulator:
    """Base class of manipulators (every hook does nothing)."""

    def initialize(self, execution: "Execution") -> None:
        """Called in the instantiated state, after the parameter bindings are applied."""

    def next_tick(self, n: int) -> int | None:
        """The next tick count after ``n`` before which :meth:`step` is to be called, or None."""
        return None

    def step(self, execution: "Execution", n: int) -> None:
        """Called before tick ``n`` is stepped."""


class SetValues(Manipulator):
    """The start values of ``--set comp.var=value`` (a run's ``set``), applied after the bindings.

    Parameters
    ----------
    values : mapping of (component, variable) to value
        Already checked and converted (see :func:`ipcosim.harness.scenario.values.with_set`).
    """

    def __init__(self, values: Mapping[tuple[str, str], Any]) -> None:
        self.values = dict(values)

    def initialize(self, execution: "Execution") -> None:
        for (comp, var), value in self.values.items():
            execution.set_start(comp, var, value)


class ScheduledValues(Manipulator):
    """Values set at given times (e.g. a parameter change or an input disturbance).

    Parameters
    ----------
    changes : sequence of (time, component, variable, value)
        Applied before the first tick that starts at or after ``time``.
    """

    def __init__(self, changes: Sequence[tuple[float, str, str, float]]) -> None:
        self.changes = sorted(changes, key=lambda c: c[0])
        self._ticks: list[int] = []

    def initialize(self, execution: "Execution") -> None:
        import math

        self._ticks = [max(0, math.ceil((t - execution.start_time) / execution.step_size - 1e-9))
                       for t, *_ in self.changes]

    def next_tick(self, n: int) -> int | None:
        later = [k for k in self._ticks if k > n]
        return min(later) if later else None

    def step(self, execution: "Execution", n: int) -> None:
        for k, (_, comp, var, value) in zip(self._ticks, self.changes):
            if k == n:
                execution.set_real(comp, var, value)
