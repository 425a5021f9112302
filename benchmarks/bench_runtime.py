"""Whole runs as a user starts them, and the FMU runtime (``make bench``), side by side in one run.

* **Whole runs**, each a fresh process from start to exit, ``COLD_RUNS`` rounds alternating the four,
  the least disturbed round's CPU time (user + system: what the run costs, the least changed by
  other load on a shared machine; the wall time and the peak memory beside it):

  - the Python flavour: ``ipcosim run build/ssp/single-mass-lqr.ssp`` (10 s at 1 ms, results written),
    against libcosim running the same archive (``from_ssp_file`` + ``simulate_until``, nothing
    recorded) -- targets: its CPU time (the cold run) and its ratio to libcosim's;
  - the native flavour: ``ipcosim run single-mass-lqr --fmus native`` against fmpy's ``simulate_fmu``
    of the same scenario exported as one FMU (``ipcosim export``; 10 s at 1 ms, its outputs
    recorded) -- target: their ratio of CPU times;

* the peak memory of the native run of 600 s against the one of 10 s (results are streamed: target);
* instantiate-to-initialized of every FMU (``fmi2Instantiate`` .. ``fmi2ExitInitializationMode`` of the
  first instance in a fresh process, through fmpy; the HIL adapters against a lockstep virtual rig
  served by this process), fastest of ``INIT_RUNS`` processes: target on the CPU time of the slowest;
* simulated seconds per CPU second of ``Prepared.run`` of single-mass LQR on the Python FMUs, median
  of ``LOOP_RUNS`` runs on the C loop (target) and on the Python loop, beside the wall-clock
  ``loop_real_time_factor``;
* the number of Python modules inside the largest FMU (``resources/**.py``);
* what an instantiate-and-free cycle of a Python FMU (a plant, a controller) leaves in fmpy's process,
  ``CYCLES[1]`` cycles after ``CYCLES[0]`` of warm-up (``tests/hosts/fmpy_instance_cycles.py``): the
  resident memory the process grows by per cycle (target, each FMU; the controller's native flavour,
  fmpy's own, beside them), and the Python heap kept per cycle beyond what the same host keeps for the
  native flavour (target).

The FMUs are those of ``build/`` (``make bench`` builds both flavours first).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Sequence

from benchmarks.targets import figure, least_disturbed, target
from ipcosim.harness.support.threads import single_threaded

COLD_RUNS = int(os.environ.get("IPCOSIM_BENCH_COLD_RUNS", "5"))
INIT_RUNS = int(os.environ.get("IPCOSIM_BENCH_INIT_RUNS", "3"))
LOOP_RUNS = int(os.environ.get("IPCOSIM_BENCH_LOOP_RUNS", "5"))
#: Instantiate-and-free cycles: (warm-up, measured) of each FMU.
CYCLES = (200, int(os.environ.get("IPCOSIM_BENCH_CYCLES", "2000")))
#: Targets: the resident memory fmpy's process grows by per instantiate-and-free cycle of a Python FMU, and the
#: Python heap such a cycle keeps beyond fmpy's own (pythonfmu 0.7.0's wrapper kept every class it made by
#: evaluating the FMU module again at each instantiation; ``ipcosim.fmus.wrapper``, section 3). What the resident
#: memory still grows by is not kept per cycle: pages of the allocator's arenas the process touches for the first
#: time, as with a native FMU (fmpy's own cycle: 170-180 B), and 0-6 B a cycle over the 2,000 cycles after
#: (docs/other-tools.md, "What a host may do with one FMU", gives the measurements).
CYCLE_TARGET_B = 250.0
#: Targets, CPU time. Measured at load 0.5-7 with one BLAS thread and the bytecode compiled: cold
#: run 0.57-0.77 s (the tree the issue was filed at takes the same), python/libcosim 0.43-0.46,
#: native/fmpy 1.4-1.9, slowest initialization 28-44 ms, simulated seconds per CPU second on the C
#: loop 46-51. The CPU time of a process grows with the machine's load (0.57 s at load 4, 0.77 s at
#: load 3 in another minute), so the absolute cold-run limit only catches a gross regression; the
#: ratio to libcosim, measured in the same alternating rounds, is the fine one: 0.25 s of CPU added
#: to the run (+40 %) took it from 0.43 to 0.62. The issue's goal for that ratio, 0.3x, is not
#: reached: see ISSUE_LIBCOSIM_GOAL. The absolute limits (cold run, initialization, C loop) hold at
#: the reference machine speed (``targets.REFERENCE_SPEED_MS``) and scale on a slower machine; at
#: that speed the last run measured cold run 0.59 s, slowest initialization 45 ms, C loop 54x (0.72 s,
#: 55 ms, 44x at 28.1 ms), each limit about a third away.
COLD_TARGET_S = 0.78
LIBCOSIM_RATIO = 0.58
ISSUE_LIBCOSIM_GOAL = 0.3
#: Target: the native run's CPU time at most fmpy's simulate_fmu of the same loop. Met since a run imports only its
#: own law's module (the amplitude bound asks that law alone whether it has a linear model) and no other command's,
#: formats nearly every value of results.csv in exact integer arithmetic instead of the interpreter's big-number
#: dtoa, starts with the cyclic garbage collector off (on, past what the start made, when it steps) and loads
#: neither OpenSSL, difflib, decimal nor the swaps: 0.90x (medians of 15 alternating rounds, load 1: 0.176 s against
#: 0.194 s; the bench's least disturbed of 5 at load 1: 0.93x, 0.169 s against 0.181 s). Before: 1.59x, 1.45x once
#: a run extracted only what it reads, 1.15x once results.csv was formatted in C and the command left without the
#: interpreter's teardown. What fmpy's process still does not pay: ipcosim's own modules, about 43 ms (of which
#: creating the 39 dataclasses on a run's path, 20 ms); the SSP reading, the three FMUs' extraction and loading,
#: the metrics and results.csv, about 40 ms together. simulate_fmu's own stepping, in Python, takes about 70 ms.
FMPY_RATIO = 1.0
INIT_TARGET_MS = 60.0
LOOP_TARGET_RTF = 41.0

#: The environment of every timed process: one BLAS thread, as ``ipcosim`` asks for itself
#: (:mod:`ipcosim.harness.support.threads`), so that neither side's CPU time counts an idle BLAS worker
#: spinning beside the main thread (it doubled the CPU time of an FMU's initialization).
CHILD_ENV = dict(os.environ)
single_threaded(CHILD_ENV)

#: libcosim on an archive, as a process of its own: ``python -c LIBCOSIM_SCRIPT ssp``.
LIBCOSIM_SCRIPT = r'''
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
log_output_level(CosimLogLevel.ERROR)
execution = CosimExecution.from_ssp_file(sys.argv[1], 1_000_000)
sys.exit(0 if execution.simulate_until(10_000_000_000) else 1)
'''
#: fmpy's simulate_fmu, as a process of its own: ``python -c FMPY_SCRIPT fmu``.
FMPY_SCRIPT = r'''
import sys
from fmpy import simulate_fmu
result = simulate_fmu(sys.argv[1], stop_time=10.0, step_size=1e-3, output_interval=1e-3)
sys.exit(0 if len(result) >= 10000 else 1)
'''

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


def process(cmd: Sequence[str]) -> tuple[float, float, float]:
    """One fresh process: (wall s, CPU s, peak resident MB); raises with its last error line if it fails."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(list(cmd), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=CHILD_ENV)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read() if proc.stderr else ""
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd[:4]))}...: exit status {proc.returncode}: "
                           f"{(err.strip().splitlines() or [''])[-1]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def whole_runs(tmp: Path) -> dict[str, dict[str, float]]:
    """Wall, CPU (the least disturbed of ``COLD_RUNS`` alternating rounds) and peak memory of the four whole runs."""
    from ipcosim.harness.api.export import ExportOptions, export
    from ipcosim.harness.support.paths import BUILD_SSP_DIR

    ssp = BUILD_SSP_DIR / "single-mass-lqr.ssp"
    if not ssp.is_file():
        raise FileNotFoundError(f"{ssp} missing (run `ipcosim build`)")
    loop = export(ExportOptions("single-mass-lqr", tmp / "SingleMassLqrLoop.fmu"))
    exe = Path(sys.executable).with_name("ipcosim")
    ipc = [str(exe)] if exe.exists() else [sys.executable, "-m", "ipcosim.harness.cli"]
    cmds = {"python": ipc + ["run", str(ssp), "--out", str(tmp / "py"), "--quiet"],
            "libcosim": [sys.executable, "-c", LIBCOSIM_SCRIPT, str(ssp)],
            "native": ipc + ["run", "single-mass-lqr", "--fmus", "native", "--out", str(tmp / "nat"), "--quiet"],
            "fmpy": [sys.executable, "-c", FMPY_SCRIPT, str(loop)]}
    samples: dict[str, list[tuple[float, float, float]]] = {k: [] for k in cmds}
    compile_package()
    for cmd in cmds.values():
        process(cmd)  # warm-up: the page cache, the C loop's library
    for _ in range(COLD_RUNS):
        for name, cmd in cmds.items():
            samples[name].append(process(cmd))
    out = {name: {"wall": least_disturbed([x[0] for x in s]), "cpu": least_disturbed([x[1] for x in s]),
                  "mb": max(x[2] for x in s)} for name, s in samples.items()}
    _, _, out["native"]["mb_600s"] = process(cmds["native"] + ["--stop-time", "600"])
    return out


