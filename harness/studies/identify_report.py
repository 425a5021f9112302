"""What an identification writes (:mod:`ipcosim.harness.studies.identify`): the identified constants as a
parameter set (``identified.ssv``) and its figure (``identified.png``: measured against simulated readings).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ipcosim.harness.studies.identify_result import INVALID_COUNTS, Identification


def write_identified(result: Identification, out: Path) -> list[Path]:
    """``out/identified.ssv`` (the identified constants as ``plant.<name>``, for ``--parameter-file``; only for a
    valid fit, :attr:`Identification.valid`) and ``out/identified.png`` (:func:`identified_figure`).

    Returns
    -------
    list of Path
        The files written (the plot only where matplotlib is installed).
    """
    from ipcosim.harness.scenario.ssv import ssv_text

    out.mkdir(parents=True, exist_ok=True)
    written = []
    if result.valid:
        ssv = out / "identified.ssv"
        values = {f"plant.{n}": v["value"] for n, v in result.parameters.items()}
        ssv.write_text(ssv_text(values, name="identified", description=f"{result.plant} plant identified from "
                                                                       f"{result.source}"))
        written.append(ssv)
    from ipcosim.harness.support.extras import optional_figure, require

    if optional_figure(lambda: require("matplotlib") or True, "identified.png") is None:
        return written
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = identified_figure(result)
    fig.savefig(out / "identified.png", dpi=110)
    plt.close(fig)
    return written + [out / "identified.png"]


#: How the plot shows each kind of output: (factor from SI, unit).
_PLOT_UNITS = {"pendulum_angle": (1e3, "mrad")}


def identified_figure(result: Identification) -> Any:
    """The identification's figure: per output, the measured and the simulated reading [mm or mrad] above their
    difference in encoder counts (the fitted part's largest difference in the label, +-0.5 count marked: what the
    true model leaves), the held-out quarter shaded; a fit that is not valid says so in the title."""
    import matplotlib.pyplot as plt

    n = len(result.outputs)
    fig, axes = plt.subplots(2 * n, 1, sharex=True, figsize=(9, 2.1 * 2 * n),
                             gridspec_kw={"height_ratios": [2, 1] * n})
    for j, name in enumerate(result.outputs):
        ax, res = axes[2 * j], axes[2 * j + 1]
        factor, unit = _PLOT_UNITS.get(name, (1e3, "mm"))
        offset = math.pi if name == "pendulum_angle" and abs(result.measured[0, j] - math.pi) < 1 else 0.0
        ax.plot(result.time, (result.measured[:, j] - offset) * factor, lw=0.8, label="measured")
        ax.plot(result.time, (result.simulated[:, j] - offset) * factor, lw=0.8, ls="--",
                label="simulated (identified)")
        ax.set_ylabel(f"{name}{' - pi' if offset else ''}\n[{unit}]", fontsize=8)
        ax.set_title(f"{name}: held-out fit {result.fit[name]:.1%} (1 - NRMSE)", fontsize=8, loc="left")
        counts = (result.measured[:, j] - result.simulated[:, j]) / result.resolutions.get(name, 1.0)
        res.plot(result.time, counts, lw=0.6, color="C3")
        for level in (-0.5, 0.5):
            res.axhline(level, color="k", lw=0.5, ls=":")
        res.set_ylabel("residual\n[counts]", fontsize=8)
        res.set_title(f"measured - simulated; largest over the fitted part "
                      f"{result.largest_residual_counts.get(name, float('nan')):.2f} counts (dotted: +-0.5)",
                      fontsize=8, loc="left")
        for a in (ax, res):
            a.axvspan(result.held_out_from_s, result.time[-1], color="0.9", zorder=-1)
            a.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s] (shaded: held out of the fit)")
    head = f"{result.plant} identified from {Path(result.source).parent.name or result.source}"
    if not result.valid:
        fig.suptitle(f"{head}: NOT VALID, residual {max(result.largest_residual_counts.values()):.1f} counts "
                     f"(> {INVALID_COUNTS:g}): the intervals claim nothing", color="C3", fontsize=10)
    else:
        fig.suptitle(head, fontsize=10)
    fig.tight_layout()
    return fig
