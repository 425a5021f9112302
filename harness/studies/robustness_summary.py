"""A robustness sweep's numbers (:mod:`ipcosim.harness.studies.robustness`): the success rate with its 95 %
Wilson score interval and each metric's distribution over the runs (:func:`summarize`), in Markdown and on
one line.

A run is a success when its status is ``ok``: the task's success criterion,
``ipcosim.fmus.metrics.success_status`` (upright, |mean error| <= 1 mm over the final window, the motor
cart's residual peak-to-peak within its bound). The success rate is reported with its 95 % Wilson score
interval, beside the distribution of the residual amplitude (median, 90th percentile).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval of a success proportion (nan, nan for n = 0)."""
    if n <= 0:
        return (math.nan, math.nan)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def _numeric(rows: Iterable[Mapping[str, Any]], name: str) -> np.ndarray:
    values = []
    for r in rows:
        v = r.get(name)
        if isinstance(v, bool):
            values.append(1.0 if v else 0.0)
        elif isinstance(v, (int, float)) and math.isfinite(v):
            values.append(float(v))
    return np.asarray(values, dtype=float)


def summarize(rows: Sequence[Mapping[str, Any]], metric_names: Sequence[str]) -> dict[str, Any]:
    """Success rate and the distribution of each metric over the runs that completed.

    Returns
    -------
    dict
        ``runs``, ``counts`` (per status), ``success_rate``, ``success_ci95`` and ``metrics``:
        per metric ``n`` (runs with a value), ``mean``, ``std``, ``min``, ``p5``, ``median``,
        ``p90``, ``p95``, ``max`` (``ipcosim.harness.studies.columns.array_distribution``).
    """
    from ipcosim.harness.studies.columns import array_distribution

    counts: dict[str, int] = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    completed = [r for r in rows if r["status"] != "error"]
    return _summary(len(rows), counts, {name: array_distribution(_numeric(completed, name)) for name in metric_names})


def _summary(n: int, counts: dict[str, int], metrics: dict[str, dict[str, float]]) -> dict[str, Any]:
    ok = counts.get("ok", 0)
    lo, hi = wilson_interval(ok, n)
    return {"runs": n, "counts": counts, "success_rate": ok / n if n else math.nan,
            "success_ci95": [lo, hi], "metrics": metrics}


def summarize_results(path: Path, metric_names: Sequence[str], limit: int | None = None) -> dict[str, Any]:
    """:func:`summarize` of the rows of a results file, read back in memory independent of their number
    (``ipcosim.harness.studies.columns``: numpy's functions on a metric's values when there are at most
    ``limit``, default ``columns.IN_MEMORY_VALUES``, else the same numbers from passes over them on disk)."""
    from ipcosim.harness.studies import columns

    limit = columns.IN_MEMORY_VALUES if limit is None else limit
    with columns.ResultColumns(path, metric_names) as cols:
        completed = [s for s in cols.counts if s != "error"]
        metrics = {name: columns.distribution(cols.source(name, completed), limit) for name in metric_names}
        return _summary(cols.runs, dict(cols.counts), metrics)


def fmt(value: Any, digits: int = 4) -> str:
    """A number for a table: 4 significant digits, '-' for missing."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, float)):
        if value == 0:
            return "0"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.{digits}g}"
    return str(value)


def summary_markdown(summary: Mapping[str, Any], title: str = "Robustness") -> str:
    """The summary as Markdown (success rate line + distribution table)."""
    lo, hi = summary["success_ci95"]
    counts = ", ".join(f"{k} {v}" for k, v in sorted(summary["counts"].items()))
    lines = [f"## {title}", "",
             f"Success rate: **{100 * summary['success_rate']:.1f} %** of {summary['runs']} runs "
             f"(95 % CI {100 * lo:.1f}-{100 * hi:.1f} %); {counts}." + (f" The {amplitude_note(summary)}."
                                                                if amplitude_note(summary) else ""), "",
             "| metric | runs | mean | std | min | p5 | median | p95 | max |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary["metrics"].items():
        if not s.get("n"):
            lines.append(f"| {name} | 0 | - | - | - | - | - | - | - |")
            continue
        lines.append(f"| {name} | {s['n']} | " + " | ".join(fmt(s[k]) for k in
                                                         ("mean", "std", "min", "p5", "median", "p95", "max")) + " |")
    return "\n".join(lines) + "\n"


def summary_line(summary: Mapping[str, Any]) -> str:
    """The success rate with its 95 % interval and the counts per status, on one line."""
    lo, hi = summary["success_ci95"]
    counts = ", ".join(f"{k} {v}" for k, v in sorted(summary["counts"].items()))
    return (f"success rate {100 * summary['success_rate']:.1f} % (95 % CI {100 * lo:.1f}-{100 * hi:.1f} %) "
            f"of {summary['runs']} runs: {counts}"
            + (f"; {amplitude_note(summary)}" if amplitude_note(summary) else ""))


def amplitude_note(summary: Mapping[str, Any]) -> str:
    """The motor cart's residual peak-to-peak over the runs (median, 90th percentile), which the success criterion
    bounds (``docs/metrics.md``); empty when the runs did not measure it."""
    amp = summary["metrics"].get("cart_peak_to_peak_m") or {}
    if not amp.get("n"):
        return ""
    return (f"motor-cart residual peak-to-peak median {1e3 * amp['median']:.3g} mm, 90th percentile "
            f"{1e3 * amp['p90']:.3g} mm")
