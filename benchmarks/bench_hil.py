"""Real-time figures of hardware-in-the-loop runs (``make bench``).

The LQR scenario of the single mass, run side by side in one bench:

* ``pacer alone``: the pacer with no work per step, 3 s at 1 kHz -- the scheduling floor of
  the machine (sleep wake-up latency, preemption by other processes);
* ``simulated, --realtime``: the plant FMU, the master paced to the wall clock (the pacer's
  own jitter, no card);
* ``HIL 500 Hz`` and ``HIL 1 kHz``: ``--swap plant=hil`` against a virtual rig served by
  ``ipcosim rig serve --clock wallclock`` in its own process (the card's clock paces the
  loop; the rig's physics runs on a 0.25 ms grid), with the controller's sample period and
  the master step set to the rate.

Each line reports the period jitter (p50 / p99 / max of |actual period - h|), the
overruns (the master's: steps starting more than half a period late; the card's: requests
that reached the rig after their sample instant), the worst step time, the real-time
factor and whether the task was met. The machines here are shared and noisy: these are
measurements, not pass/fail thresholds. The HIL runs use a 0.5 s watchdog
(``IPCOSIM_BENCH_HIL_WATCHDOG``) so that a stall of the VM is reported, not fatal.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from typing import Any

SCENARIO = os.environ.get("IPCOSIM_BENCH_HIL_SCENARIO", "single-mass-lqr")
STOP_TIME = float(os.environ.get("IPCOSIM_BENCH_HIL_STOP_TIME", "10.0"))
RATES = (500, 1000)
#: Watchdog timeout of the bench's HIL runs [s]: longer than the lab's 0.1 s, because a shared
#: VM can stall a process for longer than that, and the bench is to report timing, not to stop.
WATCHDOG = float(os.environ.get("IPCOSIM_BENCH_HIL_WATCHDOG", "0.5"))


def start_rig(plant: str = "single-mass", tick: float = 2.5e-4) -> tuple[subprocess.Popen, str]:
    """``ipcosim rig serve`` (wallclock, any free port) in its own process; returns it and its card id."""
    proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--plant", plant, "--clock",
                             "wallclock", "--tick", str(tick), "--port", "0", "--duration", "600"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if "card id" not in line:
        proc.kill()
        raise RuntimeError(f"the rig did not start: {line.strip() or 'no output'}")
    return proc, line.rsplit("card id", 1)[1].strip()


def _run(label: str, swaps: dict[str, str], step: float, overrides: dict[str, Any]) -> str:
    import ipcosim.harness

    with tempfile.TemporaryDirectory(prefix="ipcosim-bench-hil-") as out:
        result = ipcosim.harness.run(SCENARIO, stop_time=STOP_TIME, step=step, overrides=overrides, swaps=swaps,
                             realtime=True, out_dir=out, raise_on_error=False)
    m = result.metrics
    us = 1e6
    status = "ok" if result.error is None else f"FAILED: {result.error}"
    card = f", card overruns {m['card_overruns']}" if "card_overruns" in m else ""
    return (f"{label:28s} jitter p50 {m.get('period_jitter_p50_s', 0) * us:6.1f} us  p99 "
            f"{m.get('period_jitter_p99_s', 0) * us:7.1f} us  max {m.get('period_jitter_max_s', 0) * us:8.1f} us; "
            f"overruns {m.get('overruns', '?')}{card}; worst step {m.get('worst_step_time_s', 0) * us:7.0f} us; "
            f"RTF {m.get('real_time_factor') or 0:.3f}; settling {m.get('settling_time_s')} s, "
            f"upright {m.get('upright')} [{status}]")


def pacer_floor(seconds: float = 3.0, period: float = 1e-3) -> str:
    """The pacer alone (no work per step): the machine's scheduling floor for the figures below."""
    from ipcosim.harness.master.realtime import Pacer

    pacer = Pacer(period)
    pacer.start()
    for n in range(int(round(seconds / period))):
        pacer.begin(n)
        pacer.end(n)
    st = pacer.stats()
    us = 1e6
    return (f"{'pacer alone, 1 kHz':28s} jitter p50 {st.period_jitter_p50 * us:6.1f} us  p99 "
            f"{st.period_jitter_p99 * us:7.1f} us  max {st.period_jitter_max * us:8.1f} us; overruns {st.overruns} "
            f"of {st.steps}")


def run() -> list[str]:
    """Bench lines (see the module docstring)."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines = [f"HIL real time: {SCENARIO}, {STOP_TIME:g} s per run, virtual rig over TCP on 127.0.0.1 "
             f"({os.cpu_count()} CPUs, load average {load:.2f} at start)", pacer_floor()]
    try:
        lines.append(_run("simulated, --realtime 1 kHz", {}, 1e-3, {}))
    except Exception as exc:  # noqa: BLE001 -- the bench reports what it cannot run
        return lines + [f"  skipped: {SCENARIO} cannot run here ({type(exc).__name__}: {exc})"]
    proc, card_id = start_rig()
    old = os.environ.get("IPCOSIM_HIL_URI")
    os.environ["IPCOSIM_HIL_URI"] = f"q4:{card_id}"
    try:
        for rate in RATES:
            h = 1.0 / rate
            lines.append(_run(f"HIL {rate} Hz (wallclock rig)", {"plant": "hil"}, h,
                              {"controller.sample_period": h, "plant.watchdog_timeout": WATCHDOG}))
            time.sleep(0.2)
    finally:
        if old is None:
            os.environ.pop("IPCOSIM_HIL_URI", None)
        else:
            os.environ["IPCOSIM_HIL_URI"] = old
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    return lines


if __name__ == "__main__":
    print("\n".join(run()))
