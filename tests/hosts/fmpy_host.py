"""The C host of ``fmi_host.c`` written with fmpy: same command line, same calls in the same order.

    python fmpy_host.py [--keep] STOP STEP SETPOINT CONTROLLER PLANT [SETPOINT CONTROLLER PLANT ...]

Each FMU argument is ``DIR:MODEL_IDENTIFIER:GUID:IN_VRS:OUT_VRS`` (see ``fmi_host.c``). Without
``--keep`` every instance is terminated and freed (fmpy's ``freeInstance`` also closes the
binary) before the process exits; with it the process exits with everything loaded.
Prints ``loop K: v1 v2 ...`` (the plant's outputs at STOP, ``%.17g``) per loop.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field

from fmpy.fmi2 import FMU2Slave


@dataclass
class Fmu:
    slave: FMU2Slave
    inputs: list[int]
    outputs: list[int]
    in_values: list[float] = field(default_factory=list)
    out_values: list[float] = field(default_factory=list)


def _vrs(text: str) -> list[int]:
    return [int(v) for v in text.split(",")] if text else []


def load(spec: str, stop: float) -> Fmu:
    unzip_dir, model_id, guid, ins, outs = spec.split(":")
    slave = FMU2Slave(guid=guid, unzipDirectory=unzip_dir, modelIdentifier=model_id, instanceName=model_id)
    slave.instantiate(loggingOn=True)
    slave.setupExperiment(startTime=0.0, stopTime=stop)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    fmu = Fmu(slave, _vrs(ins), _vrs(outs))
    fmu.out_values = list(slave.getReal(fmu.outputs)) if fmu.outputs else []
    return fmu


def step(fmu: Fmu, t: float, h: float) -> None:
    if fmu.inputs:
        fmu.slave.setReal(fmu.inputs, fmu.in_values)
    fmu.slave.doStep(t, h)
    if fmu.outputs:
        fmu.out_values = list(fmu.slave.getReal(fmu.outputs))


def run_loop(sp: Fmu, ctrl: Fmu, plant: Fmu, ticks: int, h: float) -> None:
    for n in range(ticks):
        t = n * h
        step(sp, t, h)
        plant.in_values = list(ctrl.out_values)
        step(plant, t, h)
        ctrl.in_values = sp.out_values + plant.out_values
        step(ctrl, t, h)


def main(argv: list[str]) -> int:
    keep = bool(argv) and argv[0] == "--keep"
    argv = argv[1:] if keep else argv
    stop, h = float(argv[0]), float(argv[1])
    fmus = [load(spec, stop) for spec in argv[2:]]
    ticks = int(stop / h + 0.5)
    for k in range(0, len(fmus), 3):
        run_loop(fmus[k], fmus[k + 1], fmus[k + 2], ticks, h)
        print(f"loop {k // 3}:", " ".join("%.17g" % v for v in fmus[k + 2].out_values), flush=True)
    if not keep:
        for fmu in fmus:
            fmu.slave.terminate()
            fmu.slave.freeInstance()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
