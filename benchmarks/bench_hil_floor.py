"""The README's HIL walkthrough in real time, beside the host's floor (``python -m benchmarks.bench hil_floor``).

Three subjects pace the same 5,000 steps (5 s at 1 kHz) and count the steps that start 0.5 ms or
more late (:data:`~ipcosim.harness.master.realtime.LATE_S`: the run's own histogram,
:func:`~ipcosim.harness.master.realtime.late_fraction`, and the probe's count use the one threshold):

* ``floor``: the host's floor, a bare C loop on ``clock_nanosleep`` (:mod:`benchmarks.host_floor`);
* ``in-process``: ``ipcosim run single-mass-lqr --swap plant=hil`` on the in-process wallclock rig
  (``IPCOSIM_HIL_URI=q4:0@inproc://bench?clock=wallclock``);
* ``TCP``: the README's walkthrough, ``ipcosim rig serve`` in a second process and the same run on it.

Each in four conditions: without and with real-time priority (SCHED_FIFO 50 for every process of
the subject: ``IPCOSIM_RT_PRIORITY``, ``rig serve --rt-priority``, the probe's ``--priority``;
skipped, with the reason, where the OS refuses it), on the quiet host and with two CPU hogs (two
busy-loop processes under the default policy, at the bench's nice value). A reference cell,
``loaded, own slice``, runs the loaded no-RT runs again with ``IPCOSIM_RT_SLICE_US=0`` (both
processes on the fair scheduler's own slice instead of the 0.7 ms they ask for by default), beside
the same floor. A reference subject of the no-RT cells, ``floor at TCP's CPU``, is the floor's probe
spending, after each wake-up, the CPU time a step of the TCP run just before it took (the run's
``loop_cpu_per_step_us``): what the host does to any loop that computes that long each period. Two
more reference subjects measure what a rig in a second process costs whatever it is written in: the
``pair floor`` (every cell) is the probe exchanging a message with a forked C peer over loopback TCP
every period, as the run does with its rig, with no computation on either side; ``pair at TCP's
CPU`` (the no-RT cells) is that pair spending the TCP run's CPU time a step on the loop's side and
its rig's CPU time a request (the ``ipcosim rig serve`` process's, from /proc) on the peer's. Every
repetition runs every subject in every condition, the subjects' order
rotating from one repetition to the next, so the floor is measured interleaved with the runs and
shares the host's drift. A 2 kHz row (the walkthrough with ``--step 0.0005 --set
controller.sample_period=0.0005``, beside the floor at 2 kHz) ends each repetition. Figures: the
median and the worst late fraction of each cell, and each run's median as a ratio to the floor's.

Targets (from the walkthrough's promise: as steady as the in-process rig, at the host's floor):

* the walkthrough (TCP, no real-time priority, quiet): median at most twice the in-process rig's and
  at most three times the floor's (:func:`benchmarks.host_floor.ratio`: a floor of no late step
  counts as one step in 5,000); when the host is quiet (the floor's median at most 0.3 %), also every
  run upright and at most 1 % late (its default budget);
* TCP with real-time priority and two hogs: the worst run at most max(0.5 %, three times the floor's
  worst), every run upright;
* 2 kHz over TCP: median at most 1 % late when the host is quiet (the floor's median at most
  0.3 %); on a host above that the figure is printed and not judged.

``python -m benchmarks.bench_hil_floor [--repetitions N] [--quick]`` runs this module alone through
``benchmarks.bench`` (last.json included); ``make bench`` takes ``IPCOSIM_BENCH_HIL_REPETITIONS``
(default 5). Five repetitions take about 8 minutes on a 2-core host, ``--quick`` (2) about 3.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from benchmarks import host_floor
from benchmarks.bench_hil import RT_PRIORITY, served
from benchmarks.targets import figure, fmt, target

#: The README's walkthrough, as its reader types it (terminal 1, terminal 2).
WALKTHROUGH = ("ipcosim rig serve", "ipcosim run single-mass-lqr --swap plant=hil")
#: The in-process wallclock rig of the same run.
INPROC_URI = "q4:0@inproc://bench?clock=wallclock"
SUBJECTS = ("floor", "in-process", "TCP")
#: The reference subject of the no-RT cells: the floor's probe spending, after each wake-up, the CPU
#: time a step of the TCP run beside it took (its ``loop_cpu_per_step_us``).
AT_CPU = "floor at TCP's CPU"
#: The reference subject of every cell: the floor of two processes exchanging a message each period
#: (the probe's ``--pair``: C on both sides, no computation), what any run with a rig in a second
#: process meets before it computes anything.
PAIR = "pair floor"
#: The reference subject of the no-RT cells: the pair spending the TCP run's CPU time a step on the
#: loop's side and its rig's CPU time a request on the peer's.
PAIR_AT_CPU = "pair at TCP's CPU"
REFERENCES = (AT_CPU, PAIR, PAIR_AT_CPU)
LOADS = ("quiet", "loaded")
HOGS = 2
STOP_TIME = 5.0
REPETITIONS = 5
QUICK_REPETITIONS = 2
#: The targets of the module doc.
OVER_INPROC, OVER_FLOOR, RT_LOADED_PCT, KHZ2_PCT = 2.0, 3.0, 0.5, 1.0
#: On a quiet host, every walkthrough run at most this late [%] (the run's default budget) and upright.
WALKTHROUGH_PCT = 1.0


@dataclass(frozen=True)
class Sample:
    """One paced run or floor: its late fraction (NaN when it wrote none), whether it stayed upright
    (None for the floor), its error line, and what SCHED_FIFO it got."""

    late: float
    upright: bool | None = None
    error: str | None = None
    fifo: str = ""
    cpu_us: float = float("nan")
    peer_cpu_us: float = float("nan")


def cli(command: str) -> list[str]:
    """A documented ``ipcosim ...`` command as an argv for this interpreter."""
    return [sys.executable, "-m", "ipcosim.harness.cli", *shlex.split(command)[1:]]


@contextmanager
def hogs(n: int) -> Iterator[None]:
    """``n`` busy-loop processes under the default policy (the bench's nice value) while the block runs
    (ended by their ids)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        time.sleep(0.5 if n else 0.0)
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait(timeout=30)


@contextmanager
def rig(rt: bool) -> Iterator[tuple[str, Callable[[], float]]]:
    """The walkthrough's ``ipcosim rig serve`` on a free port (``bench_hil.served``); yields its card URI
    and a function giving the CPU time its process has used [s] (NaN where /proc does not say)."""
    with served(cli(WALKTHROUGH[0]) + ["--port", "0", "--duration", "300"], rt) as (proc, uri):
        yield uri, lambda: process_cpu_s(proc.pid)


def process_cpu_s(pid: int) -> float:
    """The user and system CPU time process ``pid`` has used [s], from /proc (NaN without it)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def walkthrough(uri: str, rt: bool, period: float) -> Sample:
    """The walkthrough's run (``--realtime``, :data:`STOP_TIME`) on card ``uri``; its own late fraction."""
    from ipcosim.harness.master.realtime import late_fraction

    extra = [] if period == 1e-3 else ["--step", f"{period:g}", "--set", f"controller.sample_period={period:g}"]
    env = {k: v for k, v in os.environ.items() if k not in ("IPCOSIM_HIL_URI", "IPCOSIM_RT_PRIORITY")}
    env.update(IPCOSIM_HIL_URI=uri, **({"IPCOSIM_RT_PRIORITY": str(RT_PRIORITY)} if rt else {}))
    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-floor-") as out:
        cmd = cli(WALKTHROUGH[1]) + ["--realtime", "--stop-time", f"{STOP_TIME:g}", "--out", out, "--quiet",
                                     "--overrun-budget", "1", *extra]   # lateness is judged here, not by the run
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
        path = Path(out) / "metrics.json"
        m = json.loads(path.read_text()) if path.exists() else {}
    lines = done.stderr.strip().splitlines()
    error = (lines[-1] if lines else f"exit status {done.returncode}") if done.returncode else None
    late = late_fraction(m) if "lateness_histogram" in m else float("nan")
    fifo = (m.get("realtime_setup") or {}).get("sched_fifo", "")
    return Sample(late, bool(m.get("upright")) and not error, error, fifo, m.get("loop_cpu_per_step_us", float("nan")))


def measure(subject: str, rt: bool, period: float = 1e-3) -> Sample:
    """One sample of ``subject`` (see :data:`SUBJECTS`)."""
    if subject == "floor":
        f = host_floor.measure(period, round(STOP_TIME / period), RT_PRIORITY if rt else None)
        return Sample(f.late_fraction, fifo=f.sched_fifo)
    if subject == "in-process":
        return walkthrough(INPROC_URI, rt, period)
    with rig(rt) as (uri, rig_cpu):
        before = rig_cpu()
        run = walkthrough(uri, rt, period)
        per_request = (rig_cpu() - before) / round(STOP_TIME / period) * 1e6
        return dataclasses.replace(run, peer_cpu_us=per_request)


def at_cpu(run: Sample, pair: bool = False) -> Sample:
    """The floor's probe doing, after each wake-up, the CPU work of a step of ``run`` (NaN if it has none);
    with ``pair``, the pair's probe, its peer doing the CPU work of a request of ``run``'s rig."""
    if not run.cpu_us > 0 or (pair and not run.peer_cpu_us >= 0):
        return Sample(float("nan"))
    extra = {"pair": True, "peer_work": run.peer_cpu_us * 1e-6} if pair else {}
    return Sample(host_floor.measure(1e-3, round(STOP_TIME / 1e-3), work=run.cpu_us * 1e-6, **extra).late_fraction)


def pair_floor(rt: bool) -> Sample:
    """The pair's probe with no computation on either side (SCHED_FIFO for both with ``rt``)."""
    f = host_floor.measure(1e-3, round(STOP_TIME / 1e-3), RT_PRIORITY if rt else None, pair=True)
    return Sample(f.late_fraction, fifo=f.sched_fifo)


def rotated(items: Sequence[str], k: int) -> list[str]:
    """``items`` starting at its ``k``-th (mod its length)."""
    k %= len(items)
    return [*items[k:], *items[:k]]


Cell = tuple[str, str, bool]       # (subject, load or "2 kHz", rt)


def collect(repetitions: int, rt_modes: Sequence[bool]) -> dict[Cell, list[Sample]]:
    """Every sample of the matrix, interleaved (printed as they come: the whole takes minutes)."""
    got: dict[Cell, list[Sample]] = defaultdict(list)
    for rep in range(repetitions):
        for load in LOADS:
            with hogs(HOGS if load == "loaded" else 0):
                for rt in rt_modes:
                    for subject in rotated(SUBJECTS, rep):
                        got[(subject, load, rt)].append(measure(subject, rt))
                    references(got, (load, rt))
                    print(f"   repetition {rep + 1}, {load}, {_rt(rt)}: "
                          + ", ".join(f"{s} {_pct(got[(s, load, rt)][-1])}" for s in (*SUBJECTS, *REFERENCES)
                                      if (s, load, rt) in got), flush=True)
                if load == "loaded":
                    _own_slice(got, rep)
        for subject in rotated(("floor", "TCP"), rep):
            got[(subject, "2 kHz", False)].append(measure(subject, False, 5e-4))
        print(f"   repetition {rep + 1}, 2 kHz: floor {_pct(got[('floor', '2 kHz', False)][-1])}, "
              f"TCP {_pct(got[('TCP', '2 kHz', False)][-1])}", flush=True)
    return got


def references(got: dict[Cell, list[Sample]], condition: tuple[str, bool]) -> None:
    """The reference subjects of one condition (load, rt), after its runs: the pair's floor, and without
    RT priority the floor's and the pair's probes at the CPU of the TCP run just measured."""
    load, rt = condition
    got[(PAIR, load, rt)].append(pair_floor(rt))
    if not rt:
        tcp = got[("TCP", load, rt)][-1]
        got[(AT_CPU, load, rt)].append(at_cpu(tcp))
        got[(PAIR_AT_CPU, load, rt)].append(at_cpu(tcp, pair=True))


#: The reference cell: loaded, no RT priority, each process left on the fair scheduler's own slice.
OWN_SLICE = "loaded, own slice"


def _own_slice(got: dict[Cell, list[Sample]], rep: int) -> None:
    """The loaded no-RT runs again with ``IPCOSIM_RT_SLICE_US=0`` (the scheduler's own slice, for both
    processes), beside the same floor: what the slice request buys."""
    got[("floor", OWN_SLICE, False)].append(got[("floor", "loaded", False)][-1])
    before = os.environ.get("IPCOSIM_RT_SLICE_US")
    os.environ["IPCOSIM_RT_SLICE_US"] = "0"
    try:
        for subject in rotated(SUBJECTS[1:], rep):
            got[(subject, OWN_SLICE, False)].append(measure(subject, False))
    finally:
        os.environ.pop("IPCOSIM_RT_SLICE_US")
        os.environ.update({} if before is None else {"IPCOSIM_RT_SLICE_US": before})
    print(f"   repetition {rep + 1}, {OWN_SLICE}, no RT priority: "
          + ", ".join(f"{s} {_pct(got[(s, OWN_SLICE, False)][-1])}" for s in SUBJECTS[1:]), flush=True)


def _rt(rt: bool) -> str:
    return "RT priority" if rt else "no RT priority"


def _pct(s: Sample) -> str:
    return f"{100 * s.late:.2f} %" + ("" if not s.error else f" (failed: {_gist(s.error)})")


def _gist(error: str) -> str:
    """The first clause of a run's error line (what tripped), for the table."""
    words = error.removeprefix("ipcosim run: error: ").split(": ")
    if not (words[0].startswith("component ") and len(words) > 2):
        return ": ".join(words[:2])[:100]
    head = words[2].split(" at ")[0]                 # component X: fmi2DoStep returned ... at t = T: what tripped
    return f"{head}: {words[3].split(' at ')[0]}" if head.endswith("refused") and len(words) > 3 else head[:100]


def median(samples: list[Sample]) -> float:
    """Median late fraction (NaN if any run wrote none: a failed run is never left out)."""
    return float(np.median([s.late for s in samples]))


def worst(samples: list[Sample]) -> float:
    """Largest late fraction (NaN if any run wrote none)."""
    return float(np.max([s.late for s in samples]))


def cell_figures(got: dict[Cell, list[Sample]], load: str, rt: bool) -> str:
    """The row of one condition, its figures recorded: median / worst of each subject, the runs' ratio."""
    cell = "".join(c for c in load.lower() if c.isalnum())
    key, label = f"hil_floor.{cell}_{'rt' if rt else 'plain'}", f"{load}, {_rt(rt)}"
    floor = median(got[("floor", load, rt)])
    parts = []
    for subject in (s for s in (*SUBJECTS, *REFERENCES) if (s, load, rt) in got):
        samples, name = got[(subject, load, rt)], f"{key}_{''.join(c for c in subject.lower() if c.isalnum())}"
        anchor = {} if subject == "floor" else {"anchor": f"the floor's median beside it: {fmt(100 * floor)} %"}
        what = f"{subject}, {label}: late steps,"
        part = (f"{subject} {figure(name + '_median_pct', 100 * median(samples), '%', what=what + ' median', **anchor)}"
                f" / {figure(name + '_worst_pct', 100 * worst(samples), '%', what=what + ' worst', **anchor)}")
        if subject != "floor":
            ratio = figure(name + "_over_floor", host_floor.ratio(median(samples), floor), "x",
                           what=f"{subject}, {label}: median over the floor's median", **anchor)
            part += f" ({ratio})"
        if subject in SUBJECTS[1:]:
            cpu = float(np.median([s.cpu_us for s in samples]))
            part += f", {fmt(cpu)} us CPU a step{_rig_cpu(samples)}"
            part += f", upright {sum(bool(s.upright) for s in samples)}/{len(samples)}"
            failed = [_gist(s.error) for s in samples if s.error]
            part += f" (failed: {', '.join(sorted(set(failed)))})" if failed else ""
        parts.append(part)
    return f"{label:32s} " + "; ".join(parts)


def _rig_cpu(samples: list[Sample]) -> str:
    """The TCP rig's CPU time a request, where it was measured."""
    cpu = [s.peer_cpu_us for s in samples if s.peer_cpu_us >= 0]
    return f" (the rig's {fmt(float(np.median(cpu)))} us a request)" if cpu else ""


def judge(got: dict[Cell, list[Sample]], rt_done: bool) -> list[str]:
    """The targets of the module doc, each on its line."""
    lines = [_walkthrough_target(got)] + ([_rt_loaded_target(got)] if rt_done else [])
    return lines + [_2khz_target(got)]


def _walkthrough_target(got: dict[Cell, list[Sample]]) -> str:
    runs = got[("TCP", "quiet", False)]
    tcp, inproc, floor = (median(got[(s, "quiet", False)]) for s in ("TCP", "in-process", "floor"))
    what = "README walkthrough (TCP, no RT priority, quiet): median late fraction over"
    line = (f"walkthrough (TCP, quiet, no RT priority), median over the in-process rig's "
            f"{fmt(host_floor.ratio(tcp, inproc))}x "
            + target("hil_floor.target_walkthrough_over_inproc", host_floor.ratio(tcp, inproc), OVER_INPROC, "x",
                     what=f"{what} the in-process rig's")
            + f"; over the floor's {fmt(host_floor.ratio(tcp, floor))}x "
            + target("hil_floor.target_walkthrough_over_floor", host_floor.ratio(tcp, floor), OVER_FLOOR, "x",
                     what=f"{what} the floor's (a floor of no late step: one in 5000)"))
    upright, what = sum(bool(s.upright) for s in runs), "README walkthrough (TCP, no RT priority), quiet host"
    if floor > host_floor.QUIET:
        return line + f"; upright {upright} of {len(runs)}, not judged: the floor's median is above 0.3 %"
    return (line + f"; upright {upright} of {len(runs)} "
            + target("hil_floor.target_walkthrough_quiet_upright", upright, len(runs), at_most=False,
                     what=f"{what}: runs upright (the floor at most 0.3 %)")
            + f", worst {fmt(100 * worst(runs))} % "
            + target("hil_floor.target_walkthrough_quiet_worst_pct", 100 * worst(runs), WALKTHROUGH_PCT, "%",
                     what=f"{what}: worst late fraction (the floor at most 0.3 %)"))


def _rt_loaded_target(got: dict[Cell, list[Sample]]) -> str:
    runs, floors = got[("TCP", "loaded", True)], got[("floor", "loaded", True)]
    limit = max(RT_LOADED_PCT / 100, host_floor.allowance([worst(floors)]))
    what = "TCP rig, RT priority, two CPU hogs:"
    upright = sum(bool(s.upright) for s in runs)
    return (f"TCP, RT priority, two hogs: worst {fmt(100 * worst(runs))} % "
            + target("hil_floor.target_loaded_rt_tcp_worst_pct", 100 * worst(runs), 100 * limit, "%",
                     what=f"{what} worst late fraction (at most max(0.5 %, 3 x the floor's worst))")
            + f"; upright {upright} of {len(runs)} "
            + target("hil_floor.target_loaded_rt_tcp_upright", upright, len(runs),
                     at_most=False, what=f"{what} runs upright at the end"))


def _2khz_target(got: dict[Cell, list[Sample]]) -> str:
    tcp, floor = median(got[("TCP", "2 kHz", False)]), median(got[("floor", "2 kHz", False)])
    key, what = "hil_floor.target_2khz_tcp_median_pct", "2 kHz walkthrough (TCP, no RT priority): median late fraction"
    if floor <= host_floor.QUIET:
        verdict = target(key, 100 * tcp, KHZ2_PCT, "%", what=f"{what} (floor <= 0.3 %)")
        return f"2 kHz over TCP: median {fmt(100 * tcp)} % {verdict}"
    shown = figure(key, 100 * tcp, "%", what=what, anchor="not judged: the floor's median above 0.3 %")
    return f"2 kHz over TCP: median {shown}, not judged: the floor's median {fmt(100 * floor)} % is above 0.3 %"


def repetitions() -> int:
    """``IPCOSIM_BENCH_HIL_REPETITIONS`` (default :data:`REPETITIONS`)."""
    text = os.environ.get("IPCOSIM_BENCH_HIL_REPETITIONS", str(REPETITIONS))
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"IPCOSIM_BENCH_HIL_REPETITIONS={text}: expected a whole number >= 1")
    return int(text)


