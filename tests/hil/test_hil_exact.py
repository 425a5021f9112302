"""A wall-clock rig's physics is the lockstep replay of its own requests (to 1e-9, bit for bit here)."""
from __future__ import annotations

import random
import time

import numpy as np

from ipcosim.fmus.hil.rig import RigConfig, VirtualRig

CONFIG = dict(tick=5e-4, resolution=1e-5, initial_state={"pendulum_angle": 0.05})


def drive_in_real_time(rig: VirtualRig, steps: int, h_ns: int, seed: int) -> list[tuple[int, float, int, list[int]]]:
    """A controller on the host's clock: every ``h_ns`` a voltage from the last reading (a PD law with
    noise), now and then a request that comes late (after its sample instant); returns per request
    (the rig's instant of it, volts, sample instant, counts read)."""
    rng = random.Random(seed)
    log = []
    rig.watchdog_start(0.05)
    log.append((rig.watchdog.last_reload_ns, float("nan"), 0, []))
    base = rig.now_ns()
    counts = [0, 0]
    for k in range(steps):
        volts = max(-6.0, min(6.0, 0.02 * counts[1] * 40 + 0.01 * counts[0] + rng.uniform(-1.5, 1.5)))
        if rng.random() < 0.03:
            time.sleep(rng.uniform(0.0005, 0.003))       # a stall of the controller: the request is late
        until = base + (k + 1) * h_ns
        res = rig.step([0], [volts], [0, 1], until)
        counts = [int(c) for c in res.counts]
        log.append((rig.watchdog.last_reload_ns, volts, until, counts))
    return log


def replay(session_ns: int, log: list[tuple[int, float, int, list[int]]]) -> tuple[VirtualRig, list[list[int]]]:
    """The same session, begun at the same instant ``session_ns`` (where the operator puts the plant
    back at its initial state), and the same requests, at the same instants, on a lockstep rig with
    the wall clock's resolution."""
    rig = VirtualRig(RigConfig(clock="lockstep", **CONFIG))
    rig.advance(session_ns / 1e9)
    assert rig.now_ns() == session_ns
    rig.new_session("replay")
    start, *steps = log
    rig.advance((start[0] - rig.now_ns()) / 1e9)
    rig.watchdog_start(0.05)
    readings = []
    for instant, volts, until, _ in steps:
        rig.advance((instant - rig.now_ns()) / 1e9)
        assert rig.now_ns() == instant
        _, _, counts = rig.exchange([0], [volts], [0, 1], max(until, instant))
        readings.append(counts)
    return rig, readings


def test_a_wall_clock_run_equals_the_lockstep_replay_of_its_own_requests():
    wall = VirtualRig(RigConfig(clock="wallclock", **CONFIG))
    wall.start_clock()
    wall.new_session("run")
    session_ns = wall._t_ns         # on the wall's 10 us grid: 0 on a fast host, a tick or more on a slow one
    log = drive_in_real_time(wall, steps=400, h_ns=1_000_000, seed=3)
    late = sum(1 for instant, _, until, _ in log[1:] if instant > until)
    assert late > 0                                     # the replay covers late requests too
    off_grid = sum(1 for instant, *_ in log[1:] if instant % 500_000)
    assert off_grid > 100                               # the requests' instants are on no tick grid
    lock, readings = replay(session_ns, log)
    assert readings == [counts for *_, counts in log[1:]]
    last = max(log[-1][0], -(-log[-1][2] // 10_000) * 10_000)      # the sample instant on the 10 us clock
    assert wall._t_ns == lock.now_ns() == last                          # both at the last reading
    assert np.max(np.abs(np.array(wall.plant.state) - np.array(lock.plant.state))) <= 1e-9
    # the rest: nothing comes any more; the watchdog expires and the physics runs on with 0 V
    time.sleep(0.12)
    wall.status()
    lock.advance((wall._t_ns - lock.now_ns()) / 1e9)
    assert wall.watchdog.expired and lock.watchdog.expired_at_ns == wall.watchdog.expired_at_ns
    assert [(e.topic, e.time) for e in wall.events if e.topic in ("limit", "watchdog")] == \
        [(e.topic, e.time) for e in lock.events if e.topic in ("limit", "watchdog")]
    assert np.max(np.abs(np.array(wall.plant.state) - np.array(lock.plant.state))) <= 1e-9
