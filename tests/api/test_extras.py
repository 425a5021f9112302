"""Optional dependencies: a missing extra is one line naming the extra to install."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ipcosim.harness.support.extras import MissingExtraError, require


def test_present_module_passes() -> None:
    require("json")


def test_missing_module_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a))
    with pytest.raises(MissingExtraError,
                       match=r"matplotlib is not installed \(plots need it\): pip install 'ipcosim\[plot\]'"):
        require("matplotlib")


def test_plot_without_matplotlib_is_one_line(tmp_path) -> None:
    """`ipcosim run --plot` in a host without matplotlib: the run's results are written, the
    figure is skipped with one line naming the extra, exit 0."""
    code = (
        "import sys, importlib.abc\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'matplotlib': raise ModuleNotFoundError(name)\n"
        "import importlib.util\n"
        "real = importlib.util.find_spec\n"
        "importlib.util.find_spec = lambda n, *a: None if n.split('.')[0] == 'matplotlib' else real(n, *a)\n"
        "sys.meta_path.insert(0, Block())\n"
        "from ipcosim.harness.cli import main\n"
        f"sys.exit(main(['run', 'single-mass-lqr', '--stop-time', '0.2', '--plot', '--out', r'{tmp_path}']))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("ipcosim run: warning: plot.png skipped"), proc.stderr
    assert lines[-1].endswith("matplotlib is not installed (plots need it): pip install 'ipcosim[plot]'"), proc.stderr
    assert (tmp_path / "results.csv").is_file() and (tmp_path / "metrics.json").is_file()
