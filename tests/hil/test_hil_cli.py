"""``ipcosim rig serve|status|reset`` as processes (127.0.0.1, any free port, bounded)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ipcosim.fmus.hil import ErrorCode, HILError, open_card

ROOT = Path(__file__).resolve().parents[2]


def ipcosim(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


@pytest.fixture
def rig_process():
    procs = []

    def start(*extra: str) -> tuple[subprocess.Popen, int]:
        proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--port", "0",
                                 "--duration", "120", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        procs.append(proc)
        line = proc.stdout.readline()
        assert "serving" in line and "127.0.0.1:" in line, line + proc.stderr.read()
        return proc, int(line.split("127.0.0.1:")[1].split()[0])
    yield start
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=30)


@pytest.mark.slow
def test_serve_status_reset_and_clean_stop(rig_process):
    proc, port = rig_process("--plant", "double-mass", "--clock", "lockstep", "--initial", "pendulum_angle=0.3")
    card = open_card("q4", f"0@tcpip://127.0.0.1:{port}")
    assert card.info.plant == "double-mass" and card.info.clock == "lockstep"
    for k in range(2000):                                   # the pendulum falls past 20 degrees
        res = card.step([0], [0.0], [0, 1, 2], (k + 1) * 1e-3)
        if res.status.limit_tripped:
            break
    assert res.status.limit_tripped
    card.close()
    status = ipcosim("rig", "status", "--port", str(port))
    assert status.returncode == 0 and "amplifier OFF" in status.stdout and "pendulum limit tripped" in status.stdout
    reset = ipcosim("rig", "reset", "--port", str(port))
    assert reset.returncode == 0 and "amplifier on" in reset.stdout
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 0
    assert "stopped" in proc.stderr.read()


def test_serve_refuses_a_second_controller(rig_process):
    _, port = rig_process("--clock", "lockstep")
    first = open_card("q4", f"0@tcpip://127.0.0.1:{port}")
    with pytest.raises(HILError) as e:
        open_card("q4", f"0@tcpip://127.0.0.1:{port}")
    assert e.value.code == ErrorCode.BUSY
    first.close()


@pytest.mark.slow
def test_bad_options_are_one_line_errors():
    out = ipcosim("rig", "serve", "--port", "0", "--set", "Mp=-1", "--duration", "1")
    assert out.returncode == 1 and out.stderr.count("\n") == 1 and "Mp" in out.stderr
    # an unknown name is a usage error (docs/robustness.md's exit-status table), with the closest known names
    out = ipcosim("rig", "serve", "--port", "0", "--initial", "angle=0.1", "--duration", "1")
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert "--initial angle" in out.stderr and "no state 'angle'" in out.stderr and "pendulum_angle" in out.stderr
    out = ipcosim("rig", "serve", "--port", "0", "--plant", "double-mass", "--set", "Mpp=0.1", "--duration", "1")
    assert out.returncode == 2 and "--set Mpp" in out.stderr and "'Mp'" in out.stderr, out.stderr
    out = ipcosim("rig", "status", "--port", "1")
    assert out.returncode == 1 and "cannot connect" in out.stderr and out.stderr.count("\n") == 1
