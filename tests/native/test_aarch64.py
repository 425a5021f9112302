"""The native FMUs' 64-bit ARM libraries, run under qemu-user, against their x86-64 Linux libraries.

The FMI host of the platform tests (``tests/c/loop_host.c``, its plans in ``tests/loop_plans.py``) is
compiled twice, with the system C compiler and with Debian's aarch64 GNU/Linux cross compiler; the ARM
host runs under ``qemu-aarch64`` (user mode: each ARM instruction emulated, the ARM C library loaded from
the cross sysroot) and loads the FMUs' ``aarch64-linux`` libraries, the x86-64 host their ``linux64`` /
``x86_64-linux`` ones, from the same plan: a scenario's closed loop (setpoint, law, plant) of both
plants, and an exported loop, each as FMI 2.0 and 3.0. Both builds compile the same sources with
floating-point contraction off (``-ffp-contract=off``: no fused multiply-add, which aarch64 has and
baseline x86-64 has not), IEEE 754 double arithmetic is the same on both, and the C libraries' ``sin``,
``cos`` and ``exp`` round alike on the values met here, so the outputs must be identical, bit for bit.
Skipped, with the reason, where the cross compiler, the ARM C library or qemu-user is missing.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from loop_plans import TICKS, cart, compare, compile_host, run_host, write_plan, write_single_plan

from ipcosim.toolchain import find_compiler, find_cross_compiler

CC, ARM_CC = find_compiler(), find_cross_compiler("aarch64")
QEMU = shutil.which("qemu-aarch64")
#: The ARM C library qemu loads the host's dependencies from (Debian's libc6-arm64-cross).
SYSROOT = Path(os.environ.get("QEMU_LD_PREFIX", "/usr/aarch64-linux-gnu"))
pytestmark = [
    pytest.mark.integration,
    pytest.mark.cross,
    pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)"),
    pytest.mark.skipif(ARM_CC is None, reason="no aarch64 cross compiler (install gcc-aarch64-linux-gnu)"),
    pytest.mark.skipif(not (SYSROOT / "lib" / "libc.so.6").is_file(),
                       reason=f"no ARM C library in {SYSROOT} (install libc6-dev-arm64-cross)"),
    pytest.mark.skipif(QEMU is None, reason="qemu-user is not installed (install qemu-user)"),
]
SCENARIOS = ("single-mass-lqr", "double-mass-lqr")
#: Identical. With contraction on (``-ffp-contract=fast``) the ARM libraries of these loops differ from the
#: x86-64 ones by up to 7e-13 in the voltage within 3 s: this test fails if the flag is lost.
TOLERANCE = 0.0
EM_AARCH64 = 183  # ELF e_machine of 64-bit ARM


@pytest.fixture(scope="session")
def hosts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """The loop host for each platform, as the command prefix that runs it."""
    out = tmp_path_factory.mktemp("hosts-arm")
    compile_host(CC, out / "loop_host", "-ldl")
    compile_host(ARM_CC, out / "loop_host.arm", "-ldl")
    arm = [QEMU, "-L", str(SYSROOT), str(out / "loop_host.arm")]
    started = subprocess.run(arm, capture_output=True, text=True, timeout=60)
    if "usage: loop_host" not in started.stderr:
        pytest.skip(f"qemu-aarch64 could not start an ARM program here: {started.stderr.strip()[-300:]}")
    return {"linux64": [str(out / "loop_host")], "aarch64": arm}


def _machine(library: bytes) -> int:
    """The ELF header's e_machine (little-endian ELF64)."""
    assert library[:4] == b"\x7fELF" and library[5] == 1, "not a little-endian ELF file"
    return int.from_bytes(library[18:20], "little")


@pytest.mark.parametrize("fmi", ("2", "3"))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_closed_loop_aarch64_libraries_equal_linux64(scenario: str, fmi: str, hosts, native_fmus, native_fmus3,
                                                     tmp_path: Path) -> None:
    from ipcosim.harness.api.export import ExportOptions, loop_spec

    spec = loop_spec(ExportOptions(scenario, tmp_path / "unused.fmu", fmu_dirs=(native_fmus[1],)))
    assert len(spec.components) == 3
    folder = native_fmus3 if fmi == "3" else native_fmus[1]
    for c in spec.components:
        with zipfile.ZipFile(folder / c.fmu.name) as z:
            assert _machine(z.read(f"binaries/aarch64-linux/{c.fmu.stem}.so")) == EM_AARCH64, c.fmu.name
    results = {}
    for platform in ("linux64", "aarch64"):
        plan, columns = write_plan(spec, tmp_path, platform, native_fmus3 if fmi == "3" else None)
        results[platform] = run_host(hosts, platform, plan)
    assert results["linux64"].shape == (TICKS + 1, len(columns))
    compare(f"{scenario} FMI {fmi}.0", results, columns, TOLERANCE)
    moved = np.abs(results["aarch64"][:, columns.index(f"plant.{cart(columns)}")]).max()
    assert moved > 1e-3, f"{scenario}: the cart never moved ({moved})"


@pytest.mark.parametrize("fmi", ("2", "3"))
def test_exported_loop_aarch64_library_equals_linux64(fmi: str, hosts, native_fmus, tmp_path: Path) -> None:
    from ipcosim.harness.api.export import ExportOptions, export

    fmu = export(ExportOptions("double-mass-lqr", tmp_path / "loop.fmu", fmu_dirs=(native_fmus[1],), fmi=fmi))
    with zipfile.ZipFile(fmu) as z:
        (arm,) = [n for n in z.namelist() if n.startswith("binaries/aarch64-linux/")]
        assert _machine(z.read(arm)) == EM_AARCH64
    results = {}
    for platform in ("linux64", "aarch64"):
        plan, names = write_single_plan(fmu, tmp_path, platform, 0.01, 300)
        results[platform] = run_host(hosts, platform, plan)
    compare(f"double-mass-lqr exported, FMI {fmi}.0", results, names, TOLERANCE)
    assert np.abs(results["aarch64"][:, names.index("plant.passive_cart_position")]).max() > 1e-3


def test_the_master_loads_an_fmi2_arm_library_from_its_platform_tuple(monkeypatch: pytest.MonkeyPatch,
                                                                      native_fmus, tmp_path: Path) -> None:
    """On 64-bit ARM Linux fmpy looks for an FMI 2.0 library in ``binaries/linux64/`` (the x86-64 one here);
    the master gives it the FMU's ``binaries/aarch64-linux/`` library instead (FMI 2.0.4, section 2.3)."""
    import fmpy

    from ipcosim.harness.master.slave import fmi2_tuple_library

    with zipfile.ZipFile(native_fmus[1] / "Setpoint.fmu") as z:
        z.extractall(tmp_path)
    assert fmi2_tuple_library(tmp_path, "Setpoint") is None  # x86-64: fmpy's own linux64
    monkeypatch.setattr(fmpy, "architecture", "aarch64")
    monkeypatch.setattr(fmpy, "platform_tuple", "aarch64-linux")
    library = fmi2_tuple_library(tmp_path, "Setpoint")
    assert library == str(tmp_path / "binaries" / "aarch64-linux" / "Setpoint.so")
    assert _machine(Path(library).read_bytes()) == EM_AARCH64
    assert fmi2_tuple_library(tmp_path, "NoSuchModel") is None