def compile_package() -> None:
    """Write the bytecode of ipcosim's own modules, as pip does when it installs the wheel.

    A checkout run with ``PYTHONDONTWRITEBYTECODE`` set (as on some machines) would otherwise
    compile every module again in each timed process (about 0.16 s of CPU), and the cold run
    would time the compiler instead of ipcosim.
    """
    import compileall

    from ipcosim.fmus.pybuild import ROOT

    ok = all(compileall.compile_file(str(f), quiet=1) for f in ROOT.glob("*.py"))
    ok &= all(compileall.compile_dir(str(ROOT / pkg), quiet=1) for pkg in ("fmus", "controllers", "harness"))
    if not ok:
        raise RuntimeError(f"{ROOT}: some of ipcosim's modules do not compile")


def init_times(fmu_dir: Path, work: Path) -> dict[str, tuple[float, float]]:
    """``{model: (wall ms, CPU ms)}`` from instantiate to initialized of every FMU in ``fmu_dir``
    (the fastest of ``INIT_RUNS`` fresh processes each)."""
    return {fmu.stem: min(_init_ms(fmu, work / f"{fmu.stem}-{k}") for k in range(INIT_RUNS))
            for fmu in sorted(fmu_dir.glob("*.fmu"))}


def _init_ms(fmu: Path, unzip: Path) -> tuple[float, float]:
    """One fresh process: (wall, CPU) milliseconds from instantiate to initialized (a HIL adapter
    against a lockstep virtual rig served by this process)."""
    from ipcosim.fmus import kinds
    from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
    from ipcosim.fmus.hil.server import RigServer

    uri, server = "", None
    adapted = [kind for kind in kinds.names() if kinds.get(kind).hil_model == fmu.stem]
    if adapted:  # a plant kind's HIL adapter: a rig of that kind
        server = RigServer(VirtualRig(RigConfig(plant=adapted[0], clock="lockstep")), "127.0.0.1", 0).start()
        uri = f"q4:{server.uri}"
    try:
        proc = subprocess.run([sys.executable, "-c", INIT_SCRIPT, str(fmu), str(unzip), uri],
                              capture_output=True, text=True, timeout=120, env=CHILD_ENV)
    finally:
        if server is not None:
            server.close()
    if proc.returncode != 0:
        raise RuntimeError(f"{fmu.name}: initialization failed: {proc.stderr.strip().splitlines()[-1:]}")
    wall, cpu = proc.stdout.strip().splitlines()[-1].split()
    return float(wall), float(cpu)


