"""Native FMUs (``make bench``), side by side in one run, on ``build/fmus-native`` and ``build/fmus``
(``make bench`` builds both):

* the plant cycle through fmpy -- ``fmi2SetReal(voltage)``, ``fmi2DoStep(1 ms)``, ``fmi2GetReal(outputs)`` -- of
  the native ``IP02SingleMass``, of the Python one, and of a trivial native FMU (``Setpoint``: the floor of
  fmpy's ctypes calls), the least disturbed of many short alternating rounds
  (``benchmarks.targets.least_disturbed``); target on the native plant against that floor;
* a robustness sweep (``plant.Mp`` and ``plant.Beq`` drawn +-20 %, 10 s runs, one worker) on both flavours,
  runs alternating: CPU time per run, the least disturbed of the runs (target on the native one; CPU
  time is the least changed by other load) and their ratio;
* libcosim on the native FMUs (``simulate_until`` of 10 s): the scenario's folder, the scenario exported as
  one FMU (``ipcosim export``) at 1 ms and 10 ms communication steps -- reference figures, read against
  libcosim alone with one trivial native FMU (its own per-step cost, which caps them).

The master's loops on native FMUs are measured in ``benchmarks.bench_master`` (against their floors), the
whole native run in ``benchmarks.bench_runtime``.
"""
from __future__ import annotations

import os
import random
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path
from typing import Callable

from benchmarks.targets import figure, least_disturbed, target

ROUNDS = int(os.environ.get("IPCOSIM_BENCH_ROUNDS", "250"))
CYCLES = int(os.environ.get("IPCOSIM_BENCH_CYCLES", "50"))
SCENARIO = "single-mass-lqr"
SWEEP_RUNS = int(os.environ.get("IPCOSIM_BENCH_SWEEP_RUNS", "10"))
#: Targets: the native plant cycle / the trivial native FMU's (measured 1.8-1.9x); the native sweep's
#: CPU seconds per 10 s run, the least disturbed run (medians measured 0.011-0.015 s at load 2-14;
#: 0.0100 s at the reference machine speed, ``targets.REFERENCE_SPEED_MS``: 0.0122 s at 27.9 ms; the
#: limit scales on a slower machine).
PLANT_OVER_TRIVIAL, SWEEP_NATIVE_S = 2.4, 0.013


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
    return {k: least_disturbed(v) for k, v in samples.items()}


def _libcosim_rtf(folder: Path, step_ns: int = 1_000_000) -> float:
    """Median of three real-time factors of libcosim's ``simulate_until`` over 10 s (1 ms steps by default)."""
    from ipcosim.harness.support.extras import require

    require("libcosimpy")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    rtfs = []
    for _ in range(3):
        execution = CosimExecution.from_ssp_file(str(folder), step_ns)
        t0 = time.perf_counter()
        if not execution.simulate_until(10_000_000_000):
            raise RuntimeError(f"libcosim: simulation of {folder} failed")
        rtfs.append(10.0 / (time.perf_counter() - t0))
        execution.stop()
    return statistics.median(rtfs)


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


def _sweep(runs: int = SWEEP_RUNS) -> dict[str, float]:
    """CPU seconds per run (the least disturbed run) of the same robustness cases on the Python and the
    native FMUs, alternating."""
    from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, make
    from ipcosim.harness.studies.specs import spec_for

    nominal = make("single-mass", **dict(PRESETS[DEFAULT_PRESET["single-mass"]][1]))
    rng = random.Random(0)
    cases = [{"plant.Mp": nominal.Mp * rng.uniform(0.8, 1.2), "plant.Beq": nominal.Beq * rng.uniform(0.8, 1.2)}
             for _ in range(runs)]
    samples: dict[str, list[float]] = {"python": [], "native": []}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runners = {fmus: spec_for(SCENARIO, fmus=fmus).build() for fmus in samples}
        for i, case in enumerate(cases):
            for fmus, runner in runners.items():
                t0 = time.process_time()
                row = runner(case, i)
                samples[fmus].append(time.process_time() - t0)
                if row.get("status", "ok") != "ok":
                    raise RuntimeError(f"sweep run {i} on the {fmus} FMUs: {row.get('error')}")
    return {k: least_disturbed(v) for k, v in samples.items()}


def _libcosim(tmp: Path, native: Path) -> dict[str, float]:
    """libcosim's real-time factors on the native FMUs: the scenario's folder, one trivial FMU alone
    (libcosim's own per-step cost), the scenario exported as one FMU at 1 ms and at 10 ms steps."""
    from ipcosim.harness.api.export import ExportOptions, export
    from ipcosim.harness.scenario.flavour import write_native_folder

    out = {"scenario": _libcosim_rtf(write_native_folder(SCENARIO, tmp / "ssp")),
           "floor": _libcosim_rtf(_one_fmu_folder(native / "Setpoint.fmu", tmp / "floor"))}
    folder = _one_fmu_folder(export(ExportOptions(SCENARIO, tmp / "SingleMassLqrLoop.fmu")), tmp / "one")
    out["export 1 ms"] = _libcosim_rtf(folder)
    out["export 10 ms"] = _libcosim_rtf(folder, 10_000_000)
    return out


def run() -> list[str]:
    """Lines for ``make bench``."""
    from ipcosim.harness.scenario.flavour import native_fmu_dir
    from ipcosim.harness.support.paths import BUILD_DIR

    native, python = native_fmu_dir(), Path(BUILD_DIR) / "fmus"
    for folder in (native, python):
        if not (folder / "IP02SingleMass.fmu").is_file():
            raise FileNotFoundError(f"{folder}/IP02SingleMass.fmu missing (run `ipcosim build --native`)")
    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-") as d:
        c = _cycles(python, native, Path(d))
        lib = _libcosim(Path(d), native)
    sweep = _sweep()
    plant, trivial = c["native plant"], c["trivial native FMU"]
    anchor = f"libcosim alone with one trivial native FMU: {lib['floor']:.0f}x"
    f = {"floor": figure("native.libcosim_floor_rtf", lib["floor"], "x", what="libcosim, one trivial native FMU"),
         "native": figure("native.plant_cycle_us", plant, "us", what="native plant cycle through fmpy"),
         "python": figure("native.python_plant_cycle_us", c["python plant"], "us",
                          what="Python plant cycle through fmpy"),
         "trivial": figure("native.trivial_cycle_us", trivial, "us", anchor="fmpy ctypes calls",
                           what="trivial native FMU cycle"),
         "over": target("native.plant_over_trivial", plant / trivial, PLANT_OVER_TRIVIAL, "x",
                        what="native plant cycle / trivial native FMU cycle"),
         "py/nat": figure("native.python_over_native_cycle", c["python plant"] / plant, "x",
                          what="plant cycle: Python / native"),
         "sweep py": figure("native.sweep_python_s", sweep["python"], "s", what="Python sweep, CPU s per run"),
         "sweep nat": target("native.sweep_native_s", sweep["native"], SWEEP_NATIVE_S, "s",
                             what="native sweep, CPU s per run", per_speed=True),
         "sweep ratio": figure("native.sweep_ratio", sweep["python"] / sweep["native"], "x",
                               what="sweep: Python / native"),
         "lib": figure("native.libcosim_rtf", lib["scenario"], "x", anchor=anchor,
                       what="libcosim, native FMUs, real-time factor"),
         "lib 1": figure("native.libcosim_export_1ms_rtf", lib["export 1 ms"], "x", anchor=anchor,
                         what="libcosim, exported loop, 1 ms steps"),
         "lib 10": figure("native.libcosim_export_10ms_rtf", lib["export 10 ms"], "x", anchor=anchor,
                          what="libcosim, exported loop, 10 ms steps")}
    return [
        f"plant cycle (set, doStep 1 ms, get 5 outputs) through fmpy, least disturbed of {ROUNDS} x {CYCLES}: native "
        f"{f['native']}, python {f['python']}, trivial native FMU {f['trivial']}",
        f"  native plant / trivial native FMU {plant / trivial:.2f}x ({f['over']}); python plant / native plant "
        f"{f['py/nat']}",
        f"robustness sweep of {SCENARIO} ({SWEEP_RUNS} runs of 10 s each, one worker, least disturbed CPU time): "
        f"python {f['sweep py']}/run, native {sweep['native']:.4f} s/run ({f['sweep nat']}); "
        f"python/native {f['sweep ratio']}",
        f"libcosim on native FMUs (reference, capped by libcosim's own step cost: {f['floor']} real time, "
        f"{1e3 / lib['floor']:.1f} us per 1 ms step of its own):",
        f"  {SCENARIO} folder, 1 ms: {f['lib']} real time",
        f"  exported as one FMU (ipcosim export): {f['lib 1']} at 1 ms steps, {f['lib 10']} at 10 ms "
        "(ten 1 ms ticks inside each step; the same results)",
    ]
