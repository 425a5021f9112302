"""Plant FMU step cost (``make bench``): the cost of one communication step of
``IP02SingleMass`` and ``IP02DoubleMass`` through fmpy -- ``fmi2SetReal(voltage)``,
``fmi2DoStep(h = 1 ms)``, ``fmi2GetReal(every output)`` -- beside the same cycle on a
trivial pythonfmu FMU (one input copied to one output: the floor that pythonfmu, the
embedded interpreter and fmpy's ctypes calls cost) measured in the same run; targets on
their ratio, on the same trivial FMU written on ``ipcosim.fmus.fmi.FmuBase`` (what the shared
plumbing adds) against it, and on the pure ``Plant.do_step``.

Method: all FMUs are built into a temporary folder and instantiated once; then rounds of
``CYCLES`` cycles alternate between the FMUs (so that drifts of the machine hit all of them
alike) and the per-cycle time of the least disturbed rounds (``benchmarks.targets.least_disturbed``,
of ``ROUNDS`` short rounds) is reported.
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path
from typing import Callable

from benchmarks.targets import figure, least_disturbed, target

ROUNDS = int(os.environ.get("IPCOSIM_BENCH_ROUNDS", "250"))
CYCLES = int(os.environ.get("IPCOSIM_BENCH_CYCLES", "40"))
#: Rounds of the pure model step, per kind (about 0.2 ms each).
PURE_ROUNDS = 4 * ROUNDS
H = 1e-3
#: Targets: each cycle / the floor's (both in this run), and the pure model step (measured at load
#: 2-10: FmuBase 1.08-1.09x, plants 2.22-2.29x, Plant.do_step 3.5-3.8 us). The do_step limit holds
#: at the reference machine speed (``targets.REFERENCE_SPEED_MS``; scaled on a slower machine):
#: 3.43-3.46 us there (4.32-4.37 us measured at 29.0 ms), the limit 1.3 times that.
FMUBASE_OVER_FLOOR = 1.4
OVER_FLOOR = {"single-mass": 3.0, "double-mass": 3.0}
PURE_US = {"single-mass": 4.5, "double-mass": 4.5}

TRIVIAL_SCRIPT = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class TrivialBench(Fmi2Slave):
    """One input copied to one output."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous))
        self.register_variable(Real("y", causality=Fmi2Causality.output, variability=Fmi2Variability.continuous))

    def do_step(self, current_time, step_size):
        self.y = self.u
        return True
'''


FMUBASE_SCRIPT = '''
from ipcosim.fmus.fmi import FmuBase


class TrivialFmuBaseBench(FmuBase):
    """One input copied to one output, on ipcosim.fmus.fmi.FmuBase."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_input("u", start=0.0, unit="V", description="input")
        self.add_output("y", unit="V", description="copy of u", initial_depends_on=())

    def step(self, t, h):
        self.y = self.u
'''


def _cycle(fmu_path: Path, input_name: str, workdir: Path) -> tuple[Callable[[int], float], Callable[[], None]]:
    """An fmpy instance of the FMU and a function timing ``n`` cycles (returns seconds)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu_path))
    unzip = extract(str(fmu_path), unzipdir=str(workdir / fmu_path.stem))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=fmu_path.stem)
    slave.instantiate(loggingOn=True)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    if "initial_pendulum_angle" in {v.name for v in md.modelVariables}:
        vr = next(v.valueReference for v in md.modelVariables if v.name == "initial_pendulum_angle")
        slave.setReal([vr], [math.pi])  # hanging: a bounded motion however long the bench runs
    slave.exitInitializationMode()
    vin = [next(v.valueReference for v in md.modelVariables if v.name == input_name)]
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    step = [0]
    set_real, do_step, get_real = slave.setReal, slave.doStep, slave.getReal

    def timed(n: int) -> float:
        k = step[0]
        t0 = time.perf_counter()
        for j in range(k, k + n):
            set_real(vin, [2.0 * math.sin(0.01 * j)])
            do_step(j * H, H)
            get_real(outs)
        elapsed = time.perf_counter() - t0
        step[0] = k + n
        return elapsed

    def close() -> None:
        slave.terminate()
        slave.freeInstance()

    return timed, close


def _pure_stepper(kind: str) -> Callable[[int], float]:
    """A function timing round ``r`` of ``CYCLES`` pure ``Plant.do_step`` calls of plant ``kind`` [us per step]."""
    from ipcosim.fmus.params import DEFAULT_PRESET, preset
    from ipcosim.fmus.plant import Plant

    plant = Plant(preset(DEFAULT_PRESET[kind]))
    x = plant.x.copy()
    x[plant.state_names.index("pendulum_angle")] = math.pi
    plant.set_state(x)

    def timed(r: int) -> float:
        t0 = time.perf_counter()
        for j in range(r * CYCLES, (r + 1) * CYCLES):
            plant.do_step(j * H, H, 2.0 * math.sin(0.01 * j))
        return (time.perf_counter() - t0) / CYCLES * 1e6

    return timed