def loop_rtfs(ssp: Path) -> dict[str, dict[str, float]]:
    """Medians over ``LOOP_RUNS`` runs of one prepared scenario on each stepping loop (``c``, the
    default, and ``python``; alternating): simulated seconds per CPU second of the run (``cpu``)
    and the wall-clock ``loop_real_time_factor`` (``wall``)."""
    import ipcosim

    rtfs: dict[str, dict[str, list[float]]] = {"c": {"cpu": [], "wall": []}, "python": {"cpu": [], "wall": []}}
    with ipcosim.prepare(ssp) as prepared:
        prepared.run()  # warm-up: libraries loaded, modules imported, the C loop compiled
        for _ in range(LOOP_RUNS):
            for loop, out in rtfs.items():
                c0 = time.process_time()
                result = prepared.run(loop=loop)
                cpu = time.process_time() - c0
                if not result.metadata["loop"].startswith(loop):
                    raise RuntimeError(f"{ssp.name}: asked for the {loop} loop, ran {result.metadata['loop']}")
                out["cpu"].append(result.metadata["simulated_s"] / cpu)
                out["wall"].append(result.metrics["loop_real_time_factor"])
    return {loop: {k: statistics.median(v) for k, v in out.items()} for loop, out in rtfs.items()}


def module_counts(fmu_dir: Path) -> dict[str, tuple[int, int]]:
    """``{model: (Python files under resources/, of them the project's private package)}``."""
    out = {}
    for fmu in fmu_dir.glob("*.fmu"):
        names = [n for n in zipfile.ZipFile(fmu).namelist() if n.startswith("resources/") and n.endswith(".py")]
        out[fmu.stem] = (len(names), sum(1 for n in names if n.startswith("resources/_ipcosim_")))
    return out


