"""Slaves: one FMU instance each, driven through FMI 2.0 or FMI 3.0 co-simulation calls -- the interface
the master drives (:class:`Slave`), its statuses and its error (:class:`SlaveError`).

A slave offers the lifecycle calls (instantiate ... free, each checked) and, for the stepping
fast path, its raw C-signature functions: ``do_step(c, t, h, flag) -> status``,
``get_real(c, vrs, n, values) -> status`` and ``set_real(c, vrs, n, values) -> status``,
called with value-reference arrays resolved once and value arrays that live in the
execution's value vector (one batched call per component and step, no per-step allocation).

Values of the other types travel through *channels* (:meth:`Slave.channel`): per component and
type (``integer``, ``boolean``, ``string``) a bound ``get(buffer)`` and ``set(buffer)`` over the
component's connectors of that type, resolved once. Integer and Boolean buffers are ``c_int64``
arrays (every FMI integer type fits; ``UInt64`` as its 64 bits, :mod:`~ipcosim.harness.master.integers`),
String buffers Python lists of ``bytes``. A value a variable's type cannot hold is never set: the
master checks it first (:class:`~ipcosim.harness.master.integers.IntegerRangeError`).

The slaves of an extracted FMU, loaded through FMPy, live beside this module:
:mod:`~ipcosim.harness.master.fmu_slave` (what they share, the library loaded),
:mod:`~ipcosim.harness.master.fmi2_slave`, :mod:`~ipcosim.harness.master.fmi3_slave`, and
:mod:`~ipcosim.harness.master.slaves` (which one a component gets, the libraries kept for many runs);
their names are importable from here too.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.master.system import Variable

STATUS = {0: "fmi2OK", 1: "fmi2Warning", 2: "fmi2Discard", 3: "fmi2Error", 4: "fmi2Fatal", 5: "fmi2Pending"}
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
#: Not an FMI status: what a slave's ``do_step`` returns when the FMU completed the step and asked
#: to end the simulation (FMI 3.0 ``terminateSimulation``); the stepping loop stops on it.
TERMINATE = 16

RawDoStep = Callable[[Any, float, float, int], int]
RawGetSet = Callable[[Any, Any, int, Any], int]
BoundGetSet = Callable[[Any], int]




class SlaveError(IpcosimError, RuntimeError):
    """An FMI call returned fmi2Discard, fmi2Error or fmi2Fatal (or the FMU could not be loaded).

    Attributes
    ----------
    component : str
    function : str
    status : int
    time : float or None
    """

    def __init__(self, message: str, component: str = "", function: str = "", status: int = ERROR,
                 time: float | None = None) -> None:
        super().__init__(message)
        self.component, self.function, self.status, self.time = component, function, status, time


class Slave:
    """Interface of one co-simulation slave (FMI 2.0 semantics, values by value reference)."""

    name: str = ""
    model_name: str = ""

    #: Messages logged with status fmi2Error or fmi2Fatal so far (a Discard that comes with one is a
    #: failure even when the FMU reports fmi2Terminated).
    errors_logged: int = 0

    #: FMI state reached: 'created', 'instantiated', 'initialization', 'stepping', 'terminated',
    #: 'failed' (after fmi2Error/fmi2Fatal), 'freed'.
    state: str = "created"

    def instantiate(self) -> None: ...
    def setup_experiment(self, start_time: float, stop_time: float | None) -> None: ...
    def enter_initialization_mode(self) -> None: ...
    def exit_initialization_mode(self) -> None: ...
    def terminate(self) -> None: ...
    def free(self) -> None: ...

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        """Set values of any type (parameters, start values), grouped into one call per type."""
        raise NotImplementedError

    def get_values(self, variables: Sequence[Variable]) -> list[Any]:
        """Values of any type."""
        raise NotImplementedError

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        """``(handle, do_step, get_real, set_real)`` with C calling conventions (see module doc)."""
        raise NotImplementedError

    def channel(self, value_type: str, variables: Sequence[Variable]) -> tuple[BoundGetSet, BoundGetSet]:
        """``(get, set)`` for the ``variables`` (all of value type ``value_type``), each taking one
        buffer (see the module documentation) and returning an FMI status."""
        raise NotImplementedError

    def terminated(self) -> tuple[bool, str]:
        """After a Discard from ``do_step``: whether the FMU ended the simulation itself, and
        what its status query returned (for messages)."""
        return False, "the slave offers no status query"

    def last_successful_time(self) -> float | None:
        """After the FMU ended the simulation in a step: the time it reached in that step (FMI 2.0
        ``fmi2GetRealStatus(fmi2LastSuccessfulTime)``, FMI 3.0 ``lastSuccessfulTime``), or None."""
        return None

    def messages(self) -> list[str]:
        """Log messages the slave reported, oldest first (bounded)."""
        return []

    # ------------------------------------------------------------------ helpers
    def last_error(self) -> str:
        """The most telling logged message: the last error-level one, else the last one."""
        msgs = [m for m in self.messages() if "unknown error" not in m]
        errors = [m for m in msgs if m.startswith(("[fmi2Error]", "[fmi2Fatal]", "[fmi2Discard]"))]
        pick = (errors or msgs)[-1] if (errors or msgs) else ""
        return pick.split("] ", 1)[1] if pick.startswith("[") and "] " in pick else pick

    def label(self) -> str:
        """``component (model)``: the component a message is about."""
        return f"{self.name} ({self.model_name})" if self.model_name else self.name

    def fail(self, function: str, status: int, time: float | None = None) -> SlaveError:
        """A SlaveError for ``function`` having returned ``status``; records the failed state."""
        if status >= ERROR:
            self.state = "failed"
        at = f" at t = {time:.6g} s" if time is not None else ""
        detail = self.last_error()
        detail = f": {detail}" if detail else ""
        return SlaveError(f"component {self.label()}: {function} returned {STATUS.get(status, status)}{at}{detail}",
                          self.name, function, status, time)


#: The FMU slaves by name, and the module each lives in (imported when a name is asked for).
_FMU_SLAVES = {"FMUSlave": "fmu_slave", "load_library": "fmu_slave", "fmi2_tuple_library": "fmu_slave",
               "FMU2Slave": "fmi2_slave", "FMU3Slave": "fmi3_slave",
               "fmu_slave": "slaves", "SPECIAL_SLAVES": "slaves", "LoadedSlaves": "slaves"}


def __getattr__(name: str) -> Any:
    if name in _FMU_SLAVES:
        import importlib

        return getattr(importlib.import_module(f"ipcosim.harness.master.{_FMU_SLAVES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
