"""The HIL bench's host-stall probe: overruns split into the host's and the loop's own
(``benchmarks/stall_probe.py``), on made-up timelines and on a real probe."""
from __future__ import annotations

import time

import numpy as np

from benchmarks.stall_probe import StallProbe, attribute

H = 1_000_000  # 1 kHz [ns]


def timeline(lateness_us: dict[int, list[int]], n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Steps on a 1 kHz schedule from t = 1 s; ``{step: [lateness of it and the next steps, us]}``."""
    late = np.zeros(n, dtype=np.int64)
    for first, values in lateness_us.items():
        late[first:first + len(values)] = np.asarray(values) * 1000
    return 10 ** 9 + np.arange(n, dtype=np.int64) * H + late, late


def test_an_episode_the_probes_saw_is_the_hosts_one_they_did_not_see_is_the_loops():
    starts, late = timeline({50: [3000, 2200, 1400, 600], 120: [900]})
    host = {"fifo": True, "cpus": {"0": [[int(starts[49]) + 200_000, int(starts[50])]], "1": []}}
    got = attribute(starts, late, H, host)
    assert got["overruns"] == 5 and got["host_overruns"] == 4 and got["own_overruns"] == 1
    assert got["own_episodes"] == 1 and got["host_stall_s"] == 3.8e-3   # the stall recorded, inside the run
    assert got["behind_step_s"] == 2e-4        # catching up at 0.8 ms a step: 0.2 ms of work each
    # the same run with the probes seeing nothing, or not under SCHED_FIFO: every overrun is the loop's
    for probes in ({"fifo": True, "cpus": {"0": []}}, {**host, "fifo": False}):
        got = attribute(starts, late, H, probes)
        assert got["own_overruns"] == 5 and got["own_episodes"] == 2 and got["host_overruns"] == 0
    # a stall far too short for the lateness explains nothing
    short = {"fifo": True, "cpus": {"0": [[int(starts[50]) - 400_000, int(starts[50])]]}}
    assert attribute(starts, late, H, short)["own_overruns"] == 5


def test_jitter_outside_the_hosts_stalls_leaves_their_steps_out():
    starts, late = timeline({50: [3000, 2000, 1000]})
    host = {"fifo": True, "cpus": {"0": [[int(starts[49]), int(starts[50])]]}}
    assert attribute(starts, late, H, host)["jitter_p99_own_s"] == 0.0
    assert attribute(starts, late, H, {"fifo": True, "cpus": {}})["jitter_p99_own_s"] > 5e-4


def test_a_probe_records_a_stall_of_its_cpu():
    """The probe itself (real processes): with no stall forced, whatever it records is a list of
    [start, end] pairs inside the time it ran, on every CPU it was given."""
    with StallProbe([0]) as probe:
        t0 = time.monotonic_ns()
        time.sleep(0.2)
        t1 = time.monotonic_ns()
    assert set(probe.result["cpus"]) == {"0"} and probe.result["seconds"] >= 0.2
    for a, b in probe.result["cpus"]["0"]:
        assert t0 - 10 ** 9 < a < b < t1 + 10 ** 9 and b - a >= 300_000
