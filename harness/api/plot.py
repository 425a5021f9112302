"""The run figure, stacked like the thesis's result figures: reference and cart position(s) with
the settling band, pendulum angle (radians, as the metrics; degrees on the right), motor voltage
with its limits, over a shared time axis."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from ipcosim.harness.master.results import Result

POSITIONS = (("plant.cart_position", "cart"), ("plant.active_cart_position", "active cart"),
             ("plant.passive_cart_position", "passive cart"))
#: Percentiles that bound a panel's axis when a few samples lie far outside the rest.
ROBUST_PERCENTILES = (0.5, 99.5)
#: The axis is cut to the robust range only when the full range is this much wider.
SPIKE_RATIO = 2.0


def axis_limits(signals: list[np.ndarray], margin: float = 0.08) -> tuple[float, float] | None:
    """Y-axis limits of a panel that a few spikes cannot squash.

    The limits span the finite samples' range, unless that range is more than
    :data:`SPIKE_RATIO` times the range between the :data:`ROBUST_PERCENTILES`: then they span
    the percentile range (samples beyond it are drawn as markers on the axis edge by
    :func:`plot_result`). ``margin`` widens either range by that fraction on each side.

    Returns
    -------
    (low, high) or None
        None when there is no finite sample.
    """
    finite = [np.asarray(y, float)[np.isfinite(y)] for y in signals]
    data = np.concatenate(finite) if finite else np.zeros(0)
    if data.size == 0:
        return None
    lo, hi = float(data.min()), float(data.max())
    r_lo, r_hi = (float(v) for v in np.percentile(data, ROBUST_PERCENTILES))
    if hi - lo > SPIKE_RATIO * (r_hi - r_lo) and r_hi > r_lo:
        lo, hi = r_lo, r_hi
    pad = margin * (hi - lo) if hi > lo else max(abs(hi), 1.0) * margin
    return lo - pad, hi + pad


def _mark_spikes(ax, t: np.ndarray, y: np.ndarray, limits: tuple[float, float]) -> int:  # noqa: ANN001
    """Draw the samples beyond ``limits`` as triangles on the axis edge; returns their count."""
    lo, hi = limits
    y = np.asarray(y, float)
    above, below = y > hi, y < lo
    if above.any():
        ax.plot(t[above], np.full(int(above.sum()), hi), "^", color="tab:red", markersize=5, clip_on=False)
    if below.any():
        ax.plot(t[below], np.full(int(below.sum()), lo), "v", color="tab:red", markersize=5, clip_on=False)
    return int(above.sum() + below.sum())


def _decorate(ax, ylabel: str, result: "Result", lines: list, limits: tuple[float, float] | None  # noqa: ANN001
              ) -> tuple[float, float] | None:
    """What a control engineer reads a panel against: the settling band and time on the position,
    degrees beside the angle, the voltage limits; returns the panel's y limits (spanning them)."""
    from ipcosim.fmus.metrics import SETTLING_BAND

    if ylabel.startswith("position") and lines[0][0] == "reference" and len(lines) > 1:
        r_final, x0 = float(lines[0][1][-1]), float(lines[1][1][0])
        band = SETTLING_BAND * abs(r_final - x0)
        if band > 0:
            ax.axhspan(r_final - band, r_final + band, color="tab:green", alpha=0.15,
                       label=f"settling band +-{100 * SETTLING_BAND:g} %")
        settled = result.metrics.get("settling_time_s")
        if settled is not None:
            ax.axvline(float(result["time"][0]) + settled, color="tab:green", linestyle=":",
                       label=f"settled after {settled:.3g} s")
    elif ylabel.startswith("pendulum angle"):
        ax.secondary_yaxis("right", functions=(np.degrees, np.radians)).set_ylabel("pendulum angle [deg]")
    elif ylabel.startswith("voltage") and result.metadata.get("voltage_limit_V"):
        limit = float(result.metadata["voltage_limit_V"])
        for sign in (1, -1):
            ax.axhline(sign * limit, color="tab:red", linestyle="--", linewidth=0.8,
                       label=f"+-{limit:g} V limit" if sign > 0 else None)
        lo, hi = limits if limits is not None else (0.0, 0.0)
        limits = (min(lo, -1.08 * limit), max(hi, 1.08 * limit))
    return limits