def _pure_plants_us() -> dict[str, float]:
    """The least disturbed pure ``Plant.do_step`` of both kinds [us], in alternating rounds (as the FMU cycles
    are measured) spread over about a second, so that a stall of a shared machine (one measured run had every
    one of 250 consecutive rounds of one kind slowed 2.3 times, the other kind's not) slows both kinds alike."""
    from ipcosim.fmus.params import KINDS

    steppers = {kind: _pure_stepper(kind) for kind in KINDS}
    samples: dict[str, list[float]] = {kind: [] for kind in steppers}
    for r in range(PURE_ROUNDS):
        for kind, timed in steppers.items():
            samples[kind].append(timed(r))
    return {f"{kind}-pure": least_disturbed(s) for kind, s in samples.items()}


def measure() -> dict[str, float]:
    """Median microseconds per cycle for 'floor', 'fmubase' and each plant kind (+ '<kind>-pure')."""
    from pythonfmu import FmuBuilder

    from ipcosim.fmus import kinds, wrapper
    from ipcosim.fmus.pybuild import build_all, model_scripts

    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-") as tmp:
        work = Path(tmp)
        script = work / "fmu_trivial_bench.py"
        script.write_text(TRIVIAL_SCRIPT)
        trivial = Path(FmuBuilder.build_FMU(script, dest=work / "fmus"))
        wrapper.patch_fmu(trivial)  # as every project FMU: pythonfmu 0.7.0's exit-time double free
        base_script = work / "fmu_trivial_fmubase_bench.py"
        base_script.write_text(FMUBASE_SCRIPT)
        (base,) = build_all(work / "fmus", scripts=[base_script])
        models = {kind: kinds.get(kind).model for kind in kinds.names()}
        scripts = model_scripts()
        plants = {r.fmu.stem: r.fmu for r in build_all(work / "fmus", scripts=[scripts[m] for m in models.values()])}
        cases = {"floor": _cycle(trivial, "u", work),
                 "fmubase": _cycle(base.fmu, "u", work),
                 **{kind: _cycle(plants[model], "voltage", work) for kind, model in models.items()}}
        try:
            for timed, _ in cases.values():  # warm-up
                timed(CYCLES)
            samples: dict[str, list[float]] = {name: [] for name in cases}
            for _ in range(ROUNDS):
                for name, (timed, _) in cases.items():
                    samples[name].append(timed(CYCLES) / CYCLES * 1e6)
        finally:
            for _, close in cases.values():
                close()
    return {**{name: least_disturbed(s) for name, s in samples.items()}, **_pure_plants_us()}


def run() -> list[str]:
    """Lines for ``make bench``."""
    from ipcosim.fmus.params import KINDS

    m = measure()
    floor = m["floor"]
    lines = [f"plant FMU cycle through fmpy (setReal voltage, doStep h = 1 ms, getReal all outputs), "
             f"least disturbed of {ROUNDS} rounds of {CYCLES} cycles:",
             "floor (trivial pythonfmu FMU, 1 in / 1 out): "
             + figure("plant.floor_cycle_us", floor, "us", anchor="pythonfmu's wrapper and fmpy's ctypes calls",
                      what="trivial pythonfmu FMU cycle (the floor)"),
             f"same on ipcosim.fmus.fmi.FmuBase:            {m['fmubase']:7.1f} us  (plumbing adds "
             f"{figure('plant.fmubase_added_us', m['fmubase'] - floor, 'us', what='FmuBase plumbing over the floor')}; "
             + target("plant.fmubase_over_floor", m["fmubase"] / floor, FMUBASE_OVER_FLOOR, "x",
                      what="FmuBase trivial FMU / pythonfmu trivial FMU") + ")"]
    for kind in KINDS:
        key = kind.replace("-", "_")
        ratio = m[kind] / floor
        cycle = figure(f"plant.{key}_cycle_us", m[kind], "us", what=f"{kind} plant FMU cycle")
        lines.append(f"{kind:<12} plant FMU: {cycle} = {ratio:.2f}x the floor ("
                     + target(f"plant.{key}_over_floor", ratio, OVER_FLOOR[kind], "x",
                              what=f"{kind} plant FMU cycle / trivial FMU cycle")
                     + f"); pure Plant.do_step {m[kind + '-pure']:5.1f} us ("
                     + target(f"plant.{key}_do_step_us", m[kind + "-pure"], PURE_US[kind], "us",
                              what=f"{kind} Plant.do_step", per_speed=True) + ")")
    return lines
