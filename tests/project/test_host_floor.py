"""The host's floor (``benchmarks/host_floor.c``, ``benchmarks/host_floor.py``) and a run's late fraction
(``harness/master/realtime.py``) count the same steps: those starting 0.5 ms or more after their deadline."""
from __future__ import annotations

import json
import resource
import subprocess
import time

import numpy as np
import pytest

from benchmarks import host_floor
from ipcosim.harness.master.realtime import LATE_S, late_fraction, lateness_histogram


def test_late_means_half_a_millisecond_or_more_after_the_deadline():
    """DESIGN's definition, on made-up lateness: 0.5 ms exactly is late, a nanosecond less is not."""
    assert LATE_S == 0.5e-3
    late_ns = np.array([0, 120_000, 499_999, 500_000, 900_000, 3_000_000, 20_000_000, 0])
    metrics = {"lateness_histogram": lateness_histogram(late_ns), "realtime_steps": len(late_ns)}
    assert late_fraction(metrics) == 4 / 8
    assert late_fraction({"lateness_histogram": lateness_histogram(np.zeros(0)), "realtime_steps": 0}) == 0.0


def test_the_allowance_is_the_floor_times_the_factor_and_never_below_one_step():
    assert host_floor.allowance([0.001, 0.004, 0.002]) == pytest.approx(0.012)
    assert host_floor.allowance([0.0, 0.0], steps=5000) == pytest.approx(3 / 5000)
    assert host_floor.ratio(0.006, 0.002) == pytest.approx(3.0)
    assert host_floor.ratio(0.001, 0.0, steps=1000) == pytest.approx(1.0)


def test_a_miss_without_rt_priority_on_a_host_that_is_not_quiet_is_not_judged():
    def beside(late, *floors):
        return host_floor.Beside(late, floors, host_floor.allowance(floors), 1)

    assert beside(0.5, 0.01, 0.02).unjudged(priority=None)                      # loud host, no RT: not judged
    assert beside(0.5, 0.01, 0.02).unjudged(priority=20) is None                # under RT: the miss stands
    assert beside(0.05, 0.001, 0.002).unjudged(priority=None) is None           # quiet host: the miss stands
    assert beside(0.001, 0.01, 0.02).unjudged(priority=None) is None            # within: nothing to excuse
    assert not beside(0.05, 0.001, 0.002).within and beside(0.005, 0.001, 0.002).within


def test_the_probe_paces_to_its_deadlines_and_reports_its_steps():
    """A loop paced to absolute deadlines cannot finish before its last deadline; every figure it prints
    describes the steps it ran, with the run's threshold."""
    try:
        host_floor.probe_binary()
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))
    t0 = time.monotonic()
    floor = host_floor.measure(period=2e-3, steps=200)
    assert time.monotonic() - t0 >= 200 * 2e-3
    assert floor.steps == 200 and 0 <= floor.late <= 200 and floor.late_fraction == floor.late / 200
    assert 0 <= floor.lateness_p99 <= floor.lateness_max and floor.sched_fifo == "not requested"
    if floor.lateness_max < LATE_S:
        assert floor.late == 0


def test_the_probes_work_is_cpu_time_after_each_wake_up():
    """``--work-ns`` spends that much of the probe's own CPU time each step: 100 steps of 2 ms with 1 ms
    of work take at least 0.1 s of CPU, and the bare probe next to none."""
    try:
        exe = host_floor.probe_binary()
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))

    def cpu(*argv: str) -> tuple[float, dict]:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run([str(exe), "--period-ns", "2000000", "--steps", "100", *argv], capture_output=True,
                              text=True, timeout=30, check=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, json.loads(done.stdout)

    worked, out = cpu("--work-ns", "1000000")
    bare, plain = cpu()
    assert worked >= 0.1 and out["work_ns"] == 1_000_000 and out["steps"] == 100
    assert bare < 0.05 and plain["work_ns"] == 0


def test_a_bad_option_of_the_probe_is_one_line_and_status_2():
    try:
        exe = host_floor.probe_binary()
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))
    for argv, words in ((["--steps", "0"], "--steps 0: expected an integer"), (["--period-ns", "x"], "--period-ns x"),
                        (["--colour"], "unknown option --colour"), (["--priority"], "--priority needs a value")):
        done = subprocess.run([str(exe), *argv], capture_output=True, text=True, timeout=10)
        assert done.returncode == 2 and done.stdout == "", argv
        assert done.stderr.count("\n") == 1 and words in done.stderr, done.stderr


