"""The host's floor: how many steps of a bare 1 kHz loop start late on this host, now.

``benchmarks/host_floor.c`` paces a loop that does no work on ``clock_nanosleep`` to absolute
deadlines and counts the steps that start :data:`~ipcosim.harness.master.realtime.LATE_S` or more
after theirs, the threshold of a paced run's own late fraction
(:func:`~ipcosim.harness.master.realtime.late_fraction`). Whatever the host does to that loop (a
shared VM's stalls, another tenant, the CPU governor) it does to every paced run beside it, so a
real-time figure is read against the floor measured in the same minutes, never against an
absolute fraction: the HIL bench (``benchmarks/bench_hil.py``) and the tests that pace use
:func:`measure` and :func:`allowance`.

The probe is compiled at first use with the system's C compiler (``cc``, or ``$CC``) into the
temporary directory; :class:`FloorUnavailable` says why it cannot run (no compiler, a compile
error), for a bench to report and a test to skip with.

``python -m benchmarks.host_floor [--period S] [--steps N] [--priority P]`` prints one measurement.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.master.realtime import LATE_S

SOURCE = Path(__file__).resolve().parent / "host_floor.c"
#: Steps of one measurement: 5 s at 1 kHz, as many as the bench's and the tests' paced runs.
STEPS = 5000
#: A host is *quiet* while its floor is late at most this fraction of steps. Without real-time priority a
#: paced run needs CPU time each step, which the floor does not: on a loaded host the scheduler shares it
#: out by slices of milliseconds, and a run's lateness over the floor's grows with the load (measured: a
#: paced run five times its floor at a load average of 15 on 2 CPUs), so it is judged on a quiet host only.
QUIET = 0.003


class FloorUnavailable(IpcosimError, RuntimeError):
    """The probe cannot be built or run here; the message says why, in one line."""


@dataclass(frozen=True)
class Floor:
    """One measurement of the host's floor (fractions of steps; seconds)."""

    late_fraction: float
    late: int
    steps: int
    period: float
    lateness_p99: float
    lateness_max: float
    sched_fifo: str


def rt_refusal(priority: int) -> str | None:
    """Why this host refuses SCHED_FIFO at ``priority`` (None: it permits it; tried on this process and undone)."""
    if not hasattr(os, "sched_setscheduler"):
        return "the OS has no SCHED_FIFO"
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return f"SCHED_FIFO priority {priority} refused: {exc.strerror or exc} (needs CAP_SYS_NICE or rtprio)"
    os.sched_setscheduler(0, policy, param)
    return None


def probe_binary() -> Path:
    """The compiled probe (built once per version of its source, in the temporary directory).

    Raises
    ------
    FloorUnavailable
        No C compiler on PATH, or the probe does not compile.
    """
    cc = os.environ.get("CC") or shutil.which("cc")
    if not cc or not shutil.which(cc):
        raise FloorUnavailable("no C compiler (cc) on PATH to build the host's floor probe benchmarks/host_floor.c")
    digest = hashlib.sha256(SOURCE.read_bytes()).hexdigest()[:12]
    exe = Path(tempfile.gettempdir()) / f"ipcosim-host-floor-{digest}" / "host_floor"
    if exe.is_file():
        return exe
    exe.parent.mkdir(parents=True, exist_ok=True)
    tmp = exe.with_name(f"host_floor.{os.getpid()}")
    built = subprocess.run([cc, "-O2", "-o", str(tmp), str(SOURCE)], capture_output=True, text=True)
    if built.returncode:
        first = (built.stderr.strip().splitlines() or [f"exit status {built.returncode}"])[0]
        raise FloorUnavailable(f"{SOURCE.name} does not compile with {cc}: {first}")
    tmp.replace(exe)
    return exe


def measure(period: float = 1e-3, steps: int = STEPS, priority: int | None = None, work: float = 0.0, *,
            pair: bool = False, peer_work: float = 0.0) -> Floor:
    """Run the probe once: ``steps`` steps of ``period`` seconds (the same threshold as the runs).

    Parameters
    ----------
    period : float
        Step period [s].
    steps : int
        Number of steps.
    priority : int, optional
        SCHED_FIFO priority of the probe (None: the default policy); a refusal is in ``sched_fifo``.
    work : float
        CPU time the probe spends after each wake-up [s] (0: none, the bare floor), as a step computes.
    pair : bool
        The floor of two processes exchanging a message every period: a forked peer on a loopback TCP
        connection answers each step's message, which the loop waits for (half its ``work`` before
        the exchange, half after), as a run waits for a rig in a second process.
    peer_work : float
        With ``pair``: the CPU time the peer spends on each answer [s].

    Returns
    -------
    Floor
        The late fraction and the lateness of the probe's steps.
    """
    cmd = [str(probe_binary()), "--period-ns", str(round(period * 1e9)), "--steps", str(steps),
           "--late-ns", str(round(LATE_S * 1e9)), "--priority", str(priority or 0),
           "--work-ns", str(max(0, round(work * 1e9)))]
    if pair:
        cmd += ["--pair", "--peer-work-ns", str(max(0, round(peer_work * 1e9)))]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60 + 2 * steps * period)
    if done.returncode:
        raise FloorUnavailable(f"the host's floor probe failed: {done.stderr.strip() or done.returncode}")
    out = json.loads(done.stdout)
    return Floor(late_fraction=out["late_fraction"], late=out["late"], steps=out["steps"], period=period,
                 lateness_p99=out["lateness_p99_ns"] * 1e-9, lateness_max=out["lateness_max_ns"] * 1e-9,
                 sched_fifo=out["sched_fifo"])


