"""The figures of ``ipcosim analyze``: the Bode and Nyquist plots of the loop broken at the plant input,
and the margins at each break point (``analyze.plot_loop``'s files). Needs matplotlib."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

#: The break point of the loop itself, first of the responses the figures draw.
PLANT_INPUT = "plant input (voltage)"


def plot_loop(w: np.ndarray, responses: Mapping[str, np.ndarray], result: Mapping[str, Any], out: str | Path,
              title: str) -> dict[str, str]:
    """Write ``bode.png`` (:func:`_plot_bode`) and ``nyquist.png`` (:func:`_plot_nyquist`) of the loop's
    frequency response ``responses[PLANT_INPUT]`` over ``w`` into ``out``, and ``margins.png`` of every
    break point's response when ``result`` has sensor margins; returns their paths."""
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    Lw = responses[PLANT_INPUT]
    bode = _save(plt, _plot_bode(plt, w, Lw, title, result), out / "bode.png")
    nyquist = _save(plt, _plot_nyquist(plt, Lw, result.get("modulus_margin"), title), out / "nyquist.png")
    figures = {"bode": bode, "nyquist": nyquist}
    if result.get("sensor_margins"):
        figures["margins"] = _save(plt, _plot_margins(plt, result, responses, title), out / "margins.png")
    return figures


