"""The slave of an FMI 2.0 co-simulation FMU (:class:`FMU2Slave`, see
:class:`~ipcosim.harness.master.fmu_slave.FMUSlave`): the FMI 2.0 calls of the interface of
:mod:`~ipcosim.harness.master.slave`, on the FMU's shared library loaded through FMPy."""
from __future__ import annotations

import ctypes
import math
from typing import Any, Sequence

from ipcosim.harness.master.fmu_slave import FMUSlave, load_library, route_log, unroute
from ipcosim.harness.master.slave import STATUS, WARNING, BoundGetSet, RawDoStep, RawGetSet, SlaveError
from ipcosim.harness.master.system import Variable


class FMU2Slave(FMUSlave):
    """An FMI 2.0 co-simulation FMU instance (see :class:`FMUSlave`)."""

    FMI = "fmi2"

    def instantiate(self) -> None:
        from fmpy import calloc, free  # type: ignore[attr-defined]
        from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions
        from fmpy.logging import addLoggerProxy  # type: ignore[import-not-found]

        if self.state == "parked":  # a clean run's instance, kept: reset instead of instantiating anew
            self._messages.clear()
            self._call(f"{self.FMI}Reset")
            self.state = "instantiated"
            return
        if self._fmu is None:
            self._fmu = load_library(self.instance, self.unzip_dir)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger, self._sink = route_log(self)
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
            unroute(self._sink)
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


def _fmi_type(t: str) -> str:
    return {"Float64": "Real", "Float32": "Real", "Enumeration": "Integer"}.get(t, t)