def plot_result(result: "Result", path: str | Path, title: str | None = None) -> Path:
    """Write the three-panel figure of a run (:func:`figure`) to ``path`` (PNG); returns the path."""
    fig = figure(result, title, backend="Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figure(result: "Result", title: str | None = None, backend: str | None = None) -> "Figure":
    """The three-panel matplotlib figure of a run.

    Panels: (1) reference and cart position(s) [m] with the +-2 % settling band around the final
    reference and the settling time (docs/metrics.md), (2) pendulum angle [rad] (degrees on the
    right axis), (3) controller voltage [V] with the +-``voltage_limit`` lines when the run's
    metadata has ``voltage_limit_V`` (the axis then spans them). Panels whose signals the
    result lacks are left out; with none of them, every recorded column is drawn in one panel.
    Each panel's axis comes from :func:`axis_limits`: isolated spikes do not squash it; they are
    marked with red triangles on its edge and their count and range are written in the panel.
    """
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    if backend:
        matplotlib.use(backend)
    import matplotlib.pyplot as plt

    cols = result.columns
    t = result["time"]
    panels: list[tuple[str, list[tuple[str, np.ndarray, dict]]]] = []
    pos = [(label, result[c], {}) for c, label in POSITIONS if c in cols]
    ref = next((c for c in ("setpoint.reference", "controller.reference") if c in cols), None)
    if ref:
        pos.insert(0, ("reference", result[ref], {"linestyle": "--", "color": "k", "linewidth": 1.0}))
    if pos:
        panels.append(("position [m]", pos))
    if "plant.pendulum_angle" in cols:
        panels.append(("pendulum angle [rad]", [("angle", result["plant.pendulum_angle"], {})]))
    volt = next((c for c in ("controller.voltage", "plant.voltage") if c in cols), None)
    if volt:
        panels.append(("voltage [V]", [("voltage", result[volt], {"drawstyle": "steps-post"})]))
    if not panels:
        panels.append(("value", [(c, result[c], {}) for c in cols[1:]]))
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(8, 2.4 * len(panels) + 0.6), squeeze=False)
    for ax, (ylabel, lines) in zip(axes[:, 0], panels):
        for label, y, style in lines:
            ax.plot(t, y, label=label, **style)
        limits = _decorate(ax, ylabel, result, lines, axis_limits([y for _, y, _ in lines]))
        if limits is not None:
            ax.set_ylim(*limits)
            spikes = sum(_mark_spikes(ax, np.asarray(t), y, limits) for _, y, _ in lines)
            if spikes:
                extremes = np.concatenate([np.asarray(y, float)[np.isfinite(y)] for _, y, _ in lines])
                ax.annotate(f"{spikes} sample(s) beyond the axis (range {extremes.min():.3g} .. {extremes.max():.3g})",
                            xy=(0.99, 0.02), xycoords="axes fraction", ha="right", va="bottom",
                            fontsize="x-small", color="tab:red")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > 1:
            ax.legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title_text(result, title), fontsize="medium")
    fig.tight_layout()
    return fig


#: Characters per line of the run figure's title before it is wrapped.
TITLE_WIDTH = 90


def title_text(result: "Result", title: str | None = None) -> str:
    """The run figure's title: what was run and how far its results can be trusted.

    Line one: the scenario (or ``title``), its parameter set in brackets, and the marks
    ``[HIL: plant=hil]`` (a component swapped for the hardware-in-the-loop one), ``[swapped: ...]``
    (any other swap), ``[DEGRADED real time: x % late steps > budget y %]`` (a paced run over
    its overrun budget, the run that exits 3) and ``[FAILED]``. Then every ``--set`` value
    (``set: plant.Mp=0.2, ...``), wrapped at :data:`TITLE_WIDTH` characters.
    """
    import textwrap

    meta, metrics = result.metadata, result.metrics
    head = [title or str(meta.get("scenario", ""))]
    if meta.get("parameter_set"):
        head.append(f"({meta['parameter_set']})")
    swaps = {str(k): str(v) for k, v in (meta.get("swaps") or {}).items()}
    hil = {k: v for k, v in swaps.items() if Path(v).stem.lower().startswith("hil")}
    if hil:
        head.append("[HIL: " + ", ".join(f"{k}={v}" for k, v in hil.items()) + "]")
    others = {k: v for k, v in swaps.items() if k not in hil}
    if others:
        head.append("[swapped: " + ", ".join(f"{k}={v}" for k, v in others.items()) + "]")
    if metrics.get("overrun_budget_exceeded"):
        head.append(f"[DEGRADED real time: {100 * float(metrics.get('overrun_fraction', 0.0)):.2f} % late steps > "
                    f"budget {100 * float(metrics.get('overrun_budget', 0.0)):.2f} %]")
    if not result.ok:
        head.append("[FAILED]")
    lines = textwrap.wrap(" ".join(h for h in head if h), TITLE_WIDTH) or [""]
    sets = meta.get("set") or {}
    if sets:
        lines += textwrap.wrap("set: " + ", ".join(f"{k}={v}" for k, v in sets.items()), TITLE_WIDTH,
                               break_on_hyphens=False)
    return "\n".join(lines)
