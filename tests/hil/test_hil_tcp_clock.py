"""The TCP card's reckoning of the rig's clock: bounds from each reply, as a network time client keeps.

A reply stamped ``t`` (rig clock) to a request sent at host time ``s`` and read at ``r`` says the
offset (rig minus host) lies in ``[t - r, t - s]``. A reply read late (the client preempted between
its arrival and the read, or a client that sleeps while the rig answers) must not date the
reckoning by the read.
"""
from __future__ import annotations

import random
import time

import pytest

from ipcosim.fmus.hil import open_card
from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigServer
from ipcosim.fmus.hil.tcpip import DRIFT_PPM, ClockOffset

MS = 1_000_000


def exchange(offset: ClockOffset, true_offset: int, sent: int, on_wire: int, read_after: int) -> int:
    """One request sent at host time ``sent``, stamped by the rig ``on_wire`` ns later, read
    ``read_after`` ns after the stamp; returns the host time of the read."""
    stamp_host = sent + on_wire
    offset.update(stamp_host + true_offset, sent, stamp_host + read_after)
    return stamp_host + read_after


def test_replies_read_a_period_late_do_not_date_the_rigs_clock():
    rng = random.Random(7)
    true = 123_456_789
    off = ClockOffset()
    host = 10 * MS
    for _ in range(3):                       # the handshake: requests read as soon as they are answered
        host = exchange(off, true, host, rng.randint(20_000, 60_000), rng.randint(5_000, 30_000)) + MS
    for _ in range(5000):                    # 5 s of steps: every reply read about a period after it came
        host = exchange(off, true, host, rng.randint(20_000, 300_000), rng.randint(600_000, 950_000)) + 50_000
    low, high = off._bounds(host)
    assert low <= true <= high
    # within half the narrowest window seen (the handshake's), not the period the reads were late by
    assert abs(off.at(host) - true) <= 45_000


def test_the_offset_lies_within_every_replys_bounds_whatever_the_delays():
    rng = random.Random(11)
    true = -5_000_000_000
    off = ClockOffset()
    host = 0
    for _ in range(2000):
        host = exchange(off, true, host, rng.randint(0, 2 * MS), rng.randint(0, 2 * MS)) + rng.randint(0, MS)
        low, high = off._bounds(host)
        assert low <= true <= high


def test_a_jump_of_the_rigs_clock_is_taken_at_the_next_reply():
    off = ClockOffset()
    host = exchange(off, 1_000 * MS, 0, 30_000, 10_000)
    host = exchange(off, 3_000 * MS, host + MS, 30_000, 10_000)          # the rig's clock restarted
    assert abs(off.at(host) - 3_000 * MS) <= 30_000


def test_a_drifting_rig_is_followed_within_the_drift_allowance():
    ppm = DRIFT_PPM // 2                                                  # a rig clock this much fast
    off = ClockOffset()
    host = 0
    for _ in range(20_000):                                               # 20 s, prompt replies
        true = host * ppm // 1_000_000
        host = exchange(off, true, host, 40_000, 20_000) + MS
    assert abs(off.at(host) - host * ppm // 1_000_000) <= 60_000


@pytest.fixture
def wallclock_server():
    srv = RigServer(VirtualRig(RigConfig(clock="wallclock")), "127.0.0.1", 0).start()
    yield srv
    srv.close()


def test_steps_over_tcp_reach_the_rig_before_their_sample_instants(wallclock_server):
    """Each step returns at its sample instant on the card's reckoning of the rig's clock, and the next
    request, sent after the controller's work, reaches the rig before that request's instant (a client
    that reckoned the rig's clock behind sent its requests after their instants: every sample read at
    its arrival, late)."""
    card = open_card("q4", wallclock_server.uri)
    try:
        h = 2e-3
        t0 = card.time() + 5 * h
        steps = 300
        for k in range(1, steps + 1):
            res = card.step([0], [0.0], [0, 1], t0 + k * h)
            assert res.time >= t0 + k * h - 1e-4                            # not before its instant
            time.sleep(2e-4)                                                 # the controller's work
        late = wallclock_server.rig.counters["late_samples"]
    finally:
        card.close()
    assert late <= steps // 4, f"{late} of {steps} requests reached the rig after their sample instant"
