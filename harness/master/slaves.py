"""Which slave a component's FMU gets, and the slaves of many runs of one system: :func:`fmu_slave`
makes an :class:`~ipcosim.harness.master.fmi2_slave.FMU2Slave` for an FMI 2.0 FMU, an
:class:`~ipcosim.harness.master.fmi3_slave.FMU3Slave` for an FMI 3.0 one, or the slave a maker
registered in :data:`SPECIAL_SLAVES` offers (an FMU with clocks: :mod:`~ipcosim.harness.master.clocked`);
:class:`LoadedSlaves` keeps each component's library (and, asked to, its instance) from run to run.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from ipcosim.harness.master.fmi2_slave import FMU2Slave
from ipcosim.harness.master.fmi3_slave import FMU3Slave
from ipcosim.harness.master.fmu_slave import FMUSlave, load_library
from ipcosim.harness.master.system import Instance

#: Makers of the slave of an FMU that needs more than :class:`FMU2Slave` or :class:`FMU3Slave`, asked in
#: turn by :func:`fmu_slave`: ``maker(instance, unzip_dir, logging_on, library)`` -> a slave, or None.
SPECIAL_SLAVES: list[Callable[[Instance, Path, bool, Any], FMUSlave | None]] = []


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
    on first use and kept for the following runs (:func:`~ipcosim.harness.master.fmu_slave.load_library`) and,
    with ``reuse``, each component's instance too, reset between runs instead of instantiated anew
    (:attr:`FMUSlave.reusable`).
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
