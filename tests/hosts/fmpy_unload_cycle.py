"""Free and unload one pythonfmu FMU again and again while another stays loaded, with fmpy.

    python fmpy_unload_cycle.py KEPT CYCLED CYCLES

KEPT and CYCLED are ``DIR:MODEL_IDENTIFIER:GUID`` of two different FMUs. KEPT is instantiated
first and stepped throughout; CYCLED is instantiated, stepped, terminated and freed CYCLES
times (fmpy's ``freeInstance`` closes the binary). Prints ``unloaded K`` when the CYCLED
binary is no longer mapped after cycle K, then ``kept stepped N`` and exits 0.
"""
from __future__ import annotations

import sys
from pathlib import Path

from fmpy.fmi2 import FMU2Slave


def instantiate(spec: str, name: str) -> tuple[FMU2Slave, Path]:
    unzip_dir, model_id, guid = spec.split(":")
    slave = FMU2Slave(guid=guid, unzipDirectory=unzip_dir, modelIdentifier=model_id, instanceName=name)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, Path(unzip_dir, "binaries", "linux64", model_id + ".so").resolve()


def mapped(binary: Path) -> bool:
    return str(binary) in Path("/proc/self/maps").read_text()


def main(kept_spec: str, cycled_spec: str, cycles: int) -> int:
    kept, _ = instantiate(kept_spec, "kept")
    h, n = 1e-3, 0
    for k in range(cycles):
        cycled, binary = instantiate(cycled_spec, f"cycled{k}")
        for j in range(10):
            cycled.doStep(j * h, h)
            kept.doStep(n * h, h)
            n += 1
        cycled.terminate()
        cycled.freeInstance()
        if not mapped(binary):
            print(f"unloaded {k}", flush=True)
    kept.doStep(n * h, h)
    kept.terminate()
    kept.freeInstance()
    print(f"kept stepped {n + 1}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], int(sys.argv[3])))
