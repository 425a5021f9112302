"""Cost of the control laws (``make bench``), measured side by side in one run.

For every law and plant: the time of one ``step`` of the pure law (median over a 10 s closed
loop at 1 ms), the whole pure closed loop of 10 s (plant + law, ``ipcosim.controllers.simulate``) and
its real-time factor, and the LQR design itself with both back ends (python-control and the
scipy path the FMUs run at initialization). Target: the sum of the ten laws' median step times.
"""
from __future__ import annotations

import statistics
import time

from benchmarks.targets import figure, target
from ipcosim.controllers.catalog import KINDS, LAWS, default_preset, make_law
from ipcosim.controllers.laws.lqr import lqr_design_for
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.params import preset

#: Target: the mean of the median law steps (ten laws measured 26-32 us together, so 2.6-3.2 us
#: a law; twelve with the LQG laws 44.8 us, 3.7 us a law, on a quiet machine). At the reference
#: machine speed (``targets.REFERENCE_SPEED_MS``; scaled on a slower machine): 3.6 us measured
#: (4.58 us at 29.2 ms), so the limit is 1.3 times that.
LAW_STEP_US = 4.7


class _Timed:
    """Wraps a law and accumulates the time spent in its ``step``."""

    def __init__(self, law) -> None:  # noqa: ANN001
        self.law, self.elapsed, self.calls, self.times = law, 0.0, 0, []
        self.sample_period = law.sample_period

    def reset(self) -> None:
        self.law.reset()

    def step(self, y, r):  # noqa: ANN001, ANN201
        t = time.perf_counter()
        v = self.law.step(y, r)
        dt = time.perf_counter() - t
        self.elapsed += dt
        self.times.append(dt)
        self.calls += 1
        return v


def run() -> list[str]:
    lines = ["law           plant         law step us   loop 10 s [s]   real-time factor   law share"]
    steps = []
    for law in LAWS:
        for kind in KINDS:
            timed = _Timed(make_law(kind, law))
            t = time.perf_counter()
            run_loop(timed, preset(default_preset(kind)))  # type: ignore[arg-type]
            total = time.perf_counter() - t
            steps.append(1e6 * statistics.median(timed.times))
            lines.append(f"{law:13s} {kind:13s} {steps[-1]:11.1f}   {total:13.3f}   "
                         f"{10.0 / total:16.1f}   {timed.elapsed / total:8.0%}")
    for kind in KINDS:
        row = []
        for backend in ("control", "scipy"):
            t = time.perf_counter()
            for _ in range(20):
                lqr_design_for(kind, preset(default_preset(kind)), backend=backend)
            row.append((time.perf_counter() - t) / 20)
        lines.append(f"LQR design {kind}: python-control {1e3 * row[0]:.2f} ms, scipy "
                     + figure(f"controllers.lqr_design_{kind.replace('-', '_')}_ms", 1e3 * row[1], "ms",
                              what=f"LQR design, {kind}, scipy") + " "
                     f"(ratio {row[0] / row[1]:.2f})")
    lines.append(f"mean of the {len(steps)} median law steps: {sum(steps) / len(steps):.2f} us ("
                 + target("controllers.law_step_mean_us", sum(steps) / len(steps), LAW_STEP_US, "us",
                          what="mean of the median law step times", per_speed=True)
                 + f"; together {sum(steps):.1f} us)")
    return lines
