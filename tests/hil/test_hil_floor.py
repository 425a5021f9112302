"""The README's HIL walkthrough (``ipcosim rig serve`` and ``ipcosim run single-mass-lqr --swap plant=hil`` in
two processes) and the same run on the in-process wallclock rig are as steady as the host's floor: their
late steps (>= 0.5 ms) judged against a bare C loop on ``clock_nanosleep`` measured just before and after
each (``benchmarks/host_floor.py``), never against an absolute fraction. The runs are the HIL bench's own
(``benchmarks/bench_hil_floor.py``), 5 s each. Run and floor under SCHED_FIFO where the OS permits it (as
the other real-time tests of this shared machine run), otherwise both without, and then a miss on a host
that is not quiet is skipped with its figures (``Beside.unjudged``: without real-time priority a run's
lateness over the floor's grows with the load)."""
from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import bench_hil_floor as bench
from benchmarks import host_floor

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def hil_fmus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The single-mass LQR scenario's FMUs and its HIL adapter."""
    from ipcosim.fmus.pybuild import build_all

    out = tmp_path_factory.mktemp("floor-fmus")
    names = ["fmus/fmu_ip02_single_mass.py", "fmus/fmu_ip02_hil_single_mass.py", "controllers/fmu_setpoint.py",
             "controllers/fmu_lqr_single_mass.py"]
    build_all(out, scripts=[ROOT / n for n in names])
    return out


@pytest.mark.parametrize("subject", ["in-process", "TCP"])
def test_the_walkthrough_is_as_steady_as_the_hosts_floor(subject, hil_fmus, monkeypatch):
    monkeypatch.setenv("IPCOSIM_FMU_PATH", str(hil_fmus))
    rt = host_floor.rt_refusal(bench.RT_PRIORITY) is None

    def paced() -> float:
        run = bench.measure(subject, rt)
        assert run.error is None and run.upright, run.error
        return run.late

    priority = bench.RT_PRIORITY if rt else None
    try:
        judged = host_floor.beside_floor(paced, priority=priority)
    except host_floor.FloorUnavailable as exc:
        pytest.skip(str(exc))
    if judged.unjudged(priority):
        pytest.skip(judged.unjudged(priority))
    assert judged.within, str(judged)
