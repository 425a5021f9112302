"""The slave of an FMI 3.0 co-simulation FMU (:class:`FMU3Slave`), with the FMI 2.0-style interface of
:mod:`~ipcosim.harness.master.slave`: ``fmi3DoStep`` and the typed getters and setters adapted to the
FMI 2.0 calling convention; event mode is not used (an FMU with clocks: :mod:`~ipcosim.harness.master.clocked`)."""
from __future__ import annotations

import ctypes
import math
from typing import Any, Callable, Sequence

from ipcosim.harness.master import integers
from ipcosim.harness.master.fmu_slave import FMUSlave, load_library
from ipcosim.harness.master.slave import OK, TERMINATE, WARNING, BoundGetSet, RawDoStep, RawGetSet, SlaveError
from ipcosim.harness.master.system import Variable

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
