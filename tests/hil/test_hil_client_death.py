"""A controlling process that hangs or dies: the rig's watchdog (hang) or the lost connection
(death) puts the motor at 0 V. The client is a separate process driving a wallclock rig served
on 127.0.0.1; every wait is bounded."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from fmi_helpers import wait_for

from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigServer

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT = 0.5   # [s] long enough that a stall of a loaded VM does not trip it before the test does

CLIENT = """
import sys, time
from ipcosim.fmus.hil import open_card
card = open_card("q4", sys.argv[1], timeout=1.0)
card.write_analog([0], [0.0])
card.watchdog_set_analog_expiration_state([0], [0.0])
card.set_encoder_counts([0, 1], [0, 0])
card.watchdog_start(float(sys.argv[2]))
t0 = card.time()
for k in range(30000):                      # bounded: 30 s at 1 kHz
    card.step([0], [2.0], [0, 1], t0 + (k + 1) * 1e-3)
    if k == 20:
        print("running", flush=True)
"""


def start_client(uri: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", CLIENT, uri, str(TIMEOUT)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    assert line.strip() == "running", proc.stderr.read()
    return proc



@pytest.fixture
def wallclock_server():
    srv = RigServer(VirtualRig(RigConfig(clock="wallclock", tick=5e-4, pendulum_limit=None, cart_limit=None)),
                    "127.0.0.1", 0).start()
    yield srv
    srv.close()


def test_hung_client_watchdog_expires_and_the_motor_goes_to_zero_within_the_timeout(wallclock_server):
    rig = wallclock_server.rig
    proc = start_client(wallclock_server.uri)
    try:
        assert rig.motor_voltage() == pytest.approx(2.0, abs=0.005)
        os.kill(proc.pid, signal.SIGSTOP)               # the controller hangs, its connection stays open
        assert wait_for(lambda: rig.status().watchdog_expired)
        assert rig.motor_voltage() == 0.0
        # on the rig's clock: expiry no later than one physics tick after the timeout since the last reload
        assert rig.watchdog.expired_at_ns - rig.watchdog.last_reload_ns <= int(TIMEOUT * 1e9) + rig.tick_ns
        assert any(e.topic == "watchdog" for e in rig.events)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert wait_for(lambda: any(e.topic == "session" and "ended" in e.message for e in rig.events))


def test_killed_client_loses_the_session_and_the_motor_goes_to_zero(wallclock_server):
    rig = wallclock_server.rig
    proc = start_client(wallclock_server.uri)
    assert rig.motor_voltage() == pytest.approx(2.0, abs=0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert wait_for(lambda: rig.motor_voltage() == 0.0)
    assert wait_for(lambda: any(e.topic == "session" and "ended" in e.message for e in rig.events))
    assert wait_for(lambda: not rig.watchdog.running)
