"""A killed run's extraction folder is removed by the next run; a running process's never is."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

import ipcosim
from ipcosim.harness.api.engine import EXTRACT_PREFIX, remove_stale_extractions


@pytest.mark.integration
def test_the_next_run_removes_a_killed_runs_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    env = dict(os.environ, TMPDIR=str(tmp_path))
    killed = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--realtime",
                               "--stop-time", "60", "--quiet", "--out", str(tmp_path / "out")], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(f"{EXTRACT_PREFIX}{killed.pid}-*/*/modelDescription.xml")):
        assert time.monotonic() < deadline and killed.poll() is None, "the run never extracted its FMUs"
        time.sleep(0.1)
    killed.send_signal(signal.SIGKILL)
    killed.wait(30)
    left = list(tmp_path.glob(f"{EXTRACT_PREFIX}{killed.pid}-*"))
    assert len(left) == 1, "SIGKILL leaves the folder behind"
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        running = tmp_path / f"{EXTRACT_PREFIX}{alive.pid}-keep"
        running.mkdir()
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        ipcosim.run("single-mass-lqr", stop_time=0.01)
        assert not left[0].exists(), "the next run removed the dead process's folder"
        assert running.is_dir(), "a running process's folder stays"
    finally:
        alive.kill()
        alive.wait(30)
    assert remove_stale_extractions(tmp_path) == [running]
