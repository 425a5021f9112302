"""matplotlib is a declared dependency; in an environment where it is missing all the same, the
commands that draw (run --plot, sweep, compare) print and write their numbers, skip the figure
with one line naming the extra, and exit 0. matplotlib is hidden from a child interpreter
(``sys.modules`` entry None). ``analyze`` needs python-control, which imports matplotlib itself:
its figures are skipped the same way when only the drawing fails (a test below)."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration


@pytest.mark.slow
def test_every_drawing_command_keeps_its_numbers_without_matplotlib(tmp_path: Path):
    commands = {
        "run": ["run", "single-mass-lqr", "--stop-time", "2", "--plot", "--out", str(tmp_path / "run")],
        "sweep": ["sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=[0.1,0.2]", "--workers", "1",
                  "--stop-time", "1", "--out", str(tmp_path / "sweep"), "--quiet"],
        "compare": ["compare", "--scenarios", "single-mass-lqr", "--stop-time", "1", "--workers", "1",
                    "--out", str(tmp_path / "compare"), "--quiet"],
    }
    script = textwrap.dedent(f"""
        import contextlib, io, json, sys
        sys.modules["matplotlib"] = None  # as if the plot extra were not installed
        from ipcosim.harness.cli import main
        out = {{}}
        for name, argv in {commands!r}.items():
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                code = main(argv)
            out[name] = [code, err.getvalue()]
        print(json.dumps(out))
        """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    for name, (code, err) in got.items():
        assert code == 0, (name, err)
        skipped = [line for line in err.splitlines() if "skipped" in line]
        assert len(skipped) == 1 and "pip install 'ipcosim[plot]'" in skipped[0], (name, err)
    assert (tmp_path / "run" / "metrics.json").exists() and not (tmp_path / "run" / "plot.png").exists()
    assert (tmp_path / "sweep" / "summary.md").exists() and (tmp_path / "compare" / "report.md").exists()


def test_analyze_keeps_its_margins_when_the_figures_cannot_be_drawn(tmp_path, monkeypatch, capsys):
    from ipcosim.harness.analysis import analyze_plots
    from ipcosim.harness.cli import main
    from ipcosim.harness.support.extras import MissingExtraError

    def no_plot(*args, **kwargs):
        raise MissingExtraError("matplotlib is not installed (plots need it): pip install 'ipcosim[plot]'")

    monkeypatch.setattr(analyze_plots, "plot_loop", no_plot)
    from ipcosim.harness.support import extras

    monkeypatch.setattr(extras, "_said", set())  # each skip is said once a process: once in this test
    assert main(["analyze", "single-mass-lqr", "--out", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "phase margin" in out and "figures:" not in out
    assert err.count("skipped") == 1
    analysis = json.loads((tmp_path / "analysis.json").read_text())
    assert analysis["phase_margin_deg"] is not None and analysis["gain_margin"]
    assert not (tmp_path / "bode.png").exists()
