"""Slaves: one FMU instance each, driven through FMI 2.0 or FMI 3.0 co-simulation calls.

A slave offers the lifecycle calls (instantiate ... free, each checked) and, for the stepping
fast path, its raw C-signature functions: ``do_step(c, t, h, flag) -> status``,
``get_real(c, vrs, n, values) -> status`` and ``set_real(c, vrs, n, values) -> status``,
called with value-reference arrays resolved once and value arrays that live in the
execution's value vector (one batched call per component and step, no per-step allocation).

:func:`fmu_slave` makes the slave of an extracted FMU, loaded through FMPy, whose shared
library's functions are called directly: an :class:`FMU2Slave` for an FMI 2.0 FMU, an
:class:`FMU3Slave` for an FMI 3.0 one (its ``fmi3DoStep`` and typed getters and setters adapted
to the FMI 2.0 calling convention above; event mode is not used). The two are siblings over
:class:`FMUSlave`, what they share.

Values of the other types travel through *channels* (:meth:`Slave.channel`): per component and
type (``integer``, ``boolean``, ``string``) a bound ``get(buffer)`` and ``set(buffer)`` over the
component's connectors of that type, resolved once. Integer and Boolean buffers are ``c_int64``
arrays (every FMI integer type fits; ``UInt64`` as its 64 bits, :mod:`~ipcosim.harness.master.integers`),
String buffers Python lists of ``bytes``. A value a variable's type cannot hold is never set: the
master checks it first (:class:`~ipcosim.harness.master.integers.IntegerRangeError`).
"""
from __future__ import annotations

import ctypes
import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.master import integers
from ipcosim.harness.master.system import Instance, Variable

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
    """What the slaves of an extracted FMU (loaded through FMPy) share, whatever its FMI version:
    the log, the calls of the lifecycle common to both, freeing and reuse. Made by
    :func:`fmu_slave`, which picks :class:`FMU2Slave` or :class:`FMU3Slave` by the model's FMI
    version.

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

    Attributes
    ----------
    reusable : bool
        Keep the instance when a run that ended cleanly frees it (state ``parked``), and reset it
        (``fmi2Reset``) for the next run instead of instantiating anew: each pythonfmu 0.7.0
        instantiation re-executes the FMU's module and keeps the class it defines alive (a few
        kB a run in a study of many). :meth:`release` frees a parked instance for good.
    """

    reusable = False

    MAX_MESSAGES = 50

    #: Prefix of the FMI functions the class calls (``fmi2``, ``fmi3``).
    FMI = ""

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
        if status >= ERROR:
            self.errors_logged += 1
        del self._messages[:-self.MAX_MESSAGES]
    def _call(self, function: str, *args: Any) -> None:
        status = self._fmu._functions[function](self._fmu.component, *args)
        if status > WARNING:
            raise self.fail(function, status)
    def exit_initialization_mode(self) -> None:
        self._call(f"{self.FMI}ExitInitializationMode")
        self.state = "stepping"
    def terminate(self) -> None:
        if self.state in ("initialization", "stepping", "step-failed"):
            self.state = "terminating"
            self._call(f"{self.FMI}Terminate")
            self.state = "terminated"
    def free(self) -> None:
        if self._fmu is None or self.state in ("freed", "created", "parked"):
            return
        if self.reusable and self.state == "terminated" and self._fmu.component is not None:
            self.state = "parked"
            return
        _SINKS.pop(getattr(self, "_sink", None), None)
        try:
            if self._fmu.component is not None:
                getattr(self._fmu, f"{self.FMI}FreeInstance")(self._fmu.component)
        finally:
            self.state = "freed"
            self._fmu.component = None
            if self._owns_library:
                try:
                    self._fmu.freeLibrary()
                except Exception:  # noqa: BLE001 -- unloading is best effort
                    pass
    def release(self) -> None:
        """Free the instance for good (also a parked one)."""
        self.reusable = False
        if self.state == "parked":
            self.state = "terminated"
        self.free()
    def _checked(self, var: Variable, value: Any) -> int:
        """An integer value for ``var``, exact and in its type's range, else IntegerRangeError."""
        what = f"component {self.label()}: {self.name}.{var.name}"
        try:
            x = integers.exact_integer(value)
        except ValueError:
            raise integers.IntegerRangeError(f"{what}: {value!r} is not an integer") from None
        return integers.check(x, integers.integer_type(var.type, self.instance.model.fmi_version), what)