def instance_cycles(fmu_dir: Path, native_dir: Path) -> dict[str, dict[str, float]]:
    """``{name: {"rss_per_cycle", "traced_per_cycle", "seconds_per_cycle"}}`` of the plant and the controller
    of single-mass LQR (Python flavour) and of the controller's native flavour (what fmpy keeps itself)."""
    from ipcosim.fmus.pybuild import ROOT

    host = ROOT / "tests" / "hosts" / "fmpy_instance_cycles.py"
    fmus = {"IP02SingleMass": fmu_dir / "IP02SingleMass.fmu", "LQRSingleMass": fmu_dir / "LQRSingleMass.fmu",
            "native LQRSingleMass": native_dir / "LQRSingleMass.fmu"}
    out = {}
    for name, fmu in fmus.items():
        proc = subprocess.run([sys.executable, str(host), str(fmu), *map(str, CYCLES)], capture_output=True,
                              text=True, timeout=3600, env=CHILD_ENV)
        if proc.returncode != 0:
            raise RuntimeError(f"{fmu}: instantiate-and-free cycles failed: {proc.stderr.strip().splitlines()[-1:]}")
        out[name] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


def _cycle_lines(cycles: dict[str, dict[str, float]]) -> list[str]:
    own = {k: v["traced_per_cycle"] - cycles["native LQRSingleMass"]["traced_per_cycle"]
           for k, v in cycles.items() if not k.startswith("native")}
    worst = max(own, key=own.get)

    def rss(k: str, v: dict[str, float]) -> str:
        key, what = f"runtime.instance_cycle_rss_b_{k.replace(' ', '_')}", f"instantiate-and-free cycle of {k} in fmpy"
        first = (figure(key, v["rss_per_cycle"], "B", anchor="fmpy's own cycle", what=f"{what}, resident memory growth")
                 if k.startswith("native") else
                 f"{v['rss_per_cycle']:.0f} B ("
                 + target(key, v["rss_per_cycle"], CYCLE_TARGET_B, "B", what=f"{what}, resident memory growth") + ")")
        return f"{k} {first}"
    return [f"instantiate-and-free cycles in fmpy, {CYCLES[1]} after {CYCLES[0]} of warm-up, the process's resident "
            "memory growth per cycle:",
            *(f"    {rss(k, v)}" for k, v in cycles.items()),
            f"    Python heap kept per cycle beyond fmpy's own, worst {worst} {own[worst]:.0f} B ("
            + target("runtime.instance_cycle_heap_b", own[worst], CYCLE_TARGET_B, "B",
                     what="Python FMU instantiate-and-free cycle in fmpy, Python heap kept beyond fmpy's own") + ")"]


