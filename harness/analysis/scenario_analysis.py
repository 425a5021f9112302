"""``ipcosim analyze`` of a scenario, whole: the loop's linear analysis (:mod:`.analyze`), the residual cycle
of the IP02's friction and encoder counts (:mod:`.residual_cycle`), and with an output folder the figures
(:mod:`.analyze_plots`) and ``analysis.json``."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ipcosim.fmus.params import KINDS
from ipcosim.harness.analysis.analyze import (
    Loop,
    analyze_loop,
    frequency_grid,
    loop_response,
    scenario_loop,
    sensor_loop,
)


def figure_responses(loop: Loop, result: Mapping[str, Any]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """What ``analyze_plots.plot_loop`` draws: a frequency grid and the loop's response over it, broken at
    the plant input and, when ``result`` has sensor margins, at each sensor."""
    from ipcosim.harness.analysis.analyze_plots import PLANT_INPUT

    w = frequency_grid(loop.T, 3000)
    breaks = {PLANT_INPUT: loop, **{name: sensor_loop(loop, j) for j, name in
                                    enumerate(result.get("sensor_margins") or ())}}
    return w, {name: loop_response(lp, w) for name, lp in breaks.items()}


def analyze(scenario: str, *, parameter_set: str | None = None, set: Mapping[str, float] | None = None,
            out: str | Path | None = None) -> dict[str, Any]:
    """Analyse a scenario's loop (see the module docstring), with the ``--set`` values ``set``; with ``out``
    also write the figures and ``analysis.json`` there.

    Examples
    --------
    >>> r = analyze("single-mass-lqr")                       # doctest: +SKIP
    >>> r["closed_loop_stable"], round(r["delay_margin_s"], 4)  # doctest: +SKIP
    (True, 0.0179)
    """
    import json

    loop, info = scenario_loop(scenario, parameter_set, set)

    result = {**info, **analyze_loop(loop)}
    if loop.kind in KINDS:   # the IP02's friction and counts together, by the describing functions
        from ipcosim.harness.analysis import residual_cycle

        result["residual_cycle"] = residual_cycle.report(scenario, parameter_set, set)
    if out is not None:
        from ipcosim.harness.analysis.analyze_plots import plot_loop
        from ipcosim.harness.support.extras import optional_figure

        title = f"{info['scenario']} ({info['parameter_set']}): loop at the plant input"
        result["figures"] = optional_figure(lambda: plot_loop(*figure_responses(loop, result), result, out, title),
                                            "the Bode, Nyquist and margin figures") or {}
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "analysis.json").write_text(json.dumps(result, indent=2))
    return result
