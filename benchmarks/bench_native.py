"""Native FMUs (``make bench``), side by side in one run:

* the plant cycle through fmpy -- ``fmi2SetReal(voltage)``, ``fmi2DoStep(1 ms)``, ``fmi2GetReal(outputs)`` -- of
  the native ``IP02SingleMass``, of the Python one, and of a trivial native FMU (``Setpoint``: the floor of
  fmpy's ctypes calls), medians over alternating rounds;
* the loop real-time factor of ``single-mass-lqr`` on native FMUs in the ipcosim master, on its compiled C
  stepping loop (the default, target >= 200x) and on its Python loop (no target), and in libcosim
  (``simulate_until`` of 10 s, target >= 2000x);
* a robustness sweep (``plant.Mp`` and ``plant.Beq`` drawn +-20 %, 10 s runs, one worker) on both flavours:
  wall time per run and their ratio (``IPCOSIM_BENCH_SWEEP_RUNS`` runs each, default 10).

FMUs are built into a temporary folder. A missed target ends the module with an error (exit status 1).
"""
from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path
from typing import Callable

ROUNDS = int(os.environ.get("IPCOSIM_BENCH_ROUNDS", "30"))
CYCLES = int(os.environ.get("IPCOSIM_BENCH_CYCLES", "300"))
MASTER_TARGET = 200.0
LIBCOSIM_TARGET = 2000.0
SCENARIO = "single-mass-lqr"
SWEEP_RUNS = int(os.environ.get("IPCOSIM_BENCH_SWEEP_RUNS", "10"))


class TargetMissed(RuntimeError):
    """A speed target of this module was missed."""


def _cycle(fmu: Path, unzip: Path, inputs: dict[str, float], outputs: list[str]) -> Callable[[int], None]:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    extract(str(fmu), unzipdir=str(unzip))
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=fmu.stem)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    in_vr, in_val = [vr[k] for k in inputs], list(inputs.values())
    out_vr = [vr[k] for k in outputs]
    t = [0.0]

    def run(n: int) -> None:
        for _ in range(n):
            if in_vr:
                s.setReal(in_vr, in_val)
            s.doStep(t[0], 1e-3)
            t[0] += 1e-3
            s.getReal(out_vr)
    return run


def _cycles(python: Path, native: Path, tmp: Path) -> dict[str, float]:
    from ipcosim.fmus.physics import state_names

    outs = list(state_names("single-mass"))
    runs = {"native plant": _cycle(native / "IP02SingleMass.fmu", tmp / "n", {"voltage": 0.3}, outs),
            "python plant": _cycle(python / "IP02SingleMass.fmu", tmp / "p", {"voltage": 0.3}, outs),
            "trivial native FMU": _cycle(native / "Setpoint.fmu", tmp / "t", {}, ["reference"])}
    samples: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(ROUNDS):
        for name, fn in runs.items():
            t0 = time.perf_counter()
            fn(CYCLES)
            samples[name].append((time.perf_counter() - t0) / CYCLES * 1e6)
    return {k: statistics.median(v) for k, v in samples.items()}


