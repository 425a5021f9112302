"""Why the per-run bound misses: the predicted residual cycle against the simulated one, run by run
(``docs/studies.md``, "The residual cycle", "Where it fails")::

    python -m evidence.residual_runs [--seeds 0,1] [--workers 2] [--long 65]

For the double-mass LQG's ``lab`` set on the lab bench with every spread (the cells of ``evidence.results_page``'s
verdict table, 200 runs a seed): each run's predicted motor-cart peak-to-peak (recorded in its row before it ran)
against its simulated one; the error's distribution, how it follows each drawn plant factor, the spring's thirds,
and the frequencies (the prediction's friction cycle against the run's). Then what one plant's figure is worth: the
nominal lab bench run ``--long`` seconds, the motor cart's peak-to-peak over every final-window-long stretch after
the step has settled (every 0.5 s): the run's one window is one draw of those.
"""
from __future__ import annotations

import argparse
import sys
from typing import Any, Sequence

import numpy as np

SCENARIO, SET = "double-mass-lqg", "lab"
#: Where the windows of the long run may end [s]: from the step run's own end (15 s), every half second.
WINDOW_ENDS_FROM_S, WINDOW_STRIDE_S = 15.0, 0.5


def diagnosis(rows: Sequence[dict[str, Any]], less_windup: bool = False) -> dict[str, Any]:
    """The prediction against the simulation over the upright runs with a prediction (``rows``: a verdict sweep's;
    ``less_windup``: each recorded prediction less its ``2 b2 / K``, the sliding cycle alone,
    ``ipcosim.harness.analysis.residual_cycle.with_windup``).

    Returns
    -------
    dict
        ``runs``, ``predicted`` (runs with a prediction), ``relative_error`` (median, p10, p90 of
        predicted / simulated - 1), ``shortfall_mm`` (simulated - predicted: median, p90, and the share within
        the 1 mm margin), ``correlation`` (predicted with simulated), ``factors`` (each drawn ``plant.*``: its
        correlation with the simulated and with the predicted peak-to-peak), ``spring_thirds`` (by ``plant.K``:
        range, median error, share within the margin) and ``ratio`` (simulated / predicted: p10, median, p90).
    """
    from ipcosim.fmus.success import AMPLITUDE_MARGIN_M

    up = [r for r in rows if r.get("upright") is True and r.get("predicted_cart_peak_to_peak_m") is not None]
    pred = np.array([float(r["predicted_cart_peak_to_peak_m"]) for r in up])
    if less_windup:
        pred = pred - np.array([2 * float(r["plant.b2"]) / float(r["plant.K"]) for r in up])
    sim = np.array([float(r["cart_peak_to_peak_m"]) for r in up])
    err, short = pred / sim - 1.0, sim - pred
    within = short <= AMPLITUDE_MARGIN_M
    drawn = sorted(k for k in up[0] if k.startswith("plant.") and len({r[k] for r in up}) > 1)
    factors = {k: {"simulated": _corr([r[k] for r in up], sim), "predicted": _corr([r[k] for r in up], pred)}
               for k in drawn}
    K = np.array([float(r["plant.K"]) for r in up])
    edges = np.percentile(K, [0, 100 / 3, 200 / 3, 100])
    thirds = []
    for lo, hi in zip(edges, edges[1:]):
        m = (K >= lo) & (K <= hi)
        thirds.append({"K": (float(lo), float(hi)), "median_error": float(np.median(err[m])),
                       "within_margin": float(np.mean(within[m]))})
    return {"runs": len(rows), "predicted": len(up),
            "relative_error": _quantiles(err), "ratio": _quantiles(sim / pred),
            "shortfall_mm": {**{k: v * 1e3 for k, v in _quantiles(short).items()},
                             "within_margin": float(np.mean(within))},
            "correlation": _corr(pred, sim), "factors": factors, "spring_thirds": thirds,
            "windup_correlation": _corr([2 * float(r["plant.b2"]) / float(r["plant.K"]) for r in up], sim)
            if "plant.b2" in drawn else None,
            "frequency_Hz": {"simulated_median": float(np.median([float(r["cart_frequency_Hz"]) for r in up])),
                             "simulated_with_K": _corr(K, [float(r["cart_frequency_Hz"]) for r in up])}}


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _corr(a: Any, b: Any) -> float:
    return float(np.corrcoef(np.asarray(a, float), np.asarray(b, float))[0, 1])


def _quantiles(x: np.ndarray) -> dict[str, float]:
    p10, p50, p90 = np.percentile(x, [10, 50, 90])
    return {"p10": float(p10), "median": float(p50), "p90": float(p90)}


