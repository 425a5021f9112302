"""The native FMUs' Windows DLLs, run under wine, against their Linux libraries.

One small FMI 2.0 / 3.0 host (``tests/c/loop_host.c``, its plans in ``tests/loop_plans.py``) is compiled
twice, with the system C compiler and with mingw-w64; it runs a scenario's closed loop (setpoint, law,
plant) from the FMUs' binaries, or an exported loop, of either FMI version, and prints every output
after every tick as its IEEE bits. The Windows host runs the ``win64`` DLLs under wine, the Linux host
the ``linux64`` libraries, from the same plan; the outputs must agree to 1e-12 (the differences seen
are printed). Skipped, with the reason, where the cross compiler or wine is missing.
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from loop_plans import MINGW, TICKS, WINE, cart, compare, compile_host, run_host, write_plan, write_single_plan

from ipcosim.toolchain import find_compiler

CC = find_compiler()
pytestmark = [
    pytest.mark.integration,
    pytest.mark.cross,
    pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)"),
    pytest.mark.skipif(MINGW is None, reason="no mingw-w64 cross compiler (install gcc-mingw-w64-x86-64)"),
    pytest.mark.skipif(WINE is None, reason="wine is not installed (install wine64)"),
]
SCENARIOS = ("single-mass-lqr", "double-mass-lqr")
TOLERANCE = 1e-12


@pytest.fixture(scope="session")
def hosts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """The loop host for each platform, as the command prefix that runs it (wine started once here)."""
    out = tmp_path_factory.mktemp("hosts")
    compile_host(CC, out / "loop_host", "-ldl")
    compile_host(MINGW, out / "loop_host.exe")
    env = {**os.environ, "WINEPREFIX": str(out / "wineprefix"), "WINEDEBUG": "-all"}
    started = subprocess.run([WINE, str(out / "loop_host.exe")], env=env, capture_output=True, text=True, timeout=300)
    if "usage: loop_host" not in started.stderr:
        pytest.skip(f"wine could not start a Windows program here: {started.stderr.strip()[-300:]}")
    os.environ.update(WINEPREFIX=env["WINEPREFIX"], WINEDEBUG="-all")
    return {"linux64": [str(out / "loop_host")], "win64": [WINE, str(out / "loop_host.exe")]}


@pytest.mark.parametrize("fmi", ("2", "3"))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_closed_loop_win64_dlls_equal_linux64(scenario: str, fmi: str, hosts, native_fmus, native_fmus3,
                                              tmp_path: Path) -> None:
    from ipcosim.harness.api.export import ExportOptions, loop_spec

    spec = loop_spec(ExportOptions(scenario, tmp_path / "unused.fmu", fmu_dirs=(native_fmus[1],)))
    assert [c.fmu.stem for c in spec.components][0] == "Setpoint" and len(spec.components) == 3
    results = {}
    for platform in ("linux64", "win64"):
        plan, columns = write_plan(spec, tmp_path, platform, native_fmus3 if fmi == "3" else None)
        results[platform] = run_host(hosts, platform, plan)
    compare(f"{scenario} FMI {fmi}.0", results, columns, TOLERANCE)
    # the host runs the scenario's loop: its Linux rows are the master's (same FMUs, same order)
    import ipcosim

    master = ipcosim.run(scenario, fmus="native", stop_time=TICKS * spec.step, fmu_dirs=[native_fmus[1]]).data
    for j, col in enumerate(columns):
        worst = np.max(np.abs(results["linux64"][:, j] - master[col]))
        assert worst <= 1e-9 * max(1.0, np.abs(master[col]).max()), f"{scenario} {col}: host vs master {worst:.3g}"
    moved = np.abs(results["win64"][:, columns.index(f"plant.{cart(columns)}")]).max()
    assert moved > 1e-3, f"{scenario}: the cart never moved ({moved})"


@pytest.mark.parametrize("fmi", ("2", "3"))
def test_exported_loop_win64_dll_equals_linux64(fmi: str, hosts, native_fmus, tmp_path: Path) -> None:
    from ipcosim.harness.api.export import ExportOptions, export

    fmu = export(ExportOptions("double-mass-lqr", tmp_path / "loop.fmu", fmu_dirs=(native_fmus[1],), fmi=fmi))
    results = {}
    for platform in ("linux64", "win64"):
        plan, names = write_single_plan(fmu, tmp_path, platform, 0.01, 300)
        results[platform] = run_host(hosts, platform, plan)
    compare(f"double-mass-lqr exported, FMI {fmi}.0", results, names, TOLERANCE)
    assert np.abs(results["win64"][:, names.index("plant.passive_cart_position")]).max() > 1e-3
