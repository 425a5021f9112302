"""The native FMUs' Windows DLLs, run under wine, against their Linux libraries.

One small FMI 2.0 / 3.0 host (``tests/c/loop_host.c``) is compiled twice, with the system C compiler and
with mingw-w64; it runs a scenario's closed loop (setpoint, law, plant) from the FMUs' binaries,
or an exported loop, of either FMI version, and prints every output after every tick as its IEEE bits. The Windows host
runs the ``win64`` DLLs under wine, the Linux host the ``linux64`` libraries, from the same plan;
the outputs must agree to 1e-12 (the differences seen are printed). Skipped, with the reason,
where the cross compiler or wine is missing.
"""
from __future__ import annotations

import os
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ipcosim.toolchain import find_compiler, find_cross_compiler

ROOT = Path(__file__).resolve().parents[1]
CC, MINGW = find_compiler(), find_cross_compiler()
WINE = next((w for w in (shutil.which("wine64"), "/usr/lib/wine/wine64", shutil.which("wine"))
             if w and os.access(w, os.X_OK)), None)
pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)"),
    pytest.mark.skipif(MINGW is None, reason="no mingw-w64 cross compiler (install gcc-mingw-w64-x86-64)"),
    pytest.mark.skipif(WINE is None, reason="wine is not installed (install wine64)"),
]
SCENARIOS = ("single-mass-lqr", "double-mass-lqr")
TICKS = 3000  # 3 s at the scenarios' 1 ms step
TOLERANCE = 1e-12
#: Binary folder and suffix per (FMI version, platform).
BINARY = {("2.0", "linux64"): ("linux64", ".so"), ("2.0", "win64"): ("win64", ".dll"),
          ("3.0", "linux64"): ("x86_64-linux", ".so"), ("3.0", "win64"): ("x86_64-windows", ".dll")}


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


def _path(p: Path, platform: str) -> str:
    return f"Z:{p}" if platform == "win64" else str(p)


def _fmu_line(lib: Path, guid: str, multiple: int, md, platform: str) -> str:
    return f"{'fmu3' if md.fmiVersion == '3.0' else 'fmu'} {_path(lib, platform)} {guid} {multiple}"


def write_plan(spec, dest: Path, platform: str, folder: Path | None = None) -> tuple[Path, list[str]]:
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
    lines += outs + [f"order {' '.join(str(pos[n]) for n in spec.order)}", f"run {_hex(spec.step)} {TICKS}"]
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


@pytest.fixture(scope="session")
def hosts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """The loop host for each platform, as the command prefix that runs it (wine started once here)."""
    from ipcosim.harness.native.cbuild import fmi_header_dir

    out = tmp_path_factory.mktemp("hosts")
    src = ROOT / "tests" / "c" / "loop_host.c"
    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-I", str(fmi_header_dir())]
    subprocess.run([CC, *flags, str(src), "-o", str(out / "loop_host"), "-ldl"], check=True)
    subprocess.run([MINGW, *flags, str(src), "-o", str(out / "loop_host.exe")], check=True)
    env = {**os.environ, "WINEPREFIX": str(out / "wineprefix"), "WINEDEBUG": "-all"}
    started = subprocess.run([WINE, str(out / "loop_host.exe")], env=env, capture_output=True, text=True, timeout=300)
    if "usage: loop_host" not in started.stderr:
        pytest.skip(f"wine could not start a Windows program here: {started.stderr.strip()[-300:]}")
    os.environ.update(WINEPREFIX=env["WINEPREFIX"], WINEDEBUG="-all")
    return {"linux64": [str(out / "loop_host")], "win64": [WINE, str(out / "loop_host.exe")]}


def run_host(hosts: dict[str, list[str]], platform: str, plan: Path) -> np.ndarray:
    proc = subprocess.run([*hosts[platform], _path(plan, platform)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{platform} host: {proc.stderr.strip()[-500:]}"
    return parse(proc.stdout)


def compare(name: str, linux: np.ndarray, win: np.ndarray, columns: list[str]) -> float:
    assert linux.shape == win.shape and linux.shape[0] > 1, (name, linux.shape, win.shape)
    diff = np.abs(linux - win).max(axis=0)
    print(f"{name}: linux64 vs win64 max |diff| per column: "
          + ", ".join(f"{c} {d:.3g}" for c, d in zip(columns, diff)))
    assert diff.max() <= TOLERANCE, f"{name}: linux64 and win64 differ by {diff.max():.3g}"
    return float(diff.max())


@pytest.mark.parametrize("fmi", ("2", "3"))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_closed_loop_win64_dlls_equal_linux64(scenario: str, fmi: str, hosts, native_fmus, native_fmus3,
                                              tmp_path: Path) -> None:
    from ipcosim.harness.export import ExportOptions, loop_spec

    spec = loop_spec(ExportOptions(scenario, tmp_path / "unused.fmu", fmu_dirs=(native_fmus[1],)))
    assert [c.fmu.stem for c in spec.components][0] == "Setpoint" and len(spec.components) == 3
    results = {}
    for platform in ("linux64", "win64"):
        plan, columns = write_plan(spec, tmp_path, platform, native_fmus3 if fmi == "3" else None)
        results[platform] = run_host(hosts, platform, plan)
    compare(f"{scenario} FMI {fmi}.0", results["linux64"], results["win64"], columns)
    # the host runs the scenario's loop: its Linux rows are the master's (same FMUs, same order)
    import ipcosim

    master = ipcosim.run(scenario, fmus="native", stop_time=TICKS * spec.step, fmu_dirs=[native_fmus[1]]).data
    for j, col in enumerate(columns):
        worst = np.max(np.abs(results["linux64"][:, j] - master[col]))
        assert worst <= 1e-9 * max(1.0, np.abs(master[col]).max()), f"{scenario} {col}: host vs master {worst:.3g}"
    moved = np.abs(results["win64"][:, columns.index(f"plant.{_cart(columns)}")]).max()
    assert moved > 1e-3, f"{scenario}: the cart never moved ({moved})"


def _cart(columns: list[str]) -> str:
    return next(c.split(".", 1)[1] for c in columns if c.startswith("plant.") and c.endswith("cart_position"))


@pytest.mark.parametrize("fmi", ("2", "3"))
def test_exported_loop_win64_dll_equals_linux64(fmi: str, hosts, native_fmus, tmp_path: Path) -> None:
    from ipcosim.harness.export import ExportOptions, export

    fmu = export(ExportOptions("double-mass-lqr", tmp_path / "loop.fmu", fmu_dirs=(native_fmus[1],), fmi=fmi))
    results = {}
    for platform in ("linux64", "win64"):
        plan, names = write_single_plan(fmu, tmp_path, platform, 0.01, 300)
        results[platform] = run_host(hosts, platform, plan)
    compare(f"double-mass-lqr exported, FMI {fmi}.0", results["linux64"], results["win64"], names)
    assert np.abs(results["win64"][:, names.index("plant.passive_cart_position")]).max() > 1e-3