class FMU2Slave(FMUSlave):
    """An FMI 2.0 co-simulation FMU instance (see :class:`FMUSlave`)."""

    FMI = "fmi2"

    def instantiate(self) -> None:
        from fmpy import calloc, free  # type: ignore[attr-defined]
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )
        from fmpy.logging import addLoggerProxy  # type: ignore[import-not-found]

        if self.state == "parked":  # a clean run's instance, kept: reset instead of instantiating anew
            self._messages.clear()
            self._call(f"{self.FMI}Reset")
            self.state = "instantiated"
            return
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
        self._do_step, self._get_real, self._set_real = f.get("fmi2DoStep"), f["fmi2GetReal"], f["fmi2SetReal"]
        try:
            self._fmu.instantiate(callbacks=callbacks, loggingOn=self.logging_on)
        except Exception as exc:  # noqa: BLE001
            self.state = "failed-instantiate"
            _SINKS.pop(self._sink, None)
            msgs = self.messages()
            raise SlaveError(f"component {self.label()}: fmi2Instantiate failed ({exc})"
                             + (f": {msgs[-1]}" if msgs else ""), self.name, "fmi2Instantiate") from None
        self.state = "instantiated"
    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self._call("fmi2SetupExperiment", 0, 0.0, float(start_time), 1 if stop_time is not None else 0,
                   float(stop_time or 0.0))
    def enter_initialization_mode(self) -> None:
        self._call("fmi2EnterInitializationMode")
        self.state = "initialization"
    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        groups: dict[str, tuple[list[int], list[Any]]] = {}
        for var, value in zip(variables, values):
            if _fmi_type(var.type) == "Integer":
                value = self._checked(var, value)
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
    def channel(self, value_type: str, variables: Sequence[Variable]) -> tuple[BoundGetSet, BoundGetSet]:
        f, c, n = self._fmu._functions, self._fmu.component, len(variables)
        vrs = (ctypes.c_uint * max(n, 1))(*[v.vr for v in variables])
        if value_type in ("integer", "boolean"):
            # fmi2Integer and fmi2Boolean are C ints: through an int buffer to and from the
            # master's int64 one (the values set were checked to fit)
            name = "Integer" if value_type == "integer" else "Boolean"
            get, put = f[f"fmi2Get{name}"], f[f"fmi2Set{name}"]
            tmp = (ctypes.c_int * max(n, 1))()

            def get_ints(buf: Any) -> int:
                status = get(c, vrs, n, tmp)
                buf[:n] = tmp[:n]
                return status

            def set_ints(buf: Any) -> int:
                tmp[:n] = buf[:n]
                return put(c, vrs, n, tmp)

            return get_ints, set_ints
        if value_type == "string":
            get_s, put_s = f["fmi2GetString"], f["fmi2SetString"]
            tmp = (ctypes.c_char_p * max(n, 1))()

            def get_strings(dst: list) -> int:
                status = get_s(c, vrs, n, tmp)
                dst[:] = [x or b"" for x in tmp[:n]]  # copies: the FMU owns its strings
                return status

            def set_strings(src: list) -> int:
                return put_s(c, vrs, n, (ctypes.c_char_p * max(n, 1))(*src))

            return get_strings, set_strings
        raise ValueError(f"no channel for value type {value_type!r}")
    def terminated(self) -> tuple[bool, str]:
        value = ctypes.c_int(0)
        status = self._fmu._functions["fmi2GetBooleanStatus"](self._fmu.component, 3, ctypes.byref(value))
        if status > WARNING:
            return False, f"fmi2GetBooleanStatus(fmi2Terminated) returned {STATUS.get(status, status)}"
        return bool(value.value), (f"fmi2GetBooleanStatus(fmi2Terminated) returned "
                                   f"{'fmi2True' if value.value else 'fmi2False'}")
    def last_successful_time(self) -> float | None:
        value = ctypes.c_double(math.nan)
        status = self._fmu._functions["fmi2GetRealStatus"](self._fmu.component, 2, ctypes.byref(value))
        return float(value.value) if status <= WARNING and math.isfinite(value.value) else None


