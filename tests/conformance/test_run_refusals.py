"""Scenarios the master refuses before any work, in one line naming the SSD file and what is wrong:
a system with no FMU component to simulate, and a component whose FMU has no shared library for
this platform (FMI 2.0 section 2.3 / FMI 3.0 section 2.5: ``binaries/<platform>/<modelIdentifier>``)."""
from __future__ import annotations

import shutil
import zipfile

import adder_fmus
import cfmu
import fmpy
import pytest
import ssp_text as t

import ipcosim
from ipcosim.errors import IpcosimError
from ipcosim.harness import cli

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

VERSIONS = ("1.0", "2.0")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """The adder for each SSP version (FMI 2.0 for 1.0, FMI 3.0 for 2.0)."""
    out = tmp_path_factory.mktemp("refusal-fmus")
    return {"1.0": cfmu.build(adder_fmus.adder("Adder", "2.0"), out),
            "2.0": cfmu.build(adder_fmus.adder("Adder3", "3.0"), out)}


def refused(folder, tmp_path, capsys):
    """The one line ``ipcosim run`` refuses ``folder`` with (exit 1, nothing else on stderr, no result
    file), and the exception ``ipcosim.run`` raises for it."""
    with pytest.raises(IpcosimError) as info:
        ipcosim.run(folder, stop_time=0.2, step=0.1)
    capsys.readouterr()
    out = tmp_path / "out"
    assert cli.main(["run", str(folder), "--step", "0.1", "--out", str(out)]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "SystemStructure.ssd" in err[0], err
    assert not (out / "results.csv").exists()
    return info.value, err[0]


@pytest.mark.parametrize("version", VERSIONS)
def test_system_of_only_sub_systems_and_connectors_is_refused(version, tmp_path, capsys):
    """A root holding only an empty sub-system and system connectors, their connection between them:
    nothing steps, so a run could only record ``time``; it is refused instead."""
    sub = (f'<ssd:System name="sub"><ssd:Connectors>{t.connector("x", "input", version)}</ssd:Connectors>'
           "</ssd:System>")  # no ssd:Elements, as a sub-system may be written
    root = t.system("root", [sub], [t.connection(".p", "sub.x")],
                    connectors=f'<ssd:Connectors>{t.connector("p", "input", version)}</ssd:Connectors>')
    folder = t.write(tmp_path / "s", t.document(root, version), {})
    exc, line = refused(folder, tmp_path, capsys)
    assert "has no component to simulate" in str(exc) and "'root'" in str(exc)
    assert "has no component to simulate" in line


def _moved_binaries(fmu, old, new, out):
    """A copy of ``fmu`` at ``out`` with its ``binaries/<old>/`` folder renamed ``binaries/<new>/``."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w") as dst:
        for name in src.namelist():
            moved = name.replace(f"binaries/{old}/", f"binaries/{new}/", 1)
            dst.writestr(moved, src.read(name))
    return out


@pytest.mark.parametrize("version", VERSIONS)
def test_fmu_without_a_binary_for_this_platform_is_named(version, fmus, tmp_path, capsys):
    """The adder with its library moved to ``binaries/win64`` (only a Windows binary, as FMUs exported
    there often carry): the line names the SSD file, the component, the FMU file, this platform and
    the platforms the FMU has, instead of a temporary extraction path."""
    here = fmpy.platform if version == "1.0" else fmpy.platform_tuple
    other = "win64" if version == "1.0" else "x86_64-windows"
    win = _moved_binaries(fmus[version], here, other, tmp_path / "Win.fmu")
    with zipfile.ZipFile(win) as zf:
        assert not any(n.startswith(f"binaries/{here}/") for n in zf.namelist())
    comp = t.component("A", "Win", t.adder_connectors(version))
    folder = t.write(tmp_path / "s", t.document(t.system("root", [comp]), version), {"Win": win})
    exc, line = refused(folder, tmp_path, capsys)
    msg = str(exc)
    assert "SystemStructure.ssd" in msg and "component 'A'" in msg and "resources/Win.fmu" in msg
    assert f"has no binary for {here} (it has: {other})" in msg
    assert "ipcosim-run-" not in line and f"has no binary for {here}" in line
