"""Helpers for tests that drive real FMUs through fmpy: an instance with a capturing logger."""
from __future__ import annotations

import shutil
import subprocess
from ctypes import byref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)
from fmpy.logging import addLoggerProxy

_COUNTER = [0]


@dataclass
class LoggedFmu:
    """An fmpy FMU2Slave instantiated with logging on; ``messages`` collects (status, category, text)."""

    slave: FMU2Slave
    vr: dict[str, int]
    messages: list[tuple[int, str, str]] = field(default_factory=list)
    callbacks: Any = None  # keeps the ctypes callbacks alive

    def set(self, **values: float) -> None:
        for name, value in values.items():
            self.slave.setReal([self.vr[name]], [float(value)])

    def get(self, *names: str) -> list[float]:
        return self.slave.getReal([self.vr[n] for n in names])

    def text(self) -> str:
        return "\n".join(m[2] for m in self.messages)


def instantiate(fmu: Path, unzip_dir: Path | None = None, logging_on: bool = True) -> LoggedFmu:
    """Extract (once per ``unzip_dir``) and instantiate an FMU with a capturing logger."""
    md = read_model_description(str(fmu))
    if unzip_dir is None or not (unzip_dir / "modelDescription.xml").exists():
        unzip_dir = Path(extract(str(fmu), unzipdir=str(unzip_dir) if unzip_dir else None))
    _COUNTER[0] += 1
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip_dir), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=f"test{_COUNTER[0]}")
    logged = LoggedFmu(slave=slave, vr={v.name: v.valueReference for v in md.modelVariables})

    def logger(env, name, status, category, message):  # noqa: ANN001 -- ctypes callback
        logged.messages.append((int(status), (category or b"").decode(), (message or b"").decode()))

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(cb))
    logged.callbacks = (cb, logger)
    slave.instantiate(loggingOn=logging_on, callbacks=cb)
    return logged


def vdmcheck_script(root: Path) -> Path | None:
    """The VDMCheck2 launcher unpacked by ``make vdmcheck``, if present."""
    hits = sorted((root / "tools" / "vdmcheck").glob("vdmcheck-*/VDMCheck2.sh"))
    return hits[-1] if hits else None


def java_available() -> bool:
    return shutil.which("java") is not None


ROOT = Path(__file__).resolve().parents[1]


def assert_vdmcheck_clean(fmu: Path) -> None:
    """Run VDMCheck2 on ``fmu`` and fail on any finding; skip where Java (or the tool and Maven) is absent."""
    import pytest

    if not java_available():
        pytest.skip("java not installed: VDMCheck2 cannot run")
    script = vdmcheck_script(ROOT)
    if script is None:
        if shutil.which("mvn") is None:
            pytest.skip("VDMCheck2 not fetched and mvn not installed (make vdmcheck)")
        pytest.fail("VDMCheck2 missing: run `make vdmcheck`")
    out = subprocess.run([str(script), str(fmu)], capture_output=True, text=True, timeout=300)
    assert "No errors found" in out.stdout, out.stdout + out.stderr


def loaded_copies(module_suffix: str) -> list:
    """Every loaded copy of a project module: the host's (``ipcosim.<suffix>``) and each FMU's
    private one (``_ipcosim_<model>_<hash>.<suffix>``, see ``ipcosim.fmus.pybuild``)."""
    import sys

    return [m for name, m in list(sys.modules.items())
            if m is not None and (name == f"ipcosim.{module_suffix}"
                                  or (name.startswith("_ipcosim_") and name.split(".", 1)[-1] == module_suffix))]


def open_tcpip_cards() -> list:
    """The TCP/IP cards open in this process, in the host or inside any FMU."""
    return [card for m in loaded_copies("fmus.hil.tcpip") for card in list(m.OPEN_CARDS)]


def private_resource(names: list[str], path: str) -> bool:
    """True if the FMU archive listing ``names`` carries ``path`` (e.g. ``fmus/fmi.py``) in its
    private runtime package ``resources/_ipcosim_<model>_<hash>/``."""
    import re

    pattern = re.compile(r"resources/_ipcosim_[a-z0-9_]+_[0-9a-f]{10}/" + re.escape(path) + "$")
    return any(pattern.match(n) for n in names)


def wait_for(predicate, limit: float = 20.0, poll: float = 0.005) -> bool:
    """Poll ``predicate`` until it holds (True) or ``limit`` seconds of wall time pass (its last
    value): for outcomes another process or thread brings about, generous on a busy machine."""
    import time

    end = time.monotonic() + limit
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll)
    return predicate()