_FMI3_CTYPES = {"Float64": ctypes.c_double, "Float32": ctypes.c_float, "Int8": ctypes.c_int8,
                "UInt8": ctypes.c_uint8, "Int16": ctypes.c_int16, "UInt16": ctypes.c_uint16,
                "Int32": ctypes.c_int32, "UInt32": ctypes.c_uint32, "Int64": ctypes.c_int64,
                "UInt64": ctypes.c_uint64, "Enumeration": ctypes.c_int64, "Boolean": ctypes.c_bool,
                "String": ctypes.c_char_p}


class FMU3Slave(FMUSlave):
    """An FMI 3.0 co-simulation FMU instance, with the FMI 2.0-style interface of :class:`Slave`.

    Instantiated without event mode and without early return: ``fmi3DoStep``'s
    ``eventHandlingNeeded`` is ignored, ``terminateSimulation`` ends the run (the loop sees
    :data:`TERMINATE`). Float32 is converted to the master's ``c_double`` buffers; the sized
    integer types travel exactly in its ``c_int64`` ones (``UInt64`` as its 64 bits).
    """

    FMI = "fmi3"

    def instantiate(self) -> None:
        if self._fmu is None:
            self._fmu = load_library(self.instance, self.unzip_dir)

        def log(env: Any, status: int, category: bytes | None, message: bytes | None) -> None:
            self._log(env, None, status, category, message)

        try:
            self._fmu.instantiate(loggingOn=self.logging_on, logMessage=log)
        except Exception as exc:  # noqa: BLE001
            self.state = "failed-instantiate"
            msgs = self.messages()
            raise SlaveError(f"component {self.label()}: fmi3InstantiateCoSimulation failed ({exc})"
                             + (f": {msgs[-1]}" if msgs else ""), self.name, "fmi3InstantiateCoSimulation") from None
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        self.state = "instantiated"

    def setup_experiment(self, start_time: float, stop_time: float | None) -> None:
        self._experiment = (float(start_time), stop_time)  # FMI 3.0 takes them on entering initialization

    def enter_initialization_mode(self) -> None:
        start, stop = getattr(self, "_experiment", (0.0, None))
        self._call("fmi3EnterInitializationMode", False, 0.0, start, stop is not None, float(stop or 0.0))
        self.state = "initialization"

    def _typed(self, direction: str, type_: str) -> Callable[..., int]:
        name = "Int64" if type_ == "Enumeration" else type_
        return self._fmu._functions[f"fmi3{direction}{name}"]

    def set_values(self, variables: Sequence[Variable], values: Sequence[Any]) -> None:
        c = self._fmu.component
        for var, value in zip(variables, values):
            ct = _FMI3_CTYPES[var.type]
            v = str(value).encode() if var.type == "String" else value
            if var.type in integers.RANGE or var.type == "Enumeration":
                v = self._checked(var, value)
            status = self._typed("Set", var.type)(c, (ctypes.c_uint * 1)(var.vr), 1, (ct * 1)(v), 1)
            if status > WARNING:
                raise self.fail(f"fmi3Set{var.type} ({var.name})", status)

    def get_values(self, variables: Sequence[Variable]) -> list[Any]:
        out: list[Any] = []
        for var in variables:
            buf = (_FMI3_CTYPES[var.type] * 1)()
            status = self._typed("Get", var.type)(self._fmu.component, (ctypes.c_uint * 1)(var.vr), 1, buf, 1)
            if status > WARNING:
                raise self.fail(f"fmi3Get{var.type} ({var.name})", status)
            v = buf[0]
            out.append(v.decode() if isinstance(v, bytes) else v)
        return out

    def raw(self) -> tuple[Any, RawDoStep, RawGetSet, RawGetSet]:
        f = self._fmu._functions
        ds = f["fmi3DoStep"]
        event, term, early, last = self._flags
        refs = [ctypes.byref(x) for x in self._flags]

        def do_step(c: Any, t: float, h: float, flag: int) -> int:
            status = ds(c, t, h, True, *refs)
            return TERMINATE if status <= WARNING and term.value else status

        types = {v.vr: v.type for v in self.instance.model.variables.values()}
        return self._fmu.component, do_step, *self._real_io(types)

    def _real_io(self, types: dict[int, str]) -> tuple[RawGetSet, RawGetSet]:
        f = self._fmu._functions
        g64, s64, g32, s32 = f["fmi3GetFloat64"], f["fmi3SetFloat64"], f["fmi3GetFloat32"], f["fmi3SetFloat32"]
        if all(t != "Float32" for t in types.values()):
            return (lambda c, vrs, n, out: g64(c, vrs, n, out, n)), (lambda c, vrs, n, vals: s64(c, vrs, n, vals, n))
        one = ctypes.c_float * 1

        def get_real(c: Any, vrs: Any, n: int, out: Any) -> int:
            worst = OK
            for i in range(n):
                vr = (ctypes.c_uint * 1)(vrs[i])
                if types.get(vrs[i]) == "Float32":
                    tmp = one()
                    worst = max(worst, g32(c, vr, 1, tmp, 1))
                    out[i] = tmp[0]
                else:
                    tmp64 = (ctypes.c_double * 1)()
                    worst = max(worst, g64(c, vr, 1, tmp64, 1))
                    out[i] = tmp64[0]
            return worst

        def set_real(c: Any, vrs: Any, n: int, vals: Any) -> int:
            worst = OK
            for i in range(n):
                vr = (ctypes.c_uint * 1)(vrs[i])
                if types.get(vrs[i]) == "Float32":
                    worst = max(worst, s32(c, vr, 1, one(vals[i]), 1))
                else:
                    worst = max(worst, s64(c, vr, 1, (ctypes.c_double * 1)(vals[i]), 1))
            return worst

        return get_real, set_real

    def channel(self, value_type: str, variables: Sequence[Variable]) -> tuple[BoundGetSet, BoundGetSet]:
        c, n = self._fmu.component, len(variables)
        groups = []  # (positions, vr array, ctypes array type, getter, setter, type)
        for type_ in dict.fromkeys(v.type for v in variables):
            pos = [i for i, v in enumerate(variables) if v.type == type_]
            vrs = (ctypes.c_uint * len(pos))(*[variables[i].vr for i in pos])
            groups.append((pos, vrs, _FMI3_CTYPES[type_] * len(pos), self._typed("Get", type_),
                           self._typed("Set", type_), type_))

        def get(buf: Any) -> int:
            worst = OK
            for pos, vrs, arr, g, _, type_ in groups:
                tmp = arr()
                worst = max(worst, g(c, vrs, len(pos), tmp, len(pos)))
                for k, i in enumerate(pos):
                    buf[i] = (tmp[k] or b"") if value_type == "string" else integers.stored(int(tmp[k]), type_)
            return worst

        def put(buf: Any) -> int:
            worst = OK
            for pos, vrs, arr, _, s, type_ in groups:
                vals = [buf[i] for i in pos] if value_type == "string" else [integers.value(buf[i], type_) for i in pos]
                worst = max(worst, s(c, vrs, len(pos), arr(*vals), len(pos)))
            return worst

        del n
        return get, put

    def terminated(self) -> tuple[bool, str]:
        flag = bool(self._flags[1].value)
        return flag, f"fmi3DoStep set terminateSimulation = {'true' if flag else 'false'}"

    def last_successful_time(self) -> float | None:
        value = float(self._flags[3].value)
        return value if math.isfinite(value) else None


