"""Real-time pacer: deadlines on integer ticks (no drift), sleep-then-spin, statistics. Simulated clock."""
from __future__ import annotations

import random
import sys
import time

import numpy as np
import pytest

from ipcosim.harness.master.realtime import Pacer, wait_until


class SimClock:
    """A clock that advances by ``read_cost`` per reading and oversleeps by ``wake_late``."""

    def __init__(self, read_cost: int = 1_000, wake_late: int = 60_000) -> None:
        self.ns = 5_000_000_000
        self.read_cost = read_cost
        self.wake_late = wake_late
        self.sleeps: list[float] = []

    def clock(self) -> int:
        self.ns += self.read_cost
        return self.ns

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.ns += int(seconds * 1e9) + self.wake_late

    def work(self, ns: int) -> None:
        self.ns += ns


def test_deadlines_never_drift():
    sim = SimClock()
    pacer = Pacer(1e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    rng = random.Random(3)
    pacer.start()
    t0 = pacer.t0_ns
    for n in range(5000):
        pacer.begin(n)
        sim.work(rng.randrange(50_000, 600_000))
        pacer.end(n)
    starts = pacer._starts
    # every step starts at its own deadline t0 + n*h (within the spin granularity), even after 5000 steps
    assert all(0 <= s - (t0 + n * 1_000_000) <= 2 * sim.read_cost for n, s in enumerate(starts))
    st = pacer.stats()
    assert st.steps == 5000 and st.overruns == 0
    assert st.period_jitter_max <= 4e-6
    assert 6.1e-4 >= st.worst_step_time >= 5e-4


def test_sleeps_then_spins():
    sim = SimClock(wake_late=60_000)
    pacer = Pacer(1e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    pacer.start()
    pacer.begin(0)
    pacer.end(0)
    pacer.begin(1)
    # it slept until ~spin before the deadline, and the oversleep (60 us < spin) was absorbed by spinning
    assert sim.sleeps and sim.sleeps[-1] == pytest.approx(1e-3 - 200e-6, abs=1e-5)
    assert pacer._lateness[-1] <= 2 * sim.read_cost


def test_a_long_step_counts_overruns_and_later_deadlines_hold():
    sim = SimClock()
    pacer = Pacer(1e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    pacer.start()
    t0 = pacer.t0_ns
    for n in range(20):
        pacer.begin(n)
        sim.work(2_500_000 if n == 5 else 100_000)      # step 5 takes 2.5 periods
        pacer.end(n)
    st = pacer.stats()
    # step 6 starts 1.5 periods late, step 7 0.5 period (+ a little) late: both beyond half a period
    assert st.overruns == 2
    assert st.lateness_max == pytest.approx(1.5e-3, abs=1e-5)
    assert st.worst_step_time == pytest.approx(2.5e-3, abs=1e-5)
    # the schedule recovers: step 8 onwards at their original deadlines
    assert all(0 <= pacer._starts[n] - (t0 + n * 1_000_000) <= 2 * sim.read_cost for n in range(8, 20))


def test_metrics_keys():
    sim = SimClock()
    pacer = Pacer(2e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    for n in range(10):
        pacer.begin(n)
        pacer.end(n)
    m = pacer.metrics()
    for key in ("period_jitter_p50_s", "period_jitter_p99_s", "period_jitter_max_s", "overruns",
                "worst_step_time_s", "realtime_steps"):
        assert key in m
    assert m["realtime_steps"] == 10


def test_wait_until_on_the_real_clock_reaches_the_deadline():
    deadline = time.perf_counter_ns() + 2_000_000
    assert wait_until(deadline) >= deadline


def test_bad_period():
    with pytest.raises(ValueError, match="period"):
        Pacer(0.0)


def test_a_constant_offset_of_the_cards_clock_is_not_counted_as_lateness():
    """HIL: the adapter returns at the card's sample instants, 0.7 ms after the pacer's deadlines."""
    sim = SimClock()
    pacer = Pacer(1e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    pacer.start()
    t0 = pacer.t0_ns
    for n in range(200):
        pacer.begin(n)
        sim.ns = max(sim.ns, t0 + (n + 1) * 1_000_000 + 700_000)   # blocked until the card's instant
        sim.work(50_000)                                            # then the controller
        pacer.end(n)
    st = pacer.stats()
    assert st.overruns == 0 and st.lateness_max < 5e-6
    assert st.period_jitter_max < 5e-6


# --- the observer: set-up report, histogram, overrun budget, rig faults -----------------------------

class _Model:
    def __init__(self, name: str, variables: dict) -> None:
        self.name, self.variables = name, variables


class _Inst:
    def __init__(self, name: str, variables: tuple[str, ...]) -> None:
        self.name = name
        self.model = _Model(name, {v: object() for v in variables})


class _Execution:
    def __init__(self) -> None:
        self.step_size = 1e-3
        self.n_ticks = 20
        self.instances = [_Inst("controller", ("voltage",)),
                          _Inst("plant", ("voltage", "limit_tripped", "last_error", "overruns"))]
        self.slaves: list = []


def paced(observer, sim: SimClock, late_steps: set[int]) -> None:
    """Run the observer's hooks over 20 simulated steps, steps in ``late_steps`` taking 3 periods."""
    from ipcosim.harness.master.realtime import Pacer

    observer.pacer = Pacer(1e-3, clock_ns=sim.clock, sleep=sim.sleep, spin=200e-6)
    observer.pacer.start(0)
    observer.pacer.begin(0)
    observer._open = True
    for n in range(1, 21):
        sim.work(3_000_000 if n in late_steps else 100_000)
        observer.step(_Execution(), n)


def test_lateness_histogram_counts_every_step():
    from ipcosim.harness.master.realtime import lateness_histogram

    h = lateness_histogram(np.array([0, 49_999, 50_000, 300_000, 1_999_999, 7_000_000]))
    assert h["<50us"] == 2 and h["50-100us"] == 1 and h["250-500us"] == 1 and h["1000-2000us"] == 1
    assert h[">=5000us"] == 1 and sum(h.values()) == 6


def test_a_run_over_its_overrun_budget_says_so_in_one_line(monkeypatch):
    from ipcosim.harness.master.realtime import DEFAULT_OVERRUN_BUDGET, RealtimePacer, budget_warning

    obs = RealtimePacer(overrun_budget=0.05)
    paced(obs, SimClock(), late_steps={4, 9})           # 4 late starts of 20: 20 % > 5 %
    obs.finish(_Execution(), None)
    m = obs.metrics()
    assert m["overrun_budget_exceeded"] is True and m["overruns"] >= 2
    assert m["overrun_fraction"] == m["overruns"] / m["realtime_steps"]
    assert m["realtime_priority"] is False and m["lateness_max_s"] > 0
    line = budget_warning(m)
    assert "\n" not in line and "budget 5.00 %" in line and f"{100 * m['overrun_fraction']:.2f} %" in line
    assert "real-time priority not in force" in line and "--rt-priority" in line
    within = RealtimePacer(overrun_budget=0.5)
    paced(within, SimClock(), late_steps={4})
    within.finish(_Execution(), None)
    assert within.metrics()["overrun_budget_exceeded"] is False and budget_warning(within.metrics()) is None
    monkeypatch.delenv("IPCOSIM_RT_OVERRUN_BUDGET", raising=False)
    assert RealtimePacer().overrun_budget == DEFAULT_OVERRUN_BUDGET == 0.01
    monkeypatch.setenv("IPCOSIM_RT_OVERRUN_BUDGET", "0.2")
    assert RealtimePacer().overrun_budget == 0.2 and RealtimePacer(overrun_budget=0.3).overrun_budget == 0.3


@pytest.mark.integration
def test_a_degraded_realtime_run_warns_and_exits_3(tmp_path, monkeypatch, capsys):
    """A host that starts every 10th step 2 ms late (a loaded machine) is over the default 1 % budget (the
    Python loop, whose pacer waits for each step in Python, where the delay is injected)."""
    import json

    from ipcosim.harness.cli import main
    from ipcosim.harness.master import realtime

    begin = realtime.Pacer.begin

    def loaded(self, tick):
        if tick % 10 == 5:
            time.sleep(2e-3)
        return begin(self, tick)

    monkeypatch.setattr(realtime.Pacer, "begin", loaded)
    monkeypatch.delenv("IPCOSIM_RT_OVERRUN_BUDGET", raising=False)
    out = tmp_path / "rt"
    status = main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.3", "--out", str(out), "--quiet",
                   "--loop", "python"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 3, err
    assert len(err) == 1 and err[0].startswith("ipcosim run: warning: real-time run degraded:"), err
    m = json.loads((out / "metrics.json").read_text())
    assert m["overrun_budget_exceeded"] is True and m["overrun_fraction"] > 0.01 and m["lateness_max_s"] > 1e-3
    assert (out / "results.csv").is_file(), "a degraded run keeps its results"
    from metrics_doc import documented_metrics
    assert set(m) <= documented_metrics(), set(m) - documented_metrics()
    assert main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.3", "--out", str(out), "--quiet",
                 "--overrun-budget", "0.9"]) == 0
    assert main(["run", "single-mass-lqr", "--overrun-budget", "2", "--out", str(out)]) == 2  # usage
    assert "--overrun-budget 2: expected a fraction in [0, 1]" in capsys.readouterr().err
    # the C loop, which waits for each step itself: a 2 us step no host holds is degraded too
    monkeypatch.setattr(realtime.Pacer, "begin", begin)
    assert main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.002", "--step", "2e-6", "--out", str(out),
                 "--quiet", "--loop", "c"]) == 3
    m = json.loads((out / "metrics.json").read_text())
    assert m["overrun_budget_exceeded"] is True and m["realtime_steps"] == 1000 and m["overrun_fraction"] > 0.5


def test_a_fault_of_the_card_makes_the_run_not_upright_whatever_the_last_sample():
    """The card's observer (the HIL room's) records the fault; the pacer itself knows no cards."""
    from ipcosim.harness.hil.observer import CardObserver
    from ipcosim.harness.master.realtime import RealtimePacer

    message = ("component plant (IP02HILSingleMass): fmi2DoStep returned fmi2Discard at t = 2.5 s: pendulum limit "
               "tripped: pendulum_angle = +0.3498 rad beyond +-0.3491 rad")
    obs = CardObserver(overruns=True)
    obs.start(_Execution())
    obs.finish(_Execution(), RuntimeError(message))
    m = obs.metrics()
    assert m["upright"] is False and m["rig_fault"] == message
    other = CardObserver()
    other.finish(_Execution(), RuntimeError("component controller (LQRSingleMass): fmi2DoStep returned fmi2Error"))
    assert "rig_fault" not in other.metrics() and "upright" not in other.metrics()
    pacer = RealtimePacer()
    paced(pacer, SimClock(), late_steps=set())
    pacer.finish(_Execution(), RuntimeError(message))
    assert "rig_fault" not in pacer.metrics() and "upright" not in pacer.metrics()


def test_realtime_setup_reports_each_option_as_applied_or_not(monkeypatch):
    import gc
    import os

    from ipcosim.harness.master.host_setup import RealtimeSetupError, realtime_setup

    monkeypatch.delenv("IPCOSIM_RT_PRIORITY", raising=False)
    monkeypatch.setenv("IPCOSIM_RT_CPU", str(min(os.sched_getaffinity(0))))
    before = os.sched_getaffinity(0)
    report, restore = realtime_setup()
    try:
        assert report["gc"].startswith("applied") and not gc.isenabled()
        assert report["cpu_affinity"].startswith("applied: CPU")
        assert report["sched_fifo"].startswith("not requested")
        if sys.platform.startswith("linux"):
            assert report["timer_slack"].startswith("applied: 1000 ns") and _timer_slack() == 1000
    finally:
        restore()
    assert gc.isenabled() and os.sched_getaffinity(0) == before
    if sys.platform.startswith("linux"):
        assert _timer_slack() == int(report["timer_slack"].split("was ")[1].split()[0])
    monkeypatch.setenv("IPCOSIM_RT_CPU", "4000")
    report, restore = realtime_setup()
    restore()
    assert report["cpu_affinity"].startswith("not applied")
    monkeypatch.setenv("IPCOSIM_RT_PRIORITY", "nan")
    with pytest.raises(RealtimeSetupError, match="IPCOSIM_RT_PRIORITY=nan"):
        realtime_setup()


def test_a_paced_loop_asks_the_fair_scheduler_for_a_short_slice(monkeypatch):
    """Under the default policy the loop's thread asks for IPCOSIM_RT_SLICE_US (default 700 us) and gets it
    back to the scheduler's own when the run ends; 0 leaves it alone; a bad value is refused by name."""
    import os

    from ipcosim.harness.master import host_setup
    from ipcosim.harness.master.host_setup import RealtimeSetupError, realtime_setup

    if host_setup._sched_attr_calls() is None or os.sched_getscheduler(0) != os.SCHED_OTHER:
        pytest.skip("a fair-scheduler slice is asked for on Linux (x86_64, aarch64, riscv64) under SCHED_OTHER")
    monkeypatch.delenv("IPCOSIM_RT_PRIORITY", raising=False)
    monkeypatch.delenv("IPCOSIM_RT_SLICE_US", raising=False)
    default = host_setup._sched_runtime()
    report, restore = realtime_setup()
    try:
        if report["sched_slice"].startswith("not applied"):
            pytest.skip(report["sched_slice"])         # a kernel before 6.12
        assert report["sched_slice"] == "applied: 700 us" and host_setup._sched_runtime() == 700_000
    finally:
        restore()
    assert host_setup._sched_runtime() == default
    monkeypatch.setenv("IPCOSIM_RT_SLICE_US", "0")
    report, restore = realtime_setup()
    restore()
    assert report["sched_slice"].startswith("not requested") and host_setup._sched_runtime() == default
    monkeypatch.setenv("IPCOSIM_RT_SLICE_US", "nan")
    with pytest.raises(RealtimeSetupError, match="IPCOSIM_RT_SLICE_US=nan"):
        realtime_setup()


def _timer_slack() -> int:
    import ctypes
    return ctypes.CDLL(None).prctl(30, 0, 0, 0, 0)      # PR_GET_TIMERSLACK


def test_the_spin_before_a_deadline_is_only_taken_under_a_realtime_policy():
    """Under the default policy the pacer and the card sleep to the deadline; under SCHED_FIFO they spin
    its last 0.2 ms (checked in a thread of its own, where the OS permits SCHED_FIFO)."""
    import os
    import threading

    from ipcosim.fmus.hil.api import RT_SPIN_NS, policy_spin_ns
    from ipcosim.harness.master.realtime import RT_SPIN, default_spin

    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        pytest.skip("this test process itself runs under a real-time policy")
    assert default_spin() == 0.0 and policy_spin_ns() == 0 and Pacer(1e-3).spin_ns == 0
    got: list = []

    def under_fifo() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except OSError as exc:
            got.append(exc)
            return
        got.extend([default_spin(), policy_spin_ns(), Pacer(1e-3).spin_ns])

    t = threading.Thread(target=under_fifo)
    t.start()
    t.join()
    if got and isinstance(got[0], OSError):
        pytest.skip(f"SCHED_FIFO refused here: {got[0]}")
    assert got == [RT_SPIN, RT_SPIN_NS, RT_SPIN_NS] and RT_SPIN_NS == 200_000


@pytest.mark.integration
@pytest.mark.realtime
def test_a_paced_run_writes_its_rows_a_few_at_a_time_and_its_timeline_when_asked(tmp_path, monkeypatch, capsys):
    """results.csv costs about 10 us a row: a paced run hands rows to the writer every
    ``PACED_WRITE_SECONDS``, not 0.2 s of them at once (which made the steps after them start late);
    ``IPCOSIM_RT_TIMELINE`` writes each step's start and lateness, and an unwritable one is one line."""
    from ipcosim.harness.cli import main
    from ipcosim.harness.master import realtime
    from ipcosim.harness.master.recorder import Recorder

    emitted: list[int] = []
    emit = Recorder.emit

    def counting(self, rows):
        emitted.append(rows - self.base_row)
        return emit(self, rows)

    monkeypatch.setattr(Recorder, "emit", counting)
    timeline = tmp_path / "timeline.npz"
    monkeypatch.setenv("IPCOSIM_RT_TIMELINE", str(timeline))
    out = tmp_path / "rt"
    assert main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.2", "--out", str(out), "--quiet",
                 "--overrun-budget", "1"]) == 0
    most = round(realtime.PACED_WRITE_SECONDS / 1e-3)
    assert emitted and max(emitted) <= most + 1 and sum(emitted) == 201, emitted
    with np.load(timeline) as tl:
        starts, late = tl["starts_ns"], tl["lateness_ns"]
        assert len(starts) == len(late) == 200 and int(tl["period_ns"]) == 1_000_000
        assert np.all(np.diff(starts) > 0) and late.min() == 0
    emitted.clear()
    assert main(["run", "single-mass-lqr", "--stop-time", "0.2", "--out", str(out), "--quiet"]) == 0
    assert max(emitted) > most + 1, "an unpaced run keeps writing in large pieces"
    monkeypatch.setenv("IPCOSIM_RT_TIMELINE", str(tmp_path / "no" / "such" / "t.npz"))
    capsys.readouterr()
    assert main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.05", "--out", str(out), "--quiet",
                 "--overrun-budget", "1"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "IPCOSIM_RT_TIMELINE=" in err[0] and "not written" in err[0], err


