"""The identification replay in C: :func:`ipcosim.fmus.plant.replay`'s simulation, stepped by the native plant.

The native plant's generated ``model.c`` (``ipcosim.harness.native.cgen``, traced from the same Python plant:
DAC codes, computation delay, Karnopp stick-slip, end stops) is compiled with a small hand-written driver
(``c/replay.c``) into one shared library per plant kind: it starts the value array, writes the parameters into
their slots, initializes the model and steps it once per logged voltage, copying the measured positions after
each step. One ctypes call is one simulation of the log. The library is built once per generated source and
compiler (with the native FMUs' flags, ``cbuild.FLAGS``) into ``replay/`` of the build folder and found there
again through the project's build cache (``ipcosim.fmus.pybuild.build_cached``).

The stage coefficients of the integrator depend on the physical parameters (the armature circuit's part of the
Jacobian, ``Plant._circuit_part``): each call recomputes them with :func:`~ipcosim.harness.native.redesign.redesign`,
which also refuses what the native plant does not model (noise, a delay longer than its delay line).
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import tempfile
from dataclasses import asdict, fields, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ipcosim.errors import IpcosimError
from ipcosim.fmus.instruments import Instruments
from ipcosim.fmus.kinds import PLANT_MODELS
from ipcosim.fmus.params import plant_kind_of
from ipcosim.fmus.physics import MEASURED, state_names
from ipcosim.fmus.plant import PlantStepError
from ipcosim.harness.native import cbuild, cgen, exchange, redesign, tracer
from ipcosim.toolchain import find_compiler

DRIVER = "replay.c"


class ReplayUnavailable(IpcosimError, RuntimeError):
    """The native replay cannot run here (no C compiler, or the compile failed): the message says why."""


def replay_library(name: str, source: str, cache: Path | None = None) -> Path:
    """The shared library of the driver compiled with the plant ``name``'s generated ``source`` (built on first
    use into ``cache``, default ``replay/`` of the build folder, then found there by its digest).

    Raises
    ------
    ReplayUnavailable
        No C compiler, or the compiler failed on the sources (its first line).
    """
    from ipcosim.fmus.pybuild import build_cached
    from ipcosim.harness.support.paths import REPLAY_DIR

    cc = find_compiler()
    if cc is None:
        raise ReplayUnavailable("no C compiler found (set CC, or install gcc or clang)")
    folder = Path(cache or REPLAY_DIR)
    h = hashlib.sha256()
    for part in (source, *(cbuild.C_DIR / f for f in (DRIVER, "model.h")), os.path.realpath(cc), *cbuild.FLAGS):
        h.update(part.read_bytes() if isinstance(part, Path) else part.encode())
        h.update(b"\0")
    digest = h.hexdigest()
    so = folder / f"{name}-{digest[:16]}.so"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return build_cached(cbuild.C_DIR / DRIVER, folder, name, digest, build=lambda: _compile(source, so, cc)).fmu
    except (cbuild.NativeBuildError, OSError) as exc:
        raise ReplayUnavailable(f"the native replay of {name} did not compile: {str(exc).splitlines()[0]}") from None


def _compile(source: str, so: Path, cc: str) -> Path:
    """Compile ``model.c`` (``source``) and the driver into ``so``, written under a temporary name and renamed
    into place (parallel identifications may compile the same library); older builds of the plant go."""
    with tempfile.TemporaryDirectory(dir=so.parent) as tmp:
        work = Path(tmp)
        (work / "model.c").write_text(source)
        for name in (DRIVER, "model.h"):
            shutil.copy(cbuild.C_DIR / name, work / name)
        cbuild.compile_sources(work, ["model.c", DRIVER], work / so.name, cc)
        os.replace(work / so.name, so)
    for old in so.parent.glob(f"{so.name.rsplit('-', 1)[0]}-*.so"):
        if old != so:
            old.unlink(missing_ok=True)
    return so


class NativeReplay:
    """The compiled replay of one plant kind; called as :func:`ipcosim.fmus.plant.replay` is.

    Parameters
    ----------
    kind : str
        ``single-mass`` or ``double-mass``.
    fmu_dir : Path, optional
        Where the plant's Python FMU is (its model description names the variables; built there when missing
        or out of date); default: the build folder's ``fmus/``.

    Raises
    ------
    ReplayUnavailable
        See :func:`replay_library`.
    """

    def __init__(self, kind: str, fmu_dir: Path | None = None) -> None:
        from ipcosim.fmus.pybuild import build_all, model_scripts
        from ipcosim.harness.support.paths import BUILD_FMU_DIR

        self.kind = kind
        self.name = next(n for n, k in PLANT_MODELS.items() if k == kind)
        folder = Path(fmu_dir or BUILD_FMU_DIR)
        build_all(folder, scripts=[model_scripts()[self.name]])
        tracer.reset_table()
        try:
            model = cbuild.native_model(self.name, folder)
            source, _ = cgen.model_c(model)
        finally:
            tracer.reset_table()
        self.slots = cgen.layout(model)
        self.info = {"model": self.name, **model.meta}
        self._out = np.array([self.slots[exchange.state_key(m)] for m in MEASURED[kind]], dtype=np.intc)
        lib = ctypes.CDLL(str(replay_library(self.name, source)))
        fn = lib.ipcosim_replay
        ip, dp = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
        fn.argtypes = [ip, dp, ctypes.c_int, ctypes.c_int, dp, ctypes.c_long, ctypes.c_double, ip, ctypes.c_int, dp]
        fn.restype = ctypes.c_long
        self._fn = fn

    def values(self, params: Any, h: float, x0: Sequence[float] | None, instruments: Instruments | None
               ) -> dict[str, float]:
        """The native plant's parameter values of one replay (the integrator's coefficients redesigned for
        ``params`` and ``h``); the encoders' readout is left out as :func:`ipcosim.fmus.plant.replay` leaves it.

        Raises
        ------
        redesign.NativeParameterError
            An instrument the native plant lacks (noise) or a delay longer than its delay line.
        """
        if plant_kind_of(params) != self.kind:
            raise ValueError(f"{plant_kind_of(params)} parameters given to the {self.kind} replay")
        bench = replace(instruments or Instruments(), cart_resolution=0.0, pendulum_resolution=0.0, noise_counts=0.0)
        x0 = [0.0] * len(state_names(self.kind)) if x0 is None else list(x0)
        python = {**asdict(params), **{f.name: float(getattr(bench, f.name)) for f in fields(bench)},
                  **{f"initial_{s}": float(v) for s, v in zip(state_names(self.kind), x0)}, "integrator_step": h}
        return redesign.redesign(self.info, python)

    def __call__(self, params: Any, voltages: Sequence[float], h: float, x0: Sequence[float] | None = None,
                 instruments: Instruments | None = None) -> np.ndarray:
        """The measured positions (``MEASURED`` order, before the encoders): ``len(voltages) + 1`` rows.

        Raises
        ------
        PlantStepError
            The state became non-finite (names the step).
        ValueError
            Parameters the plant refuses (``ipcosim.fmus.params.validate``), or of the other plant kind.
        """
        values = self.values(params, h, x0, instruments)
        slots = np.array([self.slots[f"V:{n}"] for n in values], dtype=np.intc)
        data = np.array([float(v) for v in values.values()])
        u = np.ascontiguousarray(voltages, dtype=float)
        rows = np.empty((len(u) + 1, len(self._out)))
        ip, dp = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
        status = self._fn(slots.ctypes.data_as(ip), data.ctypes.data_as(dp), len(slots), self.slots["V:voltage"],
                          u.ctypes.data_as(dp), len(u), h, self._out.ctypes.data_as(ip), len(self._out),
                          rows.ctypes.data_as(dp))
        if status < 0:
            raise MemoryError("the native replay could not allocate its value array")
        if status > 0:
            raise PlantStepError(f"plant state became non-finite in the step from t = {(status - 1) * h:.6g} s "
                                 f"(h = {h:g} s, voltage = {u[status - 1]:g} V) of the native replay")
        return rows


@functools.lru_cache(maxsize=None)
def native_replay(kind: str) -> NativeReplay:
    """The :class:`NativeReplay` of plant ``kind``, made once per process (the tracing and the library's
    load take a fraction of a second; an identification replays thousands of times).

    Raises
    ------
    ReplayUnavailable
        See :func:`replay_library` (not remembered: the next call tries again).
    """
    return NativeReplay(kind)
