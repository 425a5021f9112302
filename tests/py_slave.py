"""A slave implemented in Python with the FMU calling convention of
:class:`ipcosim.harness.master.slave.Slave`: the master's tests drive it instead of an FMU."""
from __future__ import annotations

from typing import Any, Callable, Sequence

from ipcosim.harness.master import integers
from ipcosim.harness.master.slave import DISCARD, ERROR, OK, BoundGetSet, RawDoStep, RawGetSet, Slave
from ipcosim.harness.master.system import Instance, Variable


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

    def channel(self, value_type: str, variables: Sequence[Variable]) -> tuple[BoundGetSet, BoundGetSet]:
        vrs = [v.vr for v in variables]
        types = [v.type for v in variables]
        convert: Callable[[Any, str], Any] = {
            "integer": lambda x, t: integers.stored(int(x), t), "boolean": lambda x, t: 1 if x else 0,
            "string": lambda x, t: x if isinstance(x, bytes) else str(x).encode()}[value_type]

        def get(buf: Any) -> int:
            self.on_get()
            values = [convert(self.values[vr], t) for vr, t in zip(vrs, types)]
            if isinstance(buf, list):
                buf[:] = values
            else:
                for i, x in enumerate(values):
                    buf[i] = x
            return OK

        def put(buf: Any) -> int:
            for i, vr in enumerate(vrs):
                x = buf[i]
                if value_type == "integer":
                    x = integers.value(int(x), types[i])
                self.values[vr] = bool(x) if value_type == "boolean" else (x.decode() if isinstance(x, bytes) else x)
            return OK

        return get, put

    def terminated(self) -> tuple[bool, str]:
        flag = bool(getattr(self, "terminate_requested", False))
        return flag, f"the status query returned {'true' if flag else 'false'}"
