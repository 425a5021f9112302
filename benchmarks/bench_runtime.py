"""FMU runtime and whole-run speed (``make bench``), side by side in one run, with the targets:

* cold run: ``ipcosim run single-mass-lqr`` (10 s at 1 ms) as a fresh process, from start to
  exit: wall <= 1.0 s (a quiet two-core machine). The figure is the fastest of ``COLD_RUNS``
  runs (the one least disturbed by other load); the median and the process's CPU time
  (user + system) are printed beside it;
* instantiate-to-initialized of every FMU (``fmi2Instantiate`` .. ``fmi2ExitInitializationMode``
  of the first instance in a fresh process, through fmpy; the HIL adapters against a lockstep
  virtual rig served by this process): <= 50 ms each, fastest of ``INIT_RUNS`` processes;
* plant FMU cycle (``fmi2SetReal`` voltage, ``fmi2DoStep`` 1 ms, ``fmi2GetReal`` outputs) <= 2x
  the same cycle on a trivial pythonfmu FMU, measured in one process (``benchmarks.bench_plant``);
* stepping-loop real-time factor of single-mass LQR (``loop_real_time_factor`` of metrics.json:
  simulated seconds / seconds of the stepping loop) >= 60x, best of ``LOOP_RUNS`` runs, on the
  compiled C loop (the default); beside it, without a target, the same on the Python loop;
* not a target: the number of Python modules inside the largest FMU (``resources/**.py``).

The FMUs are those of ``build/`` (``make bench`` builds them first).
"""
from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from benchmarks.targets import TargetMissed

COLD_RUNS = int(os.environ.get("IPCOSIM_BENCH_COLD_RUNS", "5"))
INIT_RUNS = int(os.environ.get("IPCOSIM_BENCH_INIT_RUNS", "3"))
LOOP_RUNS = int(os.environ.get("IPCOSIM_BENCH_LOOP_RUNS", "5"))
COLD_TARGET_S = 1.0
INIT_TARGET_MS = 50.0
CYCLE_TARGET_RATIO = 2.0
LOOP_TARGET_RTF = 60.0

#: Instantiate and initialize one FMU in a fresh interpreter; prints the milliseconds it took.
INIT_SCRIPT = r'''
import sys, time
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
fmu, unzip, uri = sys.argv[1], sys.argv[2], sys.argv[3]
md = read_model_description(fmu)
extract(fmu, unzipdir=unzip)
slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="bench")
t0, c0 = time.perf_counter(), time.process_time()
slave.instantiate()
if uri:
    slave.setString([next(v.valueReference for v in md.modelVariables if v.name == "card_uri")], [uri])
slave.setupExperiment(startTime=0.0)
slave.enterInitializationMode()
slave.exitInitializationMode()
elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
slave.terminate()
slave.freeInstance()
print(elapsed * 1e3, cpu * 1e3)
'''


def cold_runs(out: Path) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds of ``COLD_RUNS`` fresh ``ipcosim run single-mass-lqr`` processes."""
    exe = Path(sys.executable).with_name("ipcosim")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "ipcosim.harness.cli"]
    walls, cpus = [], []
    for _ in range(COLD_RUNS):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd + ["run", "single-mass-lqr", "--out", str(out), "--quiet"], capture_output=True,
                              text=True)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            raise RuntimeError(f"ipcosim run failed: {proc.stderr.strip().splitlines()[-1:]}")
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


def init_times(fmu_dir: Path, work: Path) -> dict[str, tuple[float, float]]:
    """``{model: (wall ms, CPU ms)}`` from instantiate to initialized of every FMU in ``fmu_dir``
    (the fastest of ``INIT_RUNS`` fresh processes each)."""
    return {fmu.stem: min(_init_ms(fmu, work / f"{fmu.stem}-{k}") for k in range(INIT_RUNS))
            for fmu in sorted(fmu_dir.glob("*.fmu"))}


def _init_ms(fmu: Path, unzip: Path) -> tuple[float, float]:
    """One fresh process: (wall, CPU) milliseconds from instantiate to initialized (a HIL adapter
    against a lockstep virtual rig served by this process)."""
    from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
    from ipcosim.fmus.hil.server import RigServer

    uri, server = "", None
    if fmu.stem.startswith("IP02HIL"):
        plant = "single-mass" if "Single" in fmu.stem else "double-mass"
        server = RigServer(VirtualRig(RigConfig(plant=plant, clock="lockstep")), "127.0.0.1", 0).start()
        uri = f"q4:{server.uri}"
    try:
        proc = subprocess.run([sys.executable, "-c", INIT_SCRIPT, str(fmu), str(unzip), uri],
                              capture_output=True, text=True, timeout=120)
    finally:
        if server is not None:
            server.close()
    if proc.returncode != 0:
        raise RuntimeError(f"{fmu.name}: initialization failed: {proc.stderr.strip().splitlines()[-1:]}")
    wall, cpu = proc.stdout.strip().splitlines()[-1].split()
    return float(wall), float(cpu)


def loop_rtfs(ssp: Path) -> tuple[dict[str, list[float]], float]:
    """``loop_real_time_factor`` of ``LOOP_RUNS`` runs of one prepared scenario on each stepping
    loop (``c``, the default, and ``python``; alternating), and the best simulated seconds per CPU
    second of a whole run on the default loop (reference: less disturbed by other load)."""
    import ipcosim

    rtfs: dict[str, list[float]] = {"c": [], "python": []}
    cpu = []
    with ipcosim.prepare(ssp) as prepared:
        prepared.run()  # warm-up: libraries loaded, modules imported, the C loop compiled
        for _ in range(LOOP_RUNS):
            for loop in rtfs:
                c0 = time.process_time()
                result = prepared.run(loop=loop)
                if loop == "c":
                    cpu.append(time.process_time() - c0)
                if not result.metadata["loop"].startswith(loop):
                    raise RuntimeError(f"{ssp.name}: asked for the {loop} loop, ran {result.metadata['loop']}")
                rtfs[loop].append(result.metrics["loop_real_time_factor"])
    return rtfs, result.metadata["simulated_s"] / min(cpu)


def module_counts(fmu_dir: Path) -> dict[str, tuple[int, int]]:
    """``{model: (Python files under resources/, of them the project's private package)}``."""
    out = {}
    for fmu in fmu_dir.glob("*.fmu"):
        names = [n for n in zipfile.ZipFile(fmu).namelist() if n.startswith("resources/") and n.endswith(".py")]
        out[fmu.stem] = (len(names), sum(1 for n in names if n.startswith("resources/_ipcosim_")))
    return out


def run() -> list[str]:
    """Lines for ``make bench``; raises TargetMissed (after the figures) when a target is missed."""
    from benchmarks import bench_plant
    from ipcosim.fmus.pybuild import ROOT
    from ipcosim.harness.paths import BUILD_SSP_DIR

    fmu_dir = ROOT / "build" / "fmus"
    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-") as tmp:
        walls, cpus = cold_runs(Path(tmp) / "out")
        metrics = json.loads((Path(tmp) / "out" / "metrics.json").read_text())
        inits = init_times(fmu_dir, Path(tmp))
    cycle = bench_plant.measure()
    rtfs, cpu_rtf = loop_rtfs(BUILD_SSP_DIR / "single-mass-lqr.ssp")
    counts = module_counts(fmu_dir)

    cold = min(walls)
    slowest = max(inits, key=lambda k: inits[k][0])
    ratios = {k: cycle[k] / cycle["floor"] for k in ("single-mass", "double-mass")}
    best_rtf = max(rtfs["c"])
    largest = max(counts, key=lambda k: counts[k][0])
    lines = [
        f"cold `ipcosim run single-mass-lqr` (10 s at 1 ms, fresh process): {cold:.3f} s wall, fastest of "
        f"{COLD_RUNS} (median {statistics.median(walls):.3f} s; CPU {min(cpus):.3f} s)   target <= {COLD_TARGET_S:g} s",
        f"instantiate-to-initialized, slowest FMU: {slowest} {inits[slowest][0]:.1f} ms "
        f"(CPU {inits[slowest][1]:.1f} ms)   target <= {INIT_TARGET_MS:g} ms",
        "    " + ", ".join(f"{k} {w:.1f}/{c:.1f}" for k, (w, c) in sorted(inits.items())) + " (wall/CPU ms)",
        f"plant FMU cycle: single mass {cycle['single-mass']:.1f} us = {ratios['single-mass']:.2f}x, double mass "
        f"{cycle['double-mass']:.1f} us = {ratios['double-mass']:.2f}x the trivial pythonfmu FMU's "
        f"{cycle['floor']:.1f} us   target <= {CYCLE_TARGET_RATIO:g}x",
        f"stepping-loop real-time factor, single-mass LQR, C loop (the default): {best_rtf:.1f}x best of {LOOP_RUNS} "
        f"(median {statistics.median(rtfs['c']):.1f}x; whole run per CPU second {cpu_rtf:.1f}x)   target >= "
        f"{LOOP_TARGET_RTF:g}x",
        f"    the same on the Python loop: {max(rtfs['python']):.1f}x best of {LOOP_RUNS} (median "
        f"{statistics.median(rtfs['python']):.1f}x; no target)",
        f"largest FMU: {largest}, {counts[largest][0]} Python modules in resources/ "
        f"({counts[largest][1]} of the project's private package, the rest pythonfmu's and the script)",
    ]
    lines.append(f"metrics.json of the last cold run: wall_time_s {metrics['wall_time_s']:.3f}, real_time_factor "
                 f"{metrics['real_time_factor']:.1f}, loop_real_time_factor {metrics['loop_real_time_factor']:.1f}")
    missed = []
    if cold > COLD_TARGET_S:
        missed.append(f"cold run {cold:.3f} s > {COLD_TARGET_S:g} s")
    missed += [f"{k} initializes in {w:.1f} ms > {INIT_TARGET_MS:g} ms" for k, (w, _) in inits.items()
               if w > INIT_TARGET_MS]
    missed += [f"{k} plant cycle {r:.2f}x > {CYCLE_TARGET_RATIO:g}x the trivial FMU's" for k, r in ratios.items()
               if r > CYCLE_TARGET_RATIO]
    if best_rtf < LOOP_TARGET_RTF:
        missed.append(f"loop real-time factor {best_rtf:.1f}x < {LOOP_TARGET_RTF:g}x")
    if missed:
        raise TargetMissed(lines, missed)
    return lines