def test_no_compiler_is_one_reason(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with pytest.raises(host_floor.FloorUnavailable, match="no C compiler"):
        host_floor.probe_binary()


def _samples(*late: float) -> list:
    from benchmarks.bench_hil_floor import Sample

    return [Sample(x, upright=x == x) for x in late]


def test_the_hil_bench_judges_the_walkthrough_against_its_floor_and_the_in_process_rig(monkeypatch):
    """The walkthrough's targets on made-up repetitions: medians compared, a failed run (no late fraction)
    misses, each run at most 1 % late only on a quiet host (the floor at most 0.3 %), and a loaded RT run
    judged by its worst against max(0.5 %, 3 x the floor's worst)."""
    from benchmarks import bench_hil_floor as bench
    from benchmarks import targets

    def judged(tcp, inproc, floor, rt_tcp=(0.001,) * 5, rt_floor=(0.0,) * 5, khz=(0.002,) * 5, khz_floor=(0.001,) * 5):
        monkeypatch.setattr(targets, "FIGURES", {})
        got = {("TCP", "quiet", False): _samples(*tcp), ("in-process", "quiet", False): _samples(*inproc),
               ("floor", "quiet", False): _samples(*floor), ("TCP", "loaded", True): _samples(*rt_tcp),
               ("floor", "loaded", True): _samples(*rt_floor), ("TCP", "2 kHz", False): _samples(*khz),
               ("floor", "2 kHz", False): _samples(*khz_floor)}
        bench.judge(got, rt_done=True)
        return {k.removeprefix("hil_floor.target_"): f.get("met") for k, f in targets.FIGURES.items()}

    fine = judged(tcp=(0.002, 0.003, 0.004, 0.009, 0.0), inproc=(0.002,) * 5, floor=(0.001, 0.002, 0.0, 0.5, 0.001))
    assert fine == {"walkthrough_over_inproc": True, "walkthrough_over_floor": True,
                    "walkthrough_quiet_upright": True, "walkthrough_quiet_worst_pct": True,
                    "loaded_rt_tcp_worst_pct": True, "loaded_rt_tcp_upright": True, "2khz_tcp_median_pct": True}
    one_late = judged(tcp=(0.002, 0.003, 0.004, 0.02, 0.0), inproc=(0.002,) * 5, floor=(0.001,) * 5)
    assert one_late["walkthrough_quiet_worst_pct"] is False and one_late["walkthrough_over_floor"] is True
    loud = judged(tcp=(0.02,) * 5, inproc=(0.02,) * 5, floor=(0.01,) * 5)    # not a quiet host: ratios only
    assert loud["walkthrough_over_floor"] is True and "walkthrough_quiet_worst_pct" not in loud
    assert judged(tcp=(0.005,) * 5, inproc=(0.002,) * 5, floor=(0.002,) * 5)["walkthrough_over_inproc"] is False
    assert judged(tcp=(0.004,) * 5, inproc=(0.004,) * 5, floor=(0.001,) * 5)["walkthrough_over_floor"] is False
    failed = judged(tcp=(0.001, 0.001, float("nan"), 0.001, 0.001), inproc=(0.002,) * 5, floor=(0.002,) * 5)
    assert failed["walkthrough_over_inproc"] is False and failed["walkthrough_over_floor"] is False
    assert judged((0.0,) * 5, (0.0,) * 5, (0.0,) * 5, rt_tcp=(0.004, 0.006))["loaded_rt_tcp_worst_pct"] is False
    assert judged((0.0,) * 5, (0.0,) * 5, (0.0,) * 5, rt_tcp=(0.004, 0.006),
                  rt_floor=(0.0, 0.003))["loaded_rt_tcp_worst_pct"] is True       # 3 x 0.3 % above 0.5 %
    assert judged((0.0,) * 5, (0.0,) * 5, (0.0,) * 5, khz=(0.02,) * 5)["2khz_tcp_median_pct"] is False
    loud_2khz = judged((0.0,) * 5, (0.0,) * 5, (0.0,) * 5, khz=(0.02,) * 5, khz_floor=(0.004,) * 5)
    assert loud_2khz["2khz_tcp_median_pct"] is None         # a floor above 0.3 %: printed, not judged


def test_the_pairs_loop_waits_for_its_peers_answer_every_period():
    """``--pair``: the loop waits each period for the peer's answer, so a peer that spends 1.5 ms of CPU on each
    answer makes nearly every step of a 1 ms loop late, while the same peer at 0.1 ms leaves the loop on time
    on a quiet host; the peer's CPU time is spent (it is the probe's child)."""
    try:
        exe = host_floor.probe_binary()
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))

    def pair(peer_work_ns: int) -> tuple[float, dict]:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run([str(exe), "--steps", "100", "--pair", "--peer-work-ns", str(peer_work_ns)],
                              capture_output=True, text=True, timeout=30, check=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, json.loads(done.stdout)

    cpu, slow = pair(1_500_000)
    assert slow["pair"] is True and slow["peer_work_ns"] == 1_500_000
    assert cpu >= 0.15 and slow["late"] >= 90
    _, fast = pair(100_000)
    assert fast["late"] < slow["late"]
    _, bare = pair(0)
    assert bare["steps"] == 100 and bare["work_ns"] == 0
