"""Master speed, measured side by side in one process on the same ``build/ssp/*.ssp`` archives
(10 s at 1 ms), medians of several interleaved runs:

* ours: ``ipcosim.prepare(ssp).run()`` -- instantiate, initialize, 10 000 steps with
  recording, terminate, free (FMUs extracted once beforehand, as for a sweep);
* floor: a minimal hand-written FMPy loop over the same extracted FMUs with the same
  parameters: ``FMU2Slave`` set/doStep/get per component and step, value references
  resolved once, no recording, same lifecycle; the issue's target is ours <= 1.15x floor;
* libcosim (libcosimpy): the same ``.ssp``, ``simulate_until`` (its Jacobi fixed-step
  algorithm; target ours <= 0.5x);
* FMPy's ``simulate_ssp`` on the same ``.ssp`` where it runs (it ignores parameter bindings,
  so its trajectory differs; only its time is reported);
* real-time factor of ours (simulated / wall seconds; goal >= 20x).
"""
from __future__ import annotations

import statistics
import time
import warnings
from typing import Any

from benchmarks.bench import target
from ipcosim.harness.paths import BUILD_SSP_DIR

SCENARIOS = ("single-mass-lqr", "double-mass-hsmc")
REPEATS = 5
STOP, STEP = 10.0, 1e-3


def floor_loop(prepared: Any, stop: float = STOP, step: float = STEP) -> float:
    """The hand-written FMPy loop on ``prepared``'s extracted FMUs; returns its wall time [s]."""
    from fmpy.fmi2 import FMU2Slave

    system = prepared.system
    execution = prepared.execution(stop, step)  # only for the order and the step multiples
    order = [system.instances[i] for i in execution.order]
    multiple = execution.multiples
    t0 = time.perf_counter()
    fmus: dict[str, Any] = {}
    for inst in system.instances:
        f = FMU2Slave(guid=inst.model.guid, unzipDirectory=str(prepared.unzip_dirs[inst.name]),
                      modelIdentifier=inst.model.model_identifier, instanceName=inst.name)
        f.instantiate()
        f.setupExperiment(startTime=0.0, stopTime=stop)
        reals = [(v.vr, x) for v, x in inst.parameters if v.type == "Real"]
        ints = [(v.vr, int(x)) for v, x in inst.parameters if v.type in ("Integer", "Enumeration")]
        if reals:
            f.setReal([vr for vr, _ in reals], [x for _, x in reals])
        if ints:
            f.setInteger([vr for vr, _ in ints], [x for _, x in ints])
        fmus[inst.name] = f
    for f in fmus.values():
        f.enterInitializationMode()
    for f in fmus.values():
        f.exitInitializationMode()
    # per component: (fmu, input vrs, [(source component, source output index)], output vrs, multiple)
    plan = []
    outputs: dict[str, list[float]] = {}
    for inst in order:
        ins = [v for v in inst.inputs if system.link_into(inst.name, v.name) is not None]
        srcs = []
        for v in ins:
            link = system.link_into(inst.name, v.name)
            src = system.instance(link.src)
            srcs.append((link.src, [o.name for o in src.outputs].index(link.src_var.name)))
        outs = [v.vr for v in inst.outputs]
        outputs[inst.name] = fmus[inst.name].getReal(outs) if outs else []
        plan.append((fmus[inst.name], [v.vr for v in ins], srcs, outs, multiple[inst.name], inst.name))
    n_ticks = round(stop / step)
    for n in range(n_ticks):
        t = n * step
        for f, in_vrs, srcs, out_vrs, m, name in plan:
            if (n + 1) % m:
                continue
            if in_vrs:
                f.setReal(in_vrs, [outputs[c][j] for c, j in srcs])
            f.doStep(t + step - m * step, m * step)
            if out_vrs:
                outputs[name] = f.getReal(out_vrs)
    for f in fmus.values():
        f.terminate()
        f.freeInstance()
    return time.perf_counter() - t0


def _median(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def bench_scenario(name: str, repeats: int = REPEATS) -> list[str]:
    import ipcosim.harness
    from ipcosim.harness.evidence.crosscheck import run_fmpy_ssp, run_libcosim

    ssp = BUILD_SSP_DIR / f"{name}.ssp"
    if not ssp.is_file():
        return [f"{name}: {ssp} missing (run `ipcosim build`)"]
    ours, floor, lib = [], [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prepared = ipcosim.prepare(ssp)
    with prepared:
        prepared.run(STOP, STEP)  # warm-up: imports, first instantiation of each FMU module
        floor_loop(prepared)
        lib_vars = ["plant.pendulum_angle"]
        run_libcosim(ssp, 0.01, STEP, lib_vars)
        for _ in range(repeats):
            result = prepared.run(STOP, STEP)
            ours.append(result.metrics["wall_time_s"])
            floor.append(floor_loop(prepared))
            lib.append(run_libcosim(ssp, STOP, STEP, lib_vars)[1])
    _, fmpy_wall, note = run_fmpy_ssp(ssp, STOP, STEP)
    o, f, lc = _median(ours), _median(floor), _median(lib)
    lines = [
        f"{name}: {STOP:g} s at {STEP * 1e3:g} ms, medians of {repeats}",
        f"  ours (ipcosim.prepare(...).run())        {o:7.3f} s   real-time factor {STOP / o:6.1f}x "
        f"({target(f'{name} real-time factor', STOP / o, 20.0, 'x', at_most=False)})",
        f"  hand-written fmpy loop    {f:7.3f} s   ours/floor    = {o / f:5.2f}x "
        f"({target(f'{name} ours/floor', o / f, 1.15, 'x')})",
        f"  libcosim (libcosimpy)     {lc:7.3f} s   ours/libcosim = {o / lc:5.2f}x "
        f"({target(f'{name} ours/libcosim', o / lc, 0.5, 'x')})",
        (f"  fmpy simulate_ssp         {fmpy_wall:7.3f} s   ours/fmpy     = {o / fmpy_wall:5.2f}x (one run)"
         if note == "ok" else f"  fmpy simulate_ssp         does not run it: {note}"),
    ]
    return lines


def run() -> list[str]:
    lines: list[str] = []
    for name in SCENARIOS:
        lines += bench_scenario(name)
    return lines


if __name__ == "__main__":
    print("\n".join(run()))
