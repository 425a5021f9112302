"""Slaves: one FMU instance each, driven through FMI 2.0 co-simulation calls.

A slave offers the lifecycle calls (instantiate ... free, each checked) and, for the stepping
fast path, its raw C-signature functions: ``do_step(c, t, h, flag) -> status``,
``get_real(c, vrs, n, values) -> status`` and ``set_real(c, vrs, n, values) -> status``,
called with value-reference arrays resolved once and value arrays that live in the
execution's value vector (one batched call per component and step, no per-step allocation).

:class:`FMUSlave` loads an extracted FMU with FMPy's ``FMU2Slave`` and calls the shared
library's functions directly; :class:`PySlave` is a pure-Python slave with the same calling
convention (used by tests and for mock components).
"""
from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.harness.errors import IpcosimError
from ipcosim.harness.scenario.system import Instance, Variable

STATUS = {0: "fmi2OK", 1: "fmi2Warning", 2: "fmi2Discard", 3: "fmi2Error", 4: "fmi2Fatal", 5: "fmi2Pending"}
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4

RawDoStep = Callable[[Any, float, float, int], int]
RawGetSet = Callable[[Any, Any, int, Any], int]


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

    def describe(self) -> str:
        return f"{self.name} ({self.model_name})" if self.model_name else self.name

    def fail(self, function: str, status: int, time: float | None = None) -> SlaveError:
        """A SlaveError for ``function`` having returned ``status``; records the failed state."""
        if status >= ERROR:
            self.state = "failed"
        at = f" at t = {time:.6g} s" if time is not None else ""
        detail = self.last_error()
        detail = f": {detail}" if detail else ""
        return SlaveError(f"component {self.describe()}: {function} returned {STATUS.get(status, status)}{at}{detail}",
                          self.name, function, status, time)


# --------------------------------------------------------------------------- FMU slave
_LOGGER: Any = None
_SINKS: dict[int, "FMUSlave"] = {}
_SINK_COUNTER = [0]


def _route_log(env: Any, instance_name: bytes | None, status: int, category: bytes | None,
               message: bytes | None) -> None:
    """The process-wide FMI logger callback: hands a message to the slave that logged it."""
    slave = _SINKS.get(env if isinstance(env, int) else getattr(env, "value", None))
    if slave is not None:
        slave._log(env, instance_name, status, category, message)


class FMUSlave(Slave):
    """An FMI 2.0 co-simulation FMU instance (an extracted FMU loaded through FMPy).

    Parameters
    ----------
    instance : Instance
        The bound component (model, variables).
    unzip_dir : Path
        Where the FMU is extracted.
    library : FMU2Slave, optional
        A loaded library to instantiate from (see :func:`load_library`); it is then not
        unloaded on :meth:`free`. Default: load one, unload it on :meth:`free`.
    logging_on : bool
        Passed to fmi2Instantiate. On by default: pythonfmu FMUs forward their error messages
        only to instances instantiated with logging on.
    """

    MAX_MESSAGES = 50

    def __init__(self, instance: Instance, unzip_dir: Path, logging_on: bool = True, library: Any = None) -> None:
        self.name = instance.name
        self.model_name = instance.model.name
        self.instance = instance
        self.unzip_dir = Path(unzip_dir)
        self.logging_on = logging_on
        self._messages: list[str] = []
        self._fmu: Any = library
        self._owns_library = library is None
        self._callbacks: Any = None
        self._logger: Any = None
        self.state = "created"

    def messages(self) -> list[str]:
        return list(self._messages)

    def _log(self, env: Any, instance_name: bytes | None, status: int, category: bytes | None,
             message: bytes | None) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        lines = [line for line in text.splitlines() if line.strip()]
        if len(lines) > 1 and lines[0].startswith("Fatal py exception encountered"):
            text = lines[-1]  # pythonfmu's wrapper line, then the exception's text: report the latter (fmus/fmi.py)
        text = " ".join(text.split())  # one line
        if len(text) > 400:
            text = text[:397] + "..."
        self._messages.append(f"[{STATUS.get(status, status)}] {text}")
        del self._messages[:-self.MAX_MESSAGES]

    def instantiate(self) -> None:
        from fmpy import calloc, free  # type: ignore[attr-defined]
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )
        from fmpy.logging import addLoggerProxy  # type: ignore[import-not-found]

        if self._fmu is None:
            self._fmu = load_library(self.instance, self.unzip_dir)
        callbacks = fmi2CallbackFunctions()
        # fmpy's logger proxy keeps one Python logger for the whole process: every FMU's
        # messages go to the same function, which routes them by componentEnvironment.
        global _LOGGER
        if _LOGGER is None:
            _LOGGER = fmi2CallbackLoggerTYPE(_route_log)
        _SINK_COUNTER[0] += 1
        self._sink = _SINK_COUNTER[0]
        _SINKS[self._sink] = self
        callbacks.logger = _LOGGER
        callbacks.componentEnvironment = self._sink
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(ctypes.byref(callbacks))
        self._callbacks = callbacks
        f = self._fmu._functions
        self._do_step, self._get_real, self._set_real = f["fmi2DoStep"], f["fmi2GetReal"], f["fmi2SetReal"]
        try:
            self._fmu.instantiate(callbacks=callbacks, loggingOn=self.logging_on)
        except Exception as exc:  # noqa: BLE001
            self.state = "failed-instantiate"
            _SINKS.pop(self._sink, None)
            msgs = self.messages()
            raise SlaveError(f"component {self.describe()}: fmi2Instantiate failed ({exc})"
                             + (f": {msgs[-1]}" if msgs else ""), self.name, "fmi2Instantiate") from None
        self.state = "instantiated"

    def _call(self, function: str, *args: Any) -> None:
        status = self._fmu._functions[function](self._fmu.component, *args)
        if status > WARNING:
            raise self.fail(function, status)

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self._call("fmi2SetupExperiment", 0, 0.0, float(start_time), 1 if stop_time is not None else 0,
                   float(stop_time or 0.0))

    def enter_initialization_mode(self) -> None:
        self._call("fmi2EnterInitializationMode")
        self.state = "initialization"

    def exit_initialization_mode(self) -> None:
        self._call("fmi2ExitInitializationMode")
        self.state = "stepping"

    def terminate(self) -> None:
        if self.state in ("initialization", "stepping", "step-failed"):
            self.state = "terminating"
            self._call("fmi2Terminate")
            self.state = "terminated"

    def free(self) -> None:
        if self._fmu is None or self.state in ("freed", "created"):
            return
        _SINKS.pop(getattr(self, "_sink", None), None)
        try:
            if self._fmu.component is not None:
                self._fmu.fmi2FreeInstance(self._fmu.component)
        finally:
            self.state = "freed"
            self._fmu.component = None
            if self._owns_library:
                try:
                    self._fmu.freeLibrary()
                except Exception:  # noqa: BLE001 -- unloading is best effort
                    pass

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        groups: dict[str, tuple[list[int], list[Any]]] = {}
        for var, value in zip(variables, values):
            vrs, vals = groups.setdefault(_fmi_type(var.type), ([], []))
            vrs.append(var.vr)
            vals.append(value)
        fmu = self._fmu
        for t, (vrs, vals) in groups.items():
            n = len(vrs)
            vr_arr = (ctypes.c_uint * n)(*vrs)
            if t == "Real":
                status = fmu._functions["fmi2SetReal"](fmu.component, vr_arr, n, (ctypes.c_double * n)(*vals))
            elif t == "Integer":
                status = fmu._functions["fmi2SetInteger"](fmu.component, vr_arr, n, (ctypes.c_int * n)(*vals))
            elif t == "Boolean":
                status = fmu._functions["fmi2SetBoolean"](fmu.component, vr_arr, n,
                                                          (ctypes.c_int * n)(*[1 if v else 0 for v in vals]))
            else:
                status = fmu._functions["fmi2SetString"](fmu.component, vr_arr, n,
                                                         (ctypes.c_char_p * n)(*[str(v).encode() for v in vals]))
            if status > WARNING:
                names = ", ".join(v.name for v in variables if _fmi_type(v.type) == t)
                raise self.fail(f"fmi2Set{t} ({names})", status)

    def get_values(self, variables: Sequence[Variable]) -> list[Any]:
        out: list[Any] = []
        fmu = self._fmu
        for var in variables:
            t = _fmi_type(var.type)
            vr_arr = (ctypes.c_uint * 1)(var.vr)
            if t == "Real":
                buf: Any = (ctypes.c_double * 1)()
            elif t in ("Integer", "Boolean"):
                buf = (ctypes.c_int * 1)()
            else:
                buf = (ctypes.c_char_p * 1)()
            status = fmu._functions[f"fmi2Get{t}"](fmu.component, vr_arr, 1, buf)
            if status > WARNING:
                raise self.fail(f"fmi2Get{t} ({var.name})", status)
            v = buf[0]
            out.append(bool(v) if t == "Boolean" else (v.decode() if isinstance(v, bytes) else v))
        return out

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        return self._fmu.component, self._do_step, self._get_real, self._set_real


def load_library(instance: Instance, unzip_dir: Path) -> Any:
    """An FMPy ``FMU2Slave`` with the FMU's shared library loaded and its functions resolved.

    One such object can serve many consecutive instances (fmi2Instantiate ... fmi2FreeInstance)
    of the component, which saves loading and resolving on every run of a sweep.

    Raises
    ------
    SlaveError
        If the shared library cannot be loaded.
    """
    from fmpy.fmi2 import FMU2Slave

    model = instance.model
    try:
        return FMU2Slave(guid=model.guid, unzipDirectory=str(unzip_dir), modelIdentifier=model.model_identifier,
                         instanceName=instance.name)
    except Exception as exc:  # noqa: BLE001 -- fmpy raises bare exceptions
        raise SlaveError(f"component {instance.name} ({model.name}): cannot load the FMU's shared library: {exc}",
                         instance.name, "load") from None


def _fmi_type(t: str) -> str:
    return {"Float64": "Real", "Float32": "Real", "Enumeration": "Integer"}.get(t, t)


# --------------------------------------------------------------------------- Python slave
class PySlave(Slave):
    """A slave implemented in Python with the FMU calling convention (tests, mock components).

    Subclasses implement :meth:`step` (advance from ``t`` by ``h``; return an FMI status or
    True/False for OK/Discard) and keep values in ``self.values`` (value reference -> value).
    Every FMI call is appended to ``self.calls`` so tests can check the lifecycle.

    Parameters
    ----------
    instance : Instance
        The bound component (its model gives value references and start values).
    """

    def __init__(self, instance: Instance) -> None:
        self.name = instance.name
        self.model_name = instance.model.name
        self.instance = instance
        self.values: dict[int, Any] = {v.vr: v.start for v in instance.model.variables.values()}
        self.calls: list[str] = []
        self.log: list[str] = []
        self.state = "created"

    # subclasses ------------------------------------------------------------
    def step(self, t: float, h: float) -> int | bool:
        """Advance from ``t`` to ``t + h``; return an FMI status (or True/False)."""
        return OK

    def on_enter_initialization(self) -> None:
        """Hook: called on fmi2EnterInitializationMode."""

    def on_exit_initialization(self) -> None:
        """Hook: called on fmi2ExitInitializationMode."""

    def on_get(self) -> None:
        """Hook: called before values are read (compute outputs from inputs here)."""

    # lifecycle -------------------------------------------------------------
    def instantiate(self) -> None:
        self.calls.append("instantiate")
        self.state = "instantiated"

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self.calls.append("setup_experiment")

    def enter_initialization_mode(self) -> None:
        self.calls.append("enter_initialization_mode")
        self.on_enter_initialization()
        self.state = "initialization"

    def exit_initialization_mode(self) -> None:
        self.calls.append("exit_initialization_mode")
        self.on_exit_initialization()
        self.state = "stepping"

    def terminate(self) -> None:
        if self.state in ("initialization", "stepping", "step-failed"):
            self.calls.append("terminate")
            self.state = "terminated"

    def free(self) -> None:
        if self.state in ("freed", "created"):
            return
        self.calls.append("free")
        self.state = "freed"

    def messages(self) -> list[str]:
        return list(self.log)

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        self.calls.append("set_values")
        for var, value in zip(variables, values):
            self.values[var.vr] = value

    def get_values(self, variables: Sequence[Variable]) -> list[Any]:
        self.on_get()
        return [self.values[v.vr] for v in variables]

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        def do_step(c: Any, t: float, h: float, flag: int) -> int:
            self.calls.append("do_step")
            try:
                status = self.step(t, h)
            except Exception as exc:  # noqa: BLE001 -- an FMU reports errors by status
                self.log.append(f"[fmi2Error] {exc}")
                return ERROR
            if status is True or status is None:
                return OK
            if status is False:
                return DISCARD
            return int(status)

        def get_real(c: Any, vrs: Any, n: int, out: Any) -> int:
            self.on_get()
            values = self.values
            for i in range(n):
                out[i] = values[vrs[i]]
            return OK

        def set_real(c: Any, vrs: Any, n: int, vals: Any) -> int:
            values = self.values
            for i in range(n):
                values[vrs[i]] = vals[i]
            return OK

        return None, do_step, get_real, set_real