def run() -> list[str]:
    """Lines for ``make bench``: the matrix (median / worst, ratio to the floor), then the targets."""
    reps, refusal = repetitions(), host_floor.rt_refusal(RT_PRIORITY)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"   HIL late steps (>= 0.5 ms late), {reps} repetitions of {STOP_TIME:g} s, {os.cpu_count()} CPUs, "
          f"load average {load:.2f} at start; RT priority: "
          f"{'SCHED_FIFO ' + str(RT_PRIORITY) if refusal is None else 'not measured: ' + refusal}", flush=True)
    host_floor.probe_binary()   # no compiler: the module fails with the reason before any run
    rt_modes = (False, True) if refusal is None else (False,)
    got = collect(reps, rt_modes)
    lines = ["late steps per cell: median / worst of the runs (the runs' median over the floor's median)"]
    lines += [cell_figures(got, load, rt) for load in LOADS for rt in rt_modes]
    lines += [cell_figures(got, OWN_SLICE, False), cell_figures(got, "2 kHz", False)]
    return lines + judge(got, refusal is None)


def main(argv: Sequence[str] | None = None) -> int:
    """Run this module alone through ``benchmarks.bench`` (its figures land in last.json)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_hil_floor",
                                     description="The HIL walkthrough's late steps beside the host's floor.")
    parser.add_argument("--repetitions", type=int, default=REPETITIONS, help=f"default {REPETITIONS}")
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_REPETITIONS} repetitions")
    args = parser.parse_args(argv)
    if args.repetitions < 1:
        parser.error(f"--repetitions {args.repetitions}: expected a whole number >= 1")
    os.environ["IPCOSIM_BENCH_HIL_REPETITIONS"] = str(QUICK_REPETITIONS if args.quick else args.repetitions)
    from benchmarks.bench import main as bench

    return bench(["bench_hil_floor"])


if __name__ == "__main__":
    sys.exit(main())