@pytest.mark.integration
def test_a_paced_run_reports_the_cpu_its_steps_take(tmp_path, monkeypatch):
    """Each step made to burn 0.3 ms of CPU (a busy loop on the process's own CPU clock) shows in
    ``loop_cpu_per_step_us`` as at least that, and an idle-waiting paced step takes far less than its period."""
    import json

    from ipcosim.harness.cli import main
    from ipcosim.harness.master import realtime

    def run(out):
        assert main(["run", "single-mass-lqr", "--realtime", "--stop-time", "0.3", "--out", str(out), "--quiet",
                     "--overrun-budget", "1"]) == 0
        return json.loads((out / "metrics.json").read_text())["loop_cpu_per_step_us"]

    plain = run(tmp_path / "plain")
    begin, took = realtime.Pacer.begin, realtime.Pacer.took

    def burn(steps):
        until = time.process_time() + 3e-4 * steps
        while time.process_time() < until:
            pass

    def burning_begin(self, tick):      # a step paced by the pacer in Python
        burn(1)
        return begin(self, tick)

    def burning_took(self, first_tick, starts, ends):     # steps paced by the C loop, handed over
        burn(len(starts))
        return took(self, first_tick, starts, ends)

    monkeypatch.setattr(realtime.Pacer, "begin", burning_begin)
    monkeypatch.setattr(realtime.Pacer, "took", burning_took)
    burnt = run(tmp_path / "burnt")
    assert 0 < plain < 1000 and burnt >= 300 and burnt >= plain + 250, (plain, burnt)


