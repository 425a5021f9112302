"""The slaves of an extracted FMU, loaded through FMPy, whose shared library's functions are called
directly: what they share whatever their FMI version (:class:`FMUSlave`: the log, the lifecycle calls
common to both, freeing and reuse) and the loading of the FMU's library (:func:`load_library`). The
interface they implement is :class:`~ipcosim.harness.master.slave.Slave`; the slave of each FMI
version is :mod:`~ipcosim.harness.master.fmi2_slave`'s and :mod:`~ipcosim.harness.master.fmi3_slave`'s,
which one a component gets :mod:`~ipcosim.harness.master.slaves`' :func:`~ipcosim.harness.master.slaves.fmu_slave`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ipcosim.harness.master import integers
from ipcosim.harness.master.slave import ERROR, STATUS, WARNING, Slave, SlaveError
from ipcosim.harness.master.system import Instance, Variable

_LOGGER: Any = None
_SINKS: dict[int, "FMUSlave"] = {}
_SINK_COUNTER = [0]


def _route_log(env: Any, instance_name: bytes | None, status: int, category: bytes | None,
               message: bytes | None) -> None:
    """The process-wide FMI logger callback: hands a message to the slave that logged it."""
    slave = _SINKS.get(env if isinstance(env, int) else getattr(env, "value", None))
    if slave is not None:
        slave._log(env, instance_name, status, category, message)


def route_log(slave: "FMUSlave") -> tuple[Any, int]:
    """The process-wide FMI 2.0 logger callback and the ``componentEnvironment`` that routes its messages
    to ``slave`` (until :func:`unroute`): fmpy's logger proxy keeps one Python logger for the whole
    process, so every FMU's messages go to the same function, which routes them by componentEnvironment."""
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    global _LOGGER
    if _LOGGER is None:
        _LOGGER = fmi2CallbackLoggerTYPE(_route_log)
    _SINK_COUNTER[0] += 1
    _SINKS[_SINK_COUNTER[0]] = slave
    return _LOGGER, _SINK_COUNTER[0]


def unroute(sink: int | None) -> None:
    """No more messages to the slave of ``sink`` (:func:`route_log`)."""
    _SINKS.pop(sink, None)


class FMUSlave(Slave):
    """What the slaves of an extracted FMU (loaded through FMPy) share, whatever its FMI version:
    the log, the calls of the lifecycle common to both, freeing and reuse. Made by
    :func:`~ipcosim.harness.master.slaves.fmu_slave`, which picks
    :class:`~ipcosim.harness.master.fmi2_slave.FMU2Slave` or
    :class:`~ipcosim.harness.master.fmi3_slave.FMU3Slave` by the model's FMI version.

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
        unroute(getattr(self, "_sink", None))
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