def _save(plt: Any, fig: Any, path: Path) -> str:
    """Write ``fig`` to ``path`` (PNG, 110 dpi) and close it; returns the path."""
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def _plot_bode(plt: Any, w: np.ndarray, Lw: np.ndarray, title: str, result: Mapping[str, Any] | None = None) -> Any:
    """The Bode figure: |L|, |S| and |T| in dB above the phase of L, against frequency [rad/s].

    The phase panel has the -180 deg line (and -180 + k 360 deg wherever the unwrapped phase runs);
    with ``result`` (:func:`analyze_loop`) the margins are drawn where they are: each gain margin as
    a bar from |L| up (or down) to 0 dB at its phase crossover, each phase margin as a bar from the
    -180 deg line to the phase at its gain crossover, both labelled with their value."""
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6.4))
    mag = 20 * np.log10(np.abs(Lw))
    for vals, label in ((Lw, "|L|"), (1 / (1 + Lw), "|S|"), (Lw / (1 + Lw), "|T|")):
        ax1.semilogx(w, 20 * np.log10(np.abs(vals)), label=label)
    ax1.axhline(0, color="k", lw=0.5)
    ax1.set_ylabel("magnitude [dB]")
    ax1.set_title(title)
    phase = np.degrees(np.unwrap(np.angle(Lw)))
    ax2.semilogx(w, phase, label="phase of L")
    lo, hi = min(float(phase.min()), -190.0), max(float(phase.max()), -170.0)
    for k, level in enumerate(np.arange(-180.0 + 360.0 * math.ceil((lo + 180.0) / 360.0), hi, 360.0)):
        ax2.axhline(level, color="tab:red", ls="--", lw=0.9, label="-180 deg (mod 360)" if k == 0 else None)
    ax2.set_ylim(lo - 15.0, hi + 40.0)  # room for the labels above the curve
    ax2.set_ylabel("phase of L [deg]")
    ax2.set_xlabel("frequency [rad/s]")
    logw = np.log10(w)
    for pm in (result or {}).get("phase_margins") or []:
        wc, margin = pm["frequency_rad_s"], pm["phase_margin_deg"]
        at = float(np.interp(math.log10(wc), logw, phase))
        ax2.plot([wc, wc], [at - margin, at], color="tab:purple", lw=2.2, solid_capstyle="butt")
        ax2.plot([wc], [at], "o", color="tab:purple", ms=5)
        ax1.plot([wc], [0.0], "o", color="tab:purple", ms=5)
        ax2.annotate(f"PM {margin:.3g} deg\nat {wc:.3g} rad/s", (wc, at), fontsize=8, color="tab:purple",
                     **_beside(wc, logw, 4))
    gm = (result or {}).get("gain_margin") or {}
    for side in ("upper", "lower"):
        wg, db = gm.get(f"{side}_frequency_rad_s"), gm.get(f"{side}_dB")
        if db is None or not wg or not w[0] * (1 - 1e-9) <= wg <= w[-1] * (1 + 1e-9):
            continue  # infinite, at rest (z = 1: off a log axis) or beyond the grid: in analysis.json only
        at = float(np.interp(math.log10(wg), logw, mag))
        ax1.plot([wg, wg], [at, 0.0], color="tab:brown", lw=2.2, solid_capstyle="butt")
        ax1.plot([wg], [at], "s", color="tab:brown", ms=5)
        ax2.plot([wg], [float(np.interp(math.log10(wg), logw, phase))], "s", color="tab:brown", ms=5)
        ax1.annotate(f"GM {db:+.3g} dB\nat {wg:.3g} rad/s", (wg, at / 2), fontsize=8, color="tab:brown",
                     va="center", **_beside(wg, logw, 0))
    ax1.legend(fontsize=8, loc="lower left")
    ax2.legend(fontsize=8, loc="lower left")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def _beside(w: float, logw: np.ndarray, dy: float) -> dict[str, Any]:
    """Where a margin's label goes: right of its mark, or left of it in the last third of the axis."""
    right = math.log10(w) < logw[0] + 2 / 3 * (logw[-1] - logw[0])
    return {"xytext": (6 if right else -6, dy), "textcoords": "offset points", "ha": "left" if right else "right",
            "bbox": {"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.85}}


def _plot_nyquist(plt: Any, Lw: np.ndarray, modulus_margin: float | None, title: str) -> Any:
    """The Nyquist figure: L for positive and negative frequencies, whole and zoomed on -1, with the
    circle of radius ``modulus_margin`` (1/Ms) around -1 when there is one."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 5))
    for ax, lim in ((ax1, None), (ax2, 3.0)):
        ax.plot(Lw.real, Lw.imag, "b-", lw=1, label="L(e^{jwT}), w > 0")
        ax.plot(Lw.real, -Lw.imag, "b--", lw=0.7, label="w < 0")
        ax.plot([-1], [0], "r+", ms=12)
        if modulus_margin:
            t = np.linspace(0, 2 * np.pi, 200)
            ax.plot(-1 + modulus_margin * np.cos(t), modulus_margin * np.sin(t), "r:", label="1/Ms around -1")
        if lim:
            ax.set_xlim(-1 - lim, -1 + lim)
            ax.set_ylim(-lim, lim)
            ax.set_title("around -1")
        ax.set_xlabel("Re L")
        ax.set_ylabel("Im L")
        ax.grid(True, alpha=0.3)
    ax1.set_title(title)
    ax1.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _plot_margins(plt: Any, result: Mapping[str, Any], responses: Mapping[str, np.ndarray], title: str) -> Any:
    """The margins figure: left, the range of gain each break point tolerates (the plant input's and, loop at a
    time, each sensor's; the disk margin's simultaneous gain range beside the input's), with the delay margin in the
    label; right, each broken loop's Nyquist curve around -1 with the disk the disk margin keeps it out of."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    gm, dm = result["gain_margin"], result["disk_margin"]
    rows = [(PLANT_INPUT, gm["lower"], gm["upper"], result["delay_margin_s"]),
            ("plant input, disk", dm["gain_lower"], dm["gain_upper"], None)]
    rows += [(name, m["gain_lower"], m["gain_upper"], m["delay_margin_s"])
             for name, m in result["sensor_margins"].items()]
    for y, (_name, lo, hi, delay) in enumerate(rows):
        lo_plot, hi_plot = max(lo or 0.0, 0.05), min(hi or 20.0, 20.0)
        ax1.plot([lo_plot, hi_plot], [y, y], lw=8, solid_capstyle="butt", color="C0" if delay is not None else "C1")
        span = f"x{lo:.3g} .. x{hi:.3g}" if hi else f"x{lo:.3g} .. inf"
        text = span + ("" if delay is None else f", delay {delay * 1e3:.3g} ms")
        ax1.annotate(text, (hi_plot, y), xytext=(4, 6), textcoords="offset points", fontsize=8)
    ax1.axvline(1.0, color="k", lw=0.8)
    ax1.set_xscale("log")
    ax1.set_xlim(0.05, 60)
    ax1.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax1.invert_yaxis()
    ax1.set_xlabel("gain factor on the signal [1] (stable inside the bar)")
    ax1.set_title(f"{title}\ngain ranges (loop at a time) and delay margins", fontsize=9)
    ax1.grid(True, which="both", axis="x", alpha=0.3)
    for name, Lw in responses.items():
        ax2.plot(Lw.real, Lw.imag, lw=1, label=name)
    a = dm["alpha"]
    if a < 2:   # the points -1/k of the disk's gains: a disk through -(1 - a/2)/(1 + a/2) and -(1 + a/2)/(1 - a/2)
        left, right = -(1 + a / 2) / (1 - a / 2), -(1 - a / 2) / (1 + a / 2)
        t = np.linspace(0, 2 * np.pi, 200)
        c, r = (left + right) / 2, (right - left) / 2
        ax2.plot(c + r * np.cos(t), r * np.sin(t), "r:", label=f"disk margin {a:.3g} (+-{dm['phase_deg']:.3g} deg)")
    ax2.plot([-1], [0], "r+", ms=12)
    ax2.set_xlim(-3, 1)
    ax2.set_ylim(-2, 2)
    ax2.set_xlabel("Re L [1]")
    ax2.set_ylabel("Im L [1]")
    ax2.set_title("each loop broken alone, around -1", fontsize=9)
    ax2.legend(fontsize=7, loc="lower right")
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig
