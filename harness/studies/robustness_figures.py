"""A robustness sweep's figures (:mod:`ipcosim.harness.studies.robustness`): one histogram per metric, successful
and failed runs stacked (:func:`plot_distributions`), and a metric against each varied parameter, each run
coloured by its status (:func:`plot_parameters`), drawn from at most ``FIGURE_RUNS`` runs (:func:`figure_rows`),
their tick labels kept apart.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ipcosim.harness.studies.robustness_summary import _numeric

#: Runs drawn in a sweep's figures: every run of a sweep up to this size, else a random sample of this many
#: (the summary's numbers are always of every run).
FIGURE_RUNS = 5000


def figure_rows(path: Path, limit: int | None = None, seed: int = 0) -> tuple[list[dict[str, Any]], int]:
    """The rows of a results file a sweep's figures draw, and the number of rows in the file: every row when there
    are at most ``limit`` (default :data:`FIGURE_RUNS`), else ``limit`` of them drawn uniformly at random
    (reservoir sampling, reproducible with ``seed``), in file order."""
    from ipcosim.harness.studies.store import iter_results

    limit = limit or FIGURE_RUNS
    rng = np.random.default_rng(seed)
    kept: list[tuple[int, dict[str, Any]]] = []
    n = 0
    _, rows = iter_results(path)
    for n, row in enumerate(rows, start=1):
        if len(kept) < limit:
            kept.append((n, row))
        else:
            j = int(rng.integers(n))
            if j < limit:
                kept[j] = (n, row)
    kept.sort(key=lambda item: item[0])
    return [row for _, row in kept], n


def histogram(xg: np.ndarray, xb: np.ndarray, name: str, title: str = "") -> Any:
    """The figure of one metric's distribution: successful (``xg``) and failed (``xb``) runs
    stacked, its x tick labels apart (:func:`_readable_ticks`). A few runs far outside the rest
    (:func:`ipcosim.harness.api.plot.axis_limits`) are counted in the legend instead of stretching the axis."""
    import matplotlib.pyplot as plt

    from ipcosim.harness.api.plot import axis_limits

    fig, ax = plt.subplots(figsize=(5.0, 3.2), dpi=100)
    allx = np.concatenate([xg, xb])
    labels = [f"success ({xg.size})", f"failure ({xb.size})"]
    lo, hi = axis_limits([allx]) or (0.0, 0.0)
    beyond = (allx < lo) | (allx > hi)
    note = None
    if beyond.any() and hi > lo:  # a few runs far out would squash the rest into one bar: counted, not drawn
        xg, xb = xg[(xg >= lo) & (xg <= hi)], xb[(xb >= lo) & (xb <= hi)]
        far = allx[beyond]
        note = (f"{far.size} run(s) off the axis: " + (f"{far.min():.4g}" if far.size == 1 else
                                                        f"{far.min():.4g} .. {far.max():.4g}"))
        allx = allx[~beyond]
    bins = np.histogram_bin_edges(allx, bins=min(30, max(5, int(np.sqrt(allx.size)) + 1)))
    if np.ptp(allx) == 0:
        bins = np.array([allx[0] - 0.5, allx[0] + 0.5]) if allx[0] == 0 else \
            np.array([allx[0] * 0.99, allx[0] * 1.01])
        bins = np.sort(bins)
    ax.hist([xg, xb], bins=bins, stacked=True, color=["tab:green", "tab:red"],
            label=labels)
    ax.set_xlabel(name)
    ax.set_ylabel("runs")
    if title:
        ax.set_title(title, fontsize=9)
    if note:
        ax.plot([], [], " ", label=note)  # in the legend, where it cannot cover a bar or the title
    ax.legend(fontsize=8)
    fig.tight_layout()
    _readable_ticks(fig, ax.xaxis)
    fig.tight_layout()
    return fig


def plot_distributions(rows: Sequence[Mapping[str, Any]], metric_names: Sequence[str], out_dir: Path,
                       title: str = "") -> list[Path]:
    """One histogram per metric (successful and failed runs stacked), as PNG files.

    Returns
    -------
    list of Path
        The written figures, ``out_dir/<metric>.png``.
    """
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    completed = [r for r in rows if r["status"] != "error"]
    good = [r for r in completed if r["status"] == "ok"]
    bad = [r for r in completed if r["status"] != "ok"]
    paths = []
    for name in metric_names:
        xg, xb = _numeric(good, name), _numeric(bad, name)
        if xg.size + xb.size == 0:
            continue
        fig = histogram(xg, xb, name, title)
        path = out_dir / f"{name}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def shown_tick_labels(axis: Any, renderer: Any) -> list[Any]:
    """Window extents of the tick labels ``axis`` draws (those of ticks inside its view)."""
    lo, hi = sorted(axis.get_view_interval())
    slack = 1e-9 * max(abs(lo), abs(hi), 1.0)
    return [tick.label1.get_window_extent(renderer) for tick in axis.get_major_ticks()
            if lo - slack <= tick.get_loc() <= hi + slack and tick.label1.get_visible() and tick.label1.get_text()]


def tick_labels_overlap(fig: Any, axis: Any) -> bool:
    """Whether two of ``axis``'s drawn tick labels overlap, or come closer than 0.4 of the
    font size (a later layout pass may shift them by a pixel), once ``fig`` is drawn."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = sorted((b for b in shown_tick_labels(axis, renderer)), key=lambda b: b.x0)
    gap = 0.4 * axis.get_ticklabels()[0].get_size() * fig.dpi / 72 if boxes else 0.0  # [px]
    return any(a.x1 + gap > b.x0 and a.y1 > b.y0 and b.y1 > a.y0 for a, b in zip(boxes, boxes[1:]))


def _readable_ticks(fig: Any, axis: Any) -> None:
    """At most six ticks written in full (no ``+1`` offset nor ``1e6`` factor beside
    the axis); rotated when they
    still touch, fewer when even that does not part them."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    axis.set_major_formatter(formatter)
    for nbins, rotation in ((6, 0), (6, 30), (4, 30), (3, 45), (2, 45)):
        axis.set_major_locator(MaxNLocator(nbins=nbins))
        for label in axis.get_ticklabels():
            label.set_rotation(rotation)
            label.set_horizontalalignment("right" if rotation else "center")
        axis.set_tick_params(rotation=rotation)
        if not tick_labels_overlap(fig, axis):
            return


STATUS_COLORS = {"ok": "tab:green", "unsettled": "tab:orange", "hunting": "tab:purple", "fell": "tab:red",
                 "error": "black"}


def plot_parameters(rows: Sequence[Mapping[str, Any]], parameters: Sequence[str], metric: str, out_dir: Path,
                    title: str = "") -> Path | None:
    """Which parameter values fail: one panel per varied parameter, ``metric`` against the
    parameter's value, each run coloured by its status. Written to ``out_dir/parameters.png``."""
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parameters = [p for p in parameters if any(isinstance(r.get(p), (int, float)) for r in rows)]
    if not parameters:
        return None
    out_dir.mkdir(parents=True, exist_ok=True)
    n = len(parameters)
    cols = min(n, 3)
    nrows = (n + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), dpi=100, squeeze=False)
    for ax, name in zip(axes.ravel(), parameters):
        for status, color in STATUS_COLORS.items():
            pts = [(r[name], r.get(metric)) for r in rows if r["status"] == status
                   and isinstance(r.get(name), (int, float))]
            if not pts:
                continue
            xs = [p[0] for p in pts]
            ys = [p[1] if isinstance(p[1], (int, float)) and math.isfinite(p[1]) else math.nan for p in pts]
            if status == "error":
                finite = [y for r in rows for y in [r.get(metric)] if isinstance(y, (int, float)) and math.isfinite(y)]
                ys = [min(finite) if finite else 0.0] * len(xs)
            ax.scatter(xs, ys, s=12, color=color, label=f"{status} ({len(xs)})", alpha=0.8)
        ax.set_xlabel(name)
        ax.set_ylabel(metric)
        ax.grid(True, alpha=0.3)
        values = [y for r in rows for y in [r.get(metric)] if isinstance(y, (int, float)) and math.isfinite(y)]
        if values and min(values) > 0 and max(values) / min(values) > 100:
            ax.set_yscale("log")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    axes[0][0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = out_dir / "parameters.png"
    fig.savefig(path)
    plt.close(fig)
    return path