#: Makers of the slave of an FMU that needs more than :class:`FMU2Slave` or :class:`FMU3Slave`, asked in
#: turn by :func:`fmu_slave`: ``maker(instance, unzip_dir, logging_on, library)`` -> a slave, or None.
SPECIAL_SLAVES: list[Callable[[Instance, Path, bool, Any], "FMUSlave | None"]] = []


def fmu_slave(instance: Instance, unzip_dir: Path, logging_on: bool = True, library: Any = None) -> FMUSlave:
    """The slave of one extracted FMU: an :class:`FMU3Slave` for an FMI 3.0 model, else an
    :class:`FMU2Slave` (the arguments are :class:`FMUSlave`'s)."""
    for special in SPECIAL_SLAVES:  # e.g. an FMU with clocks (ipcosim.harness.master.clocked)
        slave = special(instance, unzip_dir, logging_on, library)
        if slave is not None:
            return slave
    cls = FMU3Slave if instance.model.fmi_version.startswith("3") else FMU2Slave
    return cls(instance, unzip_dir, logging_on=logging_on, library=library)


class LoadedSlaves:
    """The slaves of many runs of one system, one run at a time: each component's FMU library loaded
    on first use and kept for the following runs (:func:`load_library`) and, with ``reuse``, each
    component's instance too, reset between runs instead of instantiated anew (:attr:`FMUSlave.reusable`).
    Called with an instance, it is an :class:`~ipcosim.harness.master.execution.Execution`'s slave factory.

    Parameters
    ----------
    unzip_dirs : mapping of component name to Path
        The extracted FMUs (read when a component's slave is first asked for).
    reuse : bool
        Keep each component's instance between runs.
    make, load : callable
        The slave of an instance and the library it is made from (default :func:`fmu_slave`,
        :func:`load_library`: co-simulation).
    """

    def __init__(self, unzip_dirs: Mapping[str, Path], reuse: bool = False,
                 make: Callable[..., FMUSlave] | None = None, load: Callable[[Instance, Path], Any] | None = None
                 ) -> None:
        self.unzip_dirs = unzip_dirs
        self.reuse = reuse
        self.make, self.load = make or fmu_slave, load or load_library
        self.libraries: dict[str, Any] = {}  # component -> its loaded library
        self.kept: dict[str, FMUSlave] = {}  # component -> its instance between runs (reuse)

    def __call__(self, instance: Instance) -> FMUSlave:
        kept = self.kept.get(instance.name)
        if kept is not None and kept.state == "parked":
            return kept
        lib = self.libraries.get(instance.name)
        if lib is None:
            lib = self.libraries[instance.name] = self.load(instance, self.unzip_dirs[instance.name])
        slave = self.make(instance, self.unzip_dirs[instance.name], library=lib)
        if self.reuse:
            slave.reusable = True
            self.kept[instance.name] = slave
        return slave

    def close(self) -> None:
        """Free the kept instances and unload the libraries (best effort: every one is tried)."""
        for slave in self.kept.values():
            try:
                slave.release()
            except Exception:  # noqa: BLE001 -- best effort, as unloading below
                pass
        self.kept.clear()
        for lib in self.libraries.values():
            try:
                lib.freeLibrary()
            except Exception:  # noqa: BLE001 -- best effort
                pass
        self.libraries.clear()