def _master_rtf(native: Path) -> dict[str, float]:
    """Best loop real-time factor of three runs on each of the master's stepping loops (the
    compiled C loop, the default; the Python loop), alternating."""
    import ipcosim

    best = {"c": 0.0, "python": 0.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(3):
            for loop in best:
                result = ipcosim.run(SCENARIO, fmu_dirs=[native], fmus="native", loop=loop)
                meta = result.metadata
                if not meta["loop"].startswith(loop):
                    raise RuntimeError(f"{SCENARIO}: asked for the {loop} loop, ran {meta['loop']}")
                best[loop] = max(best[loop], (meta["stop_time"] - meta["start_time"]) / meta["loop_wall_time_s"])
    return best


def _libcosim_rtf(folder: Path, step_ns: int = 1_000_000) -> float:
    """Best of three real-time factors of libcosim's ``simulate_until`` over 10 s (1 ms steps by default)."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    best = 0.0
    for _ in range(3):
        execution = CosimExecution.from_ssp_file(str(folder), step_ns)
        t0 = time.perf_counter()
        if not execution.simulate_until(10_000_000_000):
            raise RuntimeError("libcosim: simulation failed")
        best = max(best, 10.0 / (time.perf_counter() - t0))
        execution.stop()
    return best


def _one_fmu_folder(fmu: Path, dest: Path) -> Path:
    """An SSP folder holding one FMU and nothing else."""
    (dest / "resources").mkdir(parents=True)
    shutil.copy(fmu, dest / "resources" / fmu.name)
    (dest / "SystemStructure.ssd").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
        'version="1.0" name="one">\n  <ssd:System name="one">\n    <ssd:Elements>\n'
        f'      <ssd:Component name="{fmu.stem}" type="application/x-fmu-sharedlibrary"'
        f' source="resources/{fmu.name}"/>\n'
        '    </ssd:Elements>\n  </ssd:System>\n  <ssd:DefaultExperiment startTime="0.0" stopTime="10.0"/>\n'
        '</ssd:SystemStructureDescription>\n')
    return dest


def _sweep_ratio(python: Path, native: Path) -> tuple[float, float]:
    """Seconds per run of the same robustness cases on the Python and on the native FMUs."""
    import random

    import ipcosim.harness.scenario.flavour as flavour
    from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, make
    from ipcosim.harness.studies.specs import spec_for

    nominal = make("single-mass", **dict(PRESETS[DEFAULT_PRESET["single-mass"]][1]))
    rng = random.Random(0)
    cases = [{"plant.Mp": nominal.Mp * rng.uniform(0.8, 1.2), "plant.Beq": nominal.Beq * rng.uniform(0.8, 1.2)}
             for _ in range(SWEEP_RUNS)]
    per_run = []
    saved_env, saved_dir = os.environ.get("IPCOSIM_FMU_PATH"), flavour.native_fmu_dir
    os.environ["IPCOSIM_FMU_PATH"] = str(python)
    flavour.native_fmu_dir = lambda: native  # type: ignore[assignment]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for fmus in ("python", "native"):
                runner = spec_for(SCENARIO, fmus=fmus).build()
                t0 = time.perf_counter()
                for i, case in enumerate(cases):
                    runner(case, i)
                per_run.append((time.perf_counter() - t0) / len(cases))
    finally:
        flavour.native_fmu_dir = saved_dir  # type: ignore[assignment]
        if saved_env is None:
            os.environ.pop("IPCOSIM_FMU_PATH", None)
        else:
            os.environ["IPCOSIM_FMU_PATH"] = saved_env
    return per_run[0], per_run[1]


def run() -> list[str]:
    from ipcosim.fmus.pybuild import build_all
    from ipcosim.harness.native.cbuild import build_native

    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        build_all(tmp / "fmus")
        build_native(tmp / "fmus", tmp / "fmus-native")
        c = _cycles(tmp / "fmus", tmp / "fmus-native", tmp)
        master = _master_rtf(tmp / "fmus-native")
        try:
            libcosim: dict[str, float] | None = _libcosim_rtf_native(tmp)
        except ImportError:
            libcosim = None
        sweep_py, sweep_native = _sweep_ratio(tmp / "fmus", tmp / "fmus-native")
    lines = [f"plant cycle (set, doStep 1 ms, get 5 outputs) through fmpy: native {c['native plant']:.2f} us, "
             f"python {c['python plant']:.2f} us ({c['python plant'] / c['native plant']:.0f}x), trivial native "
             f"FMU {c['trivial native FMU']:.2f} us; native plant model cost "
             f"{c['native plant'] - c['trivial native FMU']:.2f} us",
             f"{SCENARIO} on native FMUs, ipcosim master: loop real-time factor {master['c']:.0f}x on the C loop "
             f"(the default; target >= {MASTER_TARGET:g}x: {'ok' if master['c'] >= MASTER_TARGET else 'MISSED'}), "
             f"{master['python']:.0f}x on the Python loop"]
    if libcosim is None:
        lines.append("libcosim: libcosimpy not installed")
    else:
        rtf, floor = libcosim["scenario"], libcosim["floor"]
        lines.append(f"{SCENARIO} on native FMUs, libcosim: real-time factor {rtf:.0f}x (target >= "
                     f"{LIBCOSIM_TARGET:g}x: {'ok' if rtf >= LIBCOSIM_TARGET else 'MISSED'}); libcosim alone with one "
                     f"trivial native FMU: {floor:.0f}x ({1e3 / floor:.1f} us per 1 ms step of its own)")
        lines.append(f"{SCENARIO} exported as one FMU (ipcosim export), libcosim: {libcosim['export 1 ms']:.0f}x at "
                     f"1 ms communication steps, {libcosim['export 10 ms']:.0f}x at 10 ms (ten 1 ms ticks inside "
                     f"each step; the same results)")
    lines.append(f"robustness sweep of {SCENARIO} ({SWEEP_RUNS} runs of 10 s each, one worker): python "
                 f"{sweep_py:.2f} s/run, native {sweep_native:.3f} s/run, ratio {sweep_py / sweep_native:.1f}x "
                 f"(a 1000-run sweep: {1000 * sweep_py / 60:.0f} min vs {1000 * sweep_native / 60:.1f} min)")
    load = os.getloadavg()[0]
    lines.append(f"machine: {os.cpu_count()} cores, load average {load:.1f} during the run (figures scale with it)")
    missed = [line for line in lines if "MISSED" in line]
    if missed:
        for line in lines:
            print(f"   {line}", flush=True)
        raise TargetMissed("; ".join(m.split(":")[0] for m in missed) + ": target missed")
    return lines


def _libcosim_rtf_native(tmp: Path) -> dict[str, float]:
    """libcosim's real-time factors: the scenario folder written for the native FMUs in ``tmp/fmus-native``
    (1 ms steps); one trivial native FMU alone (the floor of libcosim's own per-step cost); the scenario
    exported as one FMU (``ipcosim export``) at 1 ms and at 10 ms communication steps."""
    import ipcosim.harness.scenario.flavour as flavour
    from ipcosim.harness.export import ExportOptions, export

    saved = flavour.native_fmu_dir
    flavour.native_fmu_dir = lambda: tmp / "fmus-native"  # type: ignore[assignment]
    try:
        out = {"scenario": _libcosim_rtf(flavour.write_native_folder(SCENARIO, tmp / "ssp"))}
        loop = export(ExportOptions(SCENARIO, tmp / "SingleMassLqrLoop.fmu"))
    finally:
        flavour.native_fmu_dir = saved  # type: ignore[assignment]
    out["floor"] = _libcosim_rtf(_one_fmu_folder(tmp / "fmus-native" / "Setpoint.fmu", tmp / "floor"))
    folder = _one_fmu_folder(loop, tmp / "one")
    out["export 1 ms"] = _libcosim_rtf(folder)
    out["export 10 ms"] = _libcosim_rtf(folder, 10_000_000)
    return out