@pytest.mark.integration
def test_a_paced_run_is_as_steady_as_the_hosts_floor(tmp_path):
    """The pacer adds nothing to what the host does to a loop: a 5 s paced run of the single-mass LQR has at
    most three times the late steps (>= 0.5 ms) of a bare C loop on ``clock_nanosleep`` measured just before
    and after it (``benchmarks/host_floor.py``), never an absolute fraction: a shared host's own floor moves
    between 0.2 % and 13 % from hour to hour. Run and floor under SCHED_FIFO where permitted, else both
    without, and then a miss on a host that is not quiet is skipped with its figures (``Beside.unjudged``)."""
    import json
    import os
    import subprocess
    import sys

    from benchmarks import host_floor
    from ipcosim.harness.master.realtime import late_fraction

    priority = None if host_floor.rt_refusal(20) else 20          # both under SCHED_FIFO where permitted
    env = {k: v for k, v in os.environ.items() if k != "IPCOSIM_RT_PRIORITY"}
    env.update({"IPCOSIM_RT_PRIORITY": str(priority)} if priority else {})

    def paced() -> float:
        out = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
        run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--realtime",
                              "--stop-time", "5", "--out", str(out), "--quiet", "--overrun-budget", "1"],
                             capture_output=True, text=True, timeout=300, env=env)
        assert run.returncode == 0, run.stderr
        return late_fraction(json.loads((out / "metrics.json").read_text()))

    try:
        judged = host_floor.beside_floor(paced, priority=priority)
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))
    if judged.unjudged(priority):
        pytest.skip(judged.unjudged(priority))
    assert judged.within, str(judged)


