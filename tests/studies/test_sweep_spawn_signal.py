"""A SIGTERM that reaches a sweep while its pool is spawning a worker process (the worker started, its
start-up data not yet written to it) ends the sweep like any other signal: one line, status 143, no
process left behind. Delivered at that moment, the signal used to leave a worker the pool did not
know, blocked on its start-up pipe, and the command waited for ever for multiprocessing's resource
tracker, whose pipe that worker held.

The signal is sent by the sweep's own process right after it spawned its second worker, so it arrives
there on every run.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="POSIX signals and /proc")

SCRIPT = textwrap.dedent("""
    import os
    import signal
    import sys
    from multiprocessing import util

    from ipcosim.harness import cli

    spawn = util.spawnv_passfds
    spawned = []

    def spawnv_passfds(path, args, passfds):
        pid = spawn(path, args, passfds)  # the worker runs, waiting for its start-up data
        spawned.append(pid)
        if len(spawned) == 2:  # the second worker: the pool holds the first one already
            os.kill(os.getpid(), signal.SIGTERM)
        return pid

    util.spawnv_passfds = spawnv_passfds
    sys.argv = ["ipcosim", "sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=uniform(0.8,1.2)*nominal",
                "--samples", "200", "--workers", "2", "--stop-time", "0.02", "--quiet", "--out", {out!r}]
    sys.exit(cli.main())
    """)


def _group(pgid: int) -> list[int]:
    """The live processes of process group ``pgid``."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                out.append(int(entry.name))
    return out


def test_a_signal_while_a_worker_is_spawned_ends_the_sweep_at_once(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT.format(out=str(tmp_path / "sweep"))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the sweep hung after a SIGTERM during a worker's spawn")
    assert proc.returncode == 128 + signal.SIGTERM, err
    errors = [line for line in err.splitlines() if "error" in line]
    assert len(errors) == 1 and errors[0].startswith("ipcosim sweep: error: interrupted by SIGTERM"), err
    deadline = time.monotonic() + 10
    while _group(proc.pid) and time.monotonic() < deadline:  # its workers and tracker end with it
        time.sleep(0.1)
    left = _group(proc.pid)
    if left:
        os.killpg(proc.pid, signal.SIGKILL)
    assert left == [], f"processes left behind: {left}"
