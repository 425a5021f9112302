"""Plans for the platform tests' FMI host (``tests/c/loop_host.c``) and the reading of its output.

The host, compiled for each platform (linux64 natively, win64 with mingw-w64 and run under wine,
aarch64 with Debian's cross compiler and run under qemu-user), runs a closed loop of FMUs' shared
libraries from a plan file and prints every output after every tick as its IEEE bits, so two
platforms' runs compare bit for bit (``tests/native/test_win64.py``, ``tests/native/test_aarch64.py``).
"""
from __future__ import annotations

import os
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np

from ipcosim.toolchain import find_cross_compiler

#: The win64 cross compiler and wine to run its DLLs (None where missing: the Windows runs skip).
MINGW = find_cross_compiler()
WINE = next((w for w in (shutil.which("wine64"), "/usr/lib/wine/wine64", shutil.which("wine"))
             if w and os.access(w, os.X_OK)), None)
TICKS = 3000  # 3 s at the scenarios' 1 ms step
#: Binary folder and suffix per (FMI version, platform).
BINARY = {("2.0", "linux64"): ("linux64", ".so"), ("2.0", "win64"): ("win64", ".dll"),
          ("2.0", "aarch64"): ("aarch64-linux", ".so"),
          ("3.0", "linux64"): ("x86_64-linux", ".so"), ("3.0", "win64"): ("x86_64-windows", ".dll"),
          ("3.0", "aarch64"): ("aarch64-linux", ".so")}


def _hex(x: float) -> str:
    return struct.pack(">d", float(x)).hex()


def _binary(fmu: Path, dest: Path, platform: str) -> tuple[Path, str, object]:
    """Extract ``fmu``'s binary for ``platform`` into ``dest``: (library, GUID, model description)."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    folder, suffix = BINARY[(md.fmiVersion, platform)]
    name = f"binaries/{folder}/{md.coSimulation.modelIdentifier}{suffix}"
    dest.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as z:
        lib = dest / Path(name).name
        lib.write_bytes(z.read(name))
    return lib, md.guid, md


def host_path(p: Path, platform: str) -> str:
    """``p`` as the host of ``platform`` names it (wine sees the Linux root as drive Z:)."""
    return f"Z:{p}" if platform == "win64" else str(p)


def _fmu_line(lib: Path, guid: str, multiple: int, md, platform: str) -> str:
    return f"{'fmu3' if md.fmiVersion == '3.0' else 'fmu'} {host_path(lib, platform)} {guid} {multiple}"


def write_plan(spec, dest: Path, platform: str, folder: Path | None = None,
               ticks: int = TICKS) -> tuple[Path, list[str]]:
    """A loop_host plan running the loop of ``spec`` (a ContainerSpec) on ``platform``'s binaries
    (of the FMUs of the same names in ``folder``, if given); returns (plan, column names)."""
    pos = {c.name: k for k, c in enumerate(spec.components)}
    lines, outs, columns, vrs = [], [], [], {}
    for k, c in enumerate(spec.components):
        lib, guid, md = _binary(folder / c.fmu.name if folder else c.fmu, dest / platform / c.name, platform)
        vrs[c.name] = {v.name: v for v in md.modelVariables}
        lines.append(_fmu_line(lib, guid, c.multiple, md, platform))
        for name, value in c.parameters.items():
            v = vrs[c.name][name]
            lines.append(f"set {k} {v.valueReference} {dict(Integer='i', Boolean='b').get(v.type, 'r')} "
                         f"{_hex(value)}")
        for o in c.outputs:
            outs.append(f"out {k} {vrs[c.name][o].valueReference}")
            columns.append(f"{c.name}.{o}")
    for k, c in enumerate(spec.components):
        for i in c.inputs:
            assert i.source is not None, f"{c.name}.{i.name}: an input no connection feeds"
            sc, so = i.source
            lines.append(f"link {k} {vrs[c.name][i.name].valueReference} {pos[sc]} {vrs[sc][so].valueReference} "
                         f"{_hex(i.factor)} {_hex(i.offset)}")
    lines += outs + [f"order {' '.join(str(pos[n]) for n in spec.order)}", f"run {_hex(spec.step)} {ticks}"]
    plan = dest / f"{platform}.plan"
    plan.write_text("\n".join(lines) + "\n")
    return plan, columns


def write_single_plan(fmu: Path, dest: Path, platform: str, step: float, ticks: int) -> tuple[Path, list[str]]:
    """A loop_host plan stepping one FMU (an exported loop) alone; returns (plan, output names)."""
    lib, guid, md = _binary(fmu, dest / platform, platform)
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    lines = [_fmu_line(lib, guid, 1, md, platform), *(f"out 0 {v.valueReference}" for v in outputs),
             "order 0", f"run {_hex(step)} {ticks}"]
    plan = dest / f"{platform}.plan"
    plan.write_text("\n".join(lines) + "\n")
    return plan, [v.name for v in outputs]


def parse(stdout: str) -> np.ndarray:
    """The host's rows (hex IEEE bits) as floats."""
    return np.array([[struct.unpack(">d", bytes.fromhex(x))[0] for x in line.split()]
                     for line in stdout.splitlines() if line.strip()])


def compile_host(cc: str, out: Path, *extra: str) -> Path:
    """``tests/c/loop_host.c`` compiled by ``cc`` into ``out`` (warnings are errors)."""
    from ipcosim.harness.native.cbuild import fmi_header_dir

    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-I", str(fmi_header_dir())]
    subprocess.run([cc, *flags, str(Path(__file__).parent / "c" / "loop_host.c"), "-o", str(out), *extra], check=True)
    return out


def run_host(hosts: dict[str, list[str]], platform: str, plan: Path) -> np.ndarray:
    """Run ``plan`` with the host of ``platform`` (``hosts``: platform -> command prefix)."""
    proc = subprocess.run([*hosts[platform], host_path(plan, platform)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{platform} host: {proc.stderr.strip()[-500:]}"
    return parse(proc.stdout)


def compare(name: str, runs: dict[str, np.ndarray], columns: list[str], tolerance: float) -> float:
    """The largest difference between the two platforms' runs in ``runs`` (printed per column),
    asserted at most ``tolerance``."""
    (pa, a), (pb, b) = runs.items()
    assert a.shape == b.shape and a.shape[0] > 1, (name, a.shape, b.shape)
    diff = np.abs(a - b).max(axis=0)
    print(f"{name}: {pa} vs {pb} max |diff| per column: " + ", ".join(f"{c} {d:.3g}" for c, d in zip(columns, diff)))
    assert diff.max() <= tolerance, f"{name}: {pa} and {pb} differ by {diff.max():.3g}"
    return float(diff.max())


def cart(columns: list[str]) -> str:
    """The motor cart's position output among a loop's ``columns``."""
    return next(c.split(".", 1)[1] for c in columns if c.startswith("plant.") and c.endswith("cart_position"))