def allowance(floors: Sequence[float], steps: int = STEPS, factor: float = 3.0) -> float:
    """The late fraction a paced run may have beside ``floors`` (the floor's fractions measured with it).

    ``factor`` times the largest of them, and never less than ``factor`` times one step in ``steps``:
    a floor of no late step says only that the host delayed fewer than one step in that many.

    Parameters
    ----------
    floors : sequence of float
        Late fractions of the host's floor, measured interleaved with the run.
    steps : int
        Steps of one floor measurement (its resolution).
    factor : float
        How many times the floor the run may be late.

    Returns
    -------
    float
        The largest late fraction within the floor.
    """
    return factor * max(max(floors, default=0.0), 1.0 / steps)


def ratio(late: float, floor: float, steps: int = STEPS) -> float:
    """``late`` over ``floor`` (both late fractions), a floor of no late step counting as one in ``steps``."""
    return late / max(floor, 1.0 / steps)


@dataclass(frozen=True)
class Beside:
    """A paced run's late fraction beside the floors measured before and after it (:func:`beside_floor`)."""

    late: float
    floors: tuple[float, ...]
    limit: float
    attempts: int

    @property
    def quiet(self) -> bool:
        """Whether the host was quiet beside the run (every floor at most :data:`QUIET`)."""
        return max(self.floors) <= QUIET

    @property
    def within(self) -> bool:
        """Whether the run was late no more than its :func:`allowance`."""
        return self.late <= self.limit

    def unjudged(self, priority: int | None) -> str | None:
        """Why a run outside its allowance says nothing of the loop (None: the verdict stands): it had no
        real-time priority (``priority`` None) on a host that was not quiet."""
        if self.within or priority is not None or self.quiet:
            return None
        return (f"without real-time priority on a host that is not quiet (floor above {100 * QUIET:g} %) a paced "
                f"run's lateness grows with the load: {self}")

    def __str__(self) -> str:
        floors = ", ".join(f"{100 * f:.2f} %" for f in self.floors)
        return (f"{100 * self.late:.2f} % of the run's steps late (>= {1e3 * LATE_S:g} ms), the host's floor "
                f"{floors} beside it: allowed {100 * self.limit:.2f} % (attempt {self.attempts})")


def beside_floor(paced: Callable[[], float], *, period: float = 1e-3, priority: int | None = None,
                 factor: float = 3.0, attempts: int = 2) -> Beside:
    """Run ``paced`` between two measurements of the floor and judge it against them.

    A run outside its allowance is run again (with its floors) up to ``attempts`` times: one burst
    of the host's stalls can land on the run and miss both floors, two in a row seldom do.

    Parameters
    ----------
    paced : callable
        Runs the paced loop once and returns its late fraction
        (:func:`~ipcosim.harness.master.realtime.late_fraction` of its metrics).
    period : float
        The loop's step period [s]; the floor paces the same.
    priority : int, optional
        SCHED_FIFO priority of the floor, as the run's.
    factor, attempts
        :func:`allowance`'s factor; how many times the run may be tried.

    Returns
    -------
    Beside
        The last attempt (the first within its allowance, or the last outside it).

    Raises
    ------
    FloorUnavailable
        The floor cannot be measured here (for a test to skip with).
    """
    probe_binary()
    for attempt in range(1, attempts + 1):
        before = measure(period, STEPS, priority).late_fraction
        late = paced()
        floors = (before, measure(period, STEPS, priority).late_fraction)
        judged = Beside(late, floors, allowance(floors, STEPS, factor), attempt)
        if judged.within:
            break
    return judged


def main(argv: Sequence[str] | None = None) -> int:
    """Print one measurement as JSON (exit status 1 with one line when the probe cannot run)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.host_floor", description=__doc__.splitlines()[0])
    parser.add_argument("--period", type=float, default=1e-3, help="step period [s] (default 0.001)")
    parser.add_argument("--steps", type=int, default=STEPS, help=f"steps (default {STEPS})")
    parser.add_argument("--priority", type=int, default=None, help="SCHED_FIFO priority (default: none)")
    args = parser.parse_args(argv)
    try:
        floor = measure(args.period, args.steps, args.priority)
    except FloorUnavailable as exc:
        print(f"host_floor: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(floor.__dict__))
    return 0


if __name__ == "__main__":
    sys.exit(main())
