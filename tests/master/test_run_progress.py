"""A run's progress where stderr is not a terminal (a pipe, a CI log): plain lines every few seconds of wall time,
no carriage returns, and nothing with ``--quiet``."""
from __future__ import annotations

import io
import subprocess
import sys
import types

import pytest
from master_mocks import loop_factory, loop_system

from ipcosim.harness.api.engine import Prepared
from ipcosim.harness.master import observers
from ipcosim.harness.master.observers import Progress


def run(sysm, factory, **kw):
    return Prepared(system=sysm, slave_factory=factory, algorithm="gauss-seidel").run(raise_on_error=False, **kw)


def test_lines_in_a_pipe_come_every_interval_of_wall_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """A clock that advances 1 s each time the bar reads it: over a run of 100 steps, checked every step, the
    first line comes at 2 s, then one every 5 s (2, 7, ..., 97: 20 lines), and one at the end."""
    clock = iter(range(10_000))
    monkeypatch.setattr(observers, "time", types.SimpleNamespace(perf_counter=lambda: float(next(clock))))
    stream = io.StringIO()  # not a terminal
    run(loop_system(), loop_factory(), stop_time=1.0, step=0.01, observers=[Progress(stream=stream, interval=5.0)])
    lines = stream.getvalue().split("\n")
    assert lines[-1] == "" and "\r" not in stream.getvalue()
    lines = lines[:-1]
    assert len(lines) == 21, lines
    assert lines[0].startswith("run:   2.0 %  t = 0.020 s of 1.000 s, 2.0 s elapsed")
    assert lines[1].startswith("run:   7.0 %  t = 0.070 s of 1.000 s, 7.0 s elapsed")
    assert lines[-2].startswith("run:  97.0 %") and lines[-1].startswith("run: 100.0 %  t = 1.000 s of 1.000 s")


def test_a_short_run_in_a_pipe_writes_no_line() -> None:
    stream = io.StringIO()
    run(loop_system(), loop_factory(), stop_time=1.0, step=0.01, observers=[Progress(stream=stream)])
    assert stream.getvalue() == ""  # done well within the first 2 s


@pytest.mark.integration
@pytest.mark.slow
def test_the_run_command_with_stderr_piped_reports_progress_in_lines_and_quiet_silences_it(tmp_path) -> None:
    # paced to wall time, so the run lasts its 3 s however fast the machine (a loaded one may exceed the
    # overrun budget: status 3, still a finished run with its progress)
    cmd = [sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--stop-time", "3", "--realtime"]
    loud = subprocess.run([*cmd, "--out", str(tmp_path / "a")], capture_output=True, text=True, timeout=300)
    assert loud.returncode in (0, 3), loud.stderr
    progress = [line for line in loud.stderr.splitlines() if line.startswith("run: ")]
    assert len(progress) >= 2 and "\r" not in loud.stderr, loud.stderr  # one during the run (>= 2 s), one at its end
    assert progress[-1].startswith("run: 100.0 %  t = 3.000 s of 3.000 s")
    quiet = subprocess.run([*cmd, "--out", str(tmp_path / "b"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert quiet.returncode in (0, 3), quiet.stderr
    assert not [line for line in quiet.stderr.splitlines() if line.startswith("run: ")], quiet.stderr  # no progress
    assert quiet.returncode == 3 or quiet.stderr == "", quiet.stderr  # on time: --quiet leaves stderr empty