def run() -> list[str]:
    """Lines for ``make bench``."""
    from ipcosim.fmus.pybuild import ROOT
    from ipcosim.harness.support.paths import BUILD_SSP_DIR

    fmu_dir = ROOT / "build" / "fmus"
    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-") as tmp:
        w = whole_runs(Path(tmp))
        inits = init_times(fmu_dir, Path(tmp))
    rtfs = loop_rtfs(BUILD_SSP_DIR / "single-mass-lqr.ssp")
    cycles = instance_cycles(fmu_dir, ROOT / "build" / "fmus-native")
    counts = module_counts(fmu_dir)
    # The excitation FMUs compute one period of their multisine (about 200 lines x 20 000 samples, in
    # plain Python) at initialization, once per identification experiment: a figure of their own,
    # not a regression of the loop FMUs the target was set for.
    looped = [k for k in inits if not k.startswith("Excitation")]
    slowest = max(looped, key=lambda k: inits[k][1])
    excitation = max((k for k in inits if k not in looped), key=lambda k: inits[k][1], default=None)
    largest = max(counts, key=lambda k: counts[k][0])
    py_lib, nat_fmpy = w["python"]["cpu"] / w["libcosim"]["cpu"], w["native"]["cpu"] / w["fmpy"]["cpu"]
    return [
        f"whole runs of single-mass-lqr (10 s at 1 ms), fresh processes, least disturbed of {COLD_RUNS} alternating "
        "rounds:",
        _row(w, "python", "ipcosim run of the .ssp (Python FMUs)") + "; "
        + target("runtime.cold_run_cpu_s", w["python"]["cpu"], COLD_TARGET_S, "s", what="cold run, Python FMUs, CPU",
                 per_speed=True),
        _row(w, "libcosim", "libcosim on the same .ssp") + f"; ours/libcosim {py_lib:.2f}x ("
        + target("runtime.python_over_libcosim", py_lib, LIBCOSIM_RATIO, "x",
                 what="whole run CPU: Python flavour / libcosim")
        + f"; the goal of {ISSUE_LIBCOSIM_GOAL:g}x: {'met' if py_lib <= ISSUE_LIBCOSIM_GOAL else 'not reached'})",
        _row(w, "native", "ipcosim run --fmus native") + "; 600 s instead of 10 s: peak "
        + figure("runtime.native_600s_run_mb", w["native"]["mb_600s"], "MB", what="native run of 600 s, peak memory")
        + " (" + target("runtime.native_600s_over_10s_mb", w["native"]["mb_600s"] / w["native"]["mb"], 1.15, "x",
                        what="peak memory, native run of 600 s / of 10 s (results streamed)") + ")",
        _row(w, "fmpy", "fmpy simulate_fmu of the exported loop FMU") + f"; native/fmpy {nat_fmpy:.2f}x ("
        + target("runtime.native_over_fmpy", nat_fmpy, FMPY_RATIO, "x",
                 what="whole run CPU: native / fmpy simulate_fmu of the exported loop") + ")",
        f"instantiate-to-initialized, slowest FMU: {slowest} CPU {inits[slowest][1]:.1f} ms ("
        + target("runtime.slowest_init_cpu_ms", inits[slowest][1], INIT_TARGET_MS, "ms",
                 what=f"instantiate-to-initialized CPU, {slowest}", per_speed=True)
        + f"; wall {inits[slowest][0]:.1f} ms)",
        "    " + ", ".join(f"{k} {a:.1f}/{c:.1f}" for k, (a, c) in sorted(inits.items())) + " (wall/CPU ms)",
        *([f"    identification excitation {excitation}: CPU "
           + figure("runtime.excitation_init_cpu_ms", inits[excitation][1], "ms",
                    anchor="its multisine table, computed once per experiment",
                    what=f"instantiate-to-initialized CPU, {excitation}")] if excitation else []),
        f"single-mass LQR on the Python FMUs, simulated seconds per CPU second of a run, medians of {LOOP_RUNS}: "
        f"C loop (the default) {rtfs['c']['cpu']:.1f}x ("
        + target("runtime.c_loop_cpu_rtf", rtfs["c"]["cpu"], LOOP_TARGET_RTF, "x", at_most=False,
                 what="Python FMUs, C loop, simulated s per CPU s", per_speed=True) + "), Python loop "
        + figure("runtime.python_loop_cpu_rtf", rtfs["python"]["cpu"], "x",
                 what="Python FMUs, Python loop, simulated s per CPU s")
        + f"; wall-clock loop_real_time_factor {rtfs['c']['wall']:.1f}x and {rtfs['python']['wall']:.1f}x",
        f"largest FMU: {largest}, {counts[largest][0]} Python modules in resources/ "
        f"({counts[largest][1]} of the project's private package, the rest pythonfmu's and the script)",
        *_cycle_lines(cycles),
    ]


def _row(w: dict[str, dict[str, float]], name: str, label: str) -> str:
    return (f"  {label:44s} CPU {figure(f'runtime.{name}_run_cpu_s', w[name]['cpu'], 's', what=f'{label}, CPU')}, "
            f"wall {figure(f'runtime.{name}_run_s', w[name]['wall'], 's', what=f'{label}, wall')}, peak "
            f"{figure(f'runtime.{name}_run_mb', w[name]['mb'], 'MB', what=f'{label}, peak resident memory')}")