@pytest.mark.integration
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the C loop paces on Linux (clock_nanosleep)")
def test_the_c_loop_waits_for_each_deadline_itself_and_python_runs_only_between_writes(tmp_path, monkeypatch):
    """With the C stepping loop, a paced run's ticks wait for their deadlines in C (``CLoop.pace``): every tick
    after the start-up step is handed to the pacer once, in order, started no earlier than its own deadline on
    the pacer's schedule and ended after it started; the pacer's observer is not called after the start-up step;
    and the results are the unpaced run's, byte for byte."""
    from ipcosim.harness.cli import main
    from ipcosim.harness.master import realtime

    calls: list[int] = []
    handed: list[tuple[int, int, int, int]] = []
    step, took = realtime.RealtimePacer.step, realtime.Pacer.took

    def counting(self, execution, n):
        calls.append(n)
        return step(self, execution, n)

    def recording(self, first_tick, starts, ends):
        handed.extend((first_tick + k, s, self.deadline_ns(first_tick + k), e)
                      for k, (s, e) in enumerate(zip(starts, ends)))
        return took(self, first_tick, starts, ends)

    monkeypatch.setattr(realtime.RealtimePacer, "step", counting)
    monkeypatch.setattr(realtime.Pacer, "took", recording)
    args = ["run", "single-mass-lqr", "--stop-time", "0.2", "--quiet", "--loop", "c"]
    assert main([*args, "--realtime", "--out", str(tmp_path / "paced"), "--overrun-budget", "1"]) == 0
    assert [tick for tick, *_ in handed] == list(range(1, 200))
    assert all(start >= deadline and end >= start for _, start, deadline, end in handed)
    assert calls == [1], "after the start-up step the observer is not called again"
    assert main([*args, "--out", str(tmp_path / "unpaced")]) == 0
    assert (tmp_path / "paced" / "results.csv").read_bytes() == (tmp_path / "unpaced" / "results.csv").read_bytes()
