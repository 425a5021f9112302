"""Scenarios the master refuses before any work, in one line naming the SSD file and what is wrong:
a system with no FMU component to simulate."""
from __future__ import annotations

import shutil

import pytest
import ssp_text as t

import ipcosim
from ipcosim.errors import IpcosimError
from ipcosim.harness import cli

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

VERSIONS = ("1.0", "2.0")


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