def window_spread(time: Any, position: Any, window: float) -> np.ndarray:
    """The peak-to-peak of ``position`` over every stretch ``window`` long ending at ``WINDOW_ENDS_FROM_S`` and
    every ``WINDOW_STRIDE_S`` after, to the run's end.

    Examples
    --------
    >>> t = np.arange(0.0, 20.0, 1e-3)
    >>> [round(float(v), 6) for v in window_spread(t, np.sin(2 * np.pi * t), 5.0)[:2]]   # one sinusoid: 2 each time
    [2.0, 2.0]
    """
    t, x = np.asarray(time, float), np.asarray(position, float)
    ends = np.arange(WINDOW_ENDS_FROM_S, t[-1] + 1e-9, WINDOW_STRIDE_S)
    return np.array([np.ptp(x[(t >= e - window) & (t <= e)]) for e in ends])


def long_run(stop_time: float) -> dict[str, Any]:
    """The nominal lab bench run ``stop_time`` seconds: the motor cart's peak-to-peak over every window
    (:func:`window_spread`), its quantiles [mm], and the prediction recorded before the run [mm]."""
    from ipcosim.fmus.metrics import RESIDUAL_WINDOW_S
    from ipcosim.harness.analysis.residual_cycle import realism_values
    from ipcosim.harness.api.public import run

    result = run(SCENARIO, parameter_set=SET, set=realism_values("lab", "double-mass"), stop_time=stop_time,
                 fmus="native")
    names = result.data.dtype.names
    position = next(n for n in names if n.endswith("active_cart_position") and n.startswith("controller"))
    pp = window_spread(result.data["time"], result.data[position], RESIDUAL_WINDOW_S) * 1e3
    return {"windows": len(pp), "min": float(pp.min()), "max": float(pp.max()),
            **{k: v for k, v in _quantiles(pp).items()},
            "predicted": float(result.metrics["predicted_cart_peak_to_peak_m"]) * 1e3}


def markdown(by_seed: dict[tuple[int, str], dict[str, Any]], long: dict[str, Any] | None) -> str:
    """The diagnosis as the lines ``docs/studies.md`` quotes (``by_seed``: by seed and which prediction)."""
    out = []
    for (seed, what), d in by_seed.items():
        e, s, r = d["relative_error"], d["shortfall_mm"], d["ratio"]
        out.append(f"seed {seed}, {what}: {d['predicted']} of {d['runs']} runs predicted; error median "
                   f"{e['median']:+.0%} (p10 {e['p10']:+.0%}, p90 {e['p90']:+.0%}); simulated - predicted median "
                   f"{s['median']:.2f} mm, p90 {s['p90']:.2f} mm, within the 1 mm margin {s['within_margin']:.1%}; "
                   f"simulated / predicted p10 {r['p10']:.2f}, median {r['median']:.2f}, p90 {r['p90']:.2f}; "
                   f"correlation {d['correlation']:.2f} (with 2 b2 / K {_f(d['windup_correlation'])}); "
                   f"simulated frequency median "
                   f"{d['frequency_Hz']['simulated_median']:.2f} Hz (correlation with K "
                   f"{d['frequency_Hz']['simulated_with_K']:+.2f})")
        top = sorted(d["factors"].items(), key=lambda kv: -abs(kv[1]["simulated"]))[:4]
        out.append("  factors (correlation with simulated / predicted): "
                   + ", ".join(f"{k} {v['simulated']:+.2f} / {v['predicted']:+.2f}" for k, v in top))
        out.append("  spring thirds: " + "; ".join(
            f"K {t['K'][0]:.0f}-{t['K'][1]:.0f} N/m: {t['median_error']:+.0%}, {t['within_margin']:.0%} within"
            for t in d["spring_thirds"]))
    if long:
        out.append(f"nominal bench, {long['windows']} windows of the long run: motor cart {long['min']:.2f}-"
                   f"{long['max']:.2f} mm p-p (p10 {long['p10']:.2f}, median {long['median']:.2f}, p90 "
                   f"{long['p90']:.2f}); predicted {long['predicted']:.2f}")
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    from evidence.results_page import verdict_sweep
    from ipcosim.harness.studies.executors import open_executor

    ap = argparse.ArgumentParser(prog="python -m evidence.residual_runs", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0,1", help="seeds of the 200-run cells (default 0,1)")
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--long", type=float, default=65.0, help="length of the nominal run [s] (0: none)")
    a = ap.parse_args(argv)
    try:
        seeds = [int(s) for s in a.seeds.split(",")]
    except ValueError:
        print(f"--seeds {a.seeds!r}: give integers separated by commas", file=sys.stderr)
        return 2
    executor = open_executor(a.workers)
    try:
        by_seed = {}
        for s in seeds:
            rows = verdict_sweep(SCENARIO, SET, s, a.samples, executor).rows
            by_seed[s, "as recorded"] = diagnosis(rows)
            by_seed[s, "less the windup"] = diagnosis(rows, less_windup=True)
    finally:
        executor.close()
    print(markdown(by_seed, long_run(a.long) if a.long > 0 else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