def load_library(instance: Instance, unzip_dir: Path) -> Any:
    """An FMPy ``FMU2Slave`` (``FMU3Slave`` for FMI 3.0) with the FMU's shared library loaded and its
    functions resolved.

    One such object can serve many consecutive instances (fmi2Instantiate ... fmi2FreeInstance)
    of the component, which saves loading and resolving on every run of a sweep.

    Raises
    ------
    SlaveError
        If the shared library cannot be loaded.
    """
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave as FMPyFMU3Slave

    model = instance.model
    fmi3 = model.fmi_version.startswith("3")
    cls = FMPyFMU3Slave if fmi3 else FMU2Slave
    library = None if fmi3 else fmi2_tuple_library(unzip_dir, model.model_identifier)
    try:
        return cls(guid=model.guid, unzipDirectory=str(unzip_dir), modelIdentifier=model.model_identifier,
                   instanceName=instance.name, **({"libraryPath": library} if library else {}))
    except Exception as exc:  # noqa: BLE001 -- fmpy raises bare exceptions
        raise SlaveError(f"component {instance.name} ({model.name}): cannot load the FMU's shared library: {exc}",
                         instance.name, "load") from None


def fmi2_tuple_library(unzip_dir: Path, identifier: str) -> str | None:
    """An FMI 2.0 FMU's library for a machine FMI 2.0 has no folder name for (FMI 2.0 names x86 only:
    ``linux64`` is 64-bit x86), in the FMI 3.0 platform tuple's folder as FMI 2.0.4 (section 2.3) asks,
    e.g. ``binaries/aarch64-linux/`` on 64-bit ARM Linux, where fmpy does not look; None on x86 or
    when the FMU has none there (fmpy's own choice then)."""
    import fmpy

    if fmpy.architecture in ("x86", "x86_64"):
        return None
    path = Path(unzip_dir) / "binaries" / fmpy.platform_tuple / f"{identifier}{fmpy.sharedLibraryExtension}"
    return str(path) if path.is_file() else None


def _fmi_type(t: str) -> str:
    return {"Float64": "Real", "Float32": "Real", "Enumeration": "Integer"}.get(t, t)
