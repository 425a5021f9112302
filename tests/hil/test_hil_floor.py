"""The walkthrough's run on the in-process wallclock rig (``q4:0@inproc://...?clock=wallclock``) is as
steady as the host's floor: its late steps (>= 0.5 ms) judged against a bare C loop on ``clock_nanosleep``
measured just before and after it (``benchmarks/host_floor.py``), never against an absolute fraction.
Both under SCHED_FIFO where the OS permits it (as the other real-time tests of this shared machine run),
otherwise both without, and then a miss on a host that is not quiet is skipped with its figures
(``Beside.unjudged``: without real-time priority a run's lateness over the floor's grows with the load)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import host_floor
from ipcosim.harness.master.realtime import late_fraction

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.integration
#: SCHED_FIFO priority of the run and its floor, where permitted.
RT_PRIORITY = 20


@pytest.fixture(scope="module")
def hil_fmus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The single-mass LQR scenario's FMUs and its HIL adapter."""
    from ipcosim.fmus.pybuild import build_all

    out = tmp_path_factory.mktemp("floor-fmus")
    names = ["fmus/fmu_ip02_single_mass.py", "fmus/fmu_ip02_hil_single_mass.py", "controllers/fmu_setpoint.py",
             "controllers/fmu_lqr_single_mass.py"]
    build_all(out, scripts=[ROOT / n for n in names])
    return out


def test_the_in_process_rig_is_as_steady_as_the_hosts_floor(hil_fmus, tmp_path):
    env = dict(os.environ, IPCOSIM_FMU_PATH=str(hil_fmus), PYTHONPATH=str(ROOT),
               IPCOSIM_HIL_URI="q4:0@inproc://floor?clock=wallclock")
    priority = None if host_floor.rt_refusal(RT_PRIORITY) else RT_PRIORITY
    env.pop("IPCOSIM_RT_PRIORITY", None)
    env.update({"IPCOSIM_RT_PRIORITY": str(RT_PRIORITY)} if priority else {})

    def paced() -> float:
        out = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
        run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--swap",
                              "plant=hil", "--stop-time", "5", "--out", str(out), "--quiet", "--overrun-budget", "1"],
                             capture_output=True, text=True, timeout=300, cwd=ROOT, env=env)
        assert run.returncode == 0, run.stderr
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["upright"] is True and metrics["realtime_steps"] == 5000
        return late_fraction(metrics)

    try:
        judged = host_floor.beside_floor(paced, priority=priority)
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))
    if judged.unjudged(priority):
        pytest.skip(judged.unjudged(priority))
    assert judged.within, str(judged)
