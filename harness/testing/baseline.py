"""Baselines: a run's trajectories saved as CSV to compare later runs against.

A baseline file is a CSV like ``results.csv`` (header ``time,component.variable,...``) holding
the recorded columns (10 significant digits) at no more than :data:`MAX_ROWS` communication points (every n-th
point, always the first and the last; the points are samples of the run, not interpolated).
:func:`compare` evaluates a new run at the baseline's times (linear interpolation, exact on
a shared grid) and reports, per column, the largest deviation against its tolerance.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from ipcosim.errors import IpcosimError

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.results import Result

#: Most rows a baseline keeps (a 10 s run at 1 ms is thinned to every 10th point).
MAX_ROWS = 1001


class BaselineError(IpcosimError, ValueError):
    """A baseline file that cannot be read or does not fit the run compared with it."""


def save_baseline(result: "Result", path: str | os.PathLike[str], columns: Sequence[str] | None = None) -> Path:
    """Write ``result``'s columns (names or patterns; default all) as a baseline CSV.

    Parameters
    ----------
    result : Result
        A run (``ipcosim.run(...)``).
    path : path
        The CSV file to write (folders are created).
    columns : sequence of str, optional
        Columns to keep besides ``time`` (``plant.*`` patterns allowed).

    Returns
    -------
    Path
        The file written.
    """
    names = result.select(columns)
    n = len(result.data)
    stride = max(1, math.ceil((n - 1) / (MAX_ROWS - 1))) if n > 1 else 1
    rows = np.unique(np.r_[np.arange(0, n, stride), n - 1]) if n else np.arange(0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    matrix = np.column_stack([np.asarray(result.data[c][rows], dtype=float) for c in names])
    np.savetxt(path, matrix, fmt="%.10g", delimiter=",", header=",".join(names), comments="")
    return path


def load_baseline(path: str | os.PathLike[str]) -> np.ndarray:
    """A baseline (or results.csv) as a structured array with the CSV's column names.

    Raises
    ------
    BaselineError
        Missing file, no ``time`` column, ragged rows or values that are not numbers.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise BaselineError(f"baseline {path}: cannot read ({exc.strerror or exc})") from None
    if not rows or not rows[0] or rows[0][0] != "time":
        raise BaselineError(f"baseline {path}: the first column must be 'time'")
    header, body = rows[0], [r for r in rows[1:] if r]
    try:
        values = np.array(body, dtype=float).reshape(len(body), len(header))
    except ValueError:
        raise BaselineError(f"baseline {path}: rows must hold {len(header)} numbers each") from None
    data = np.zeros(len(body), dtype=[(name, float) for name in header])
    for j, name in enumerate(header):
        data[name] = values[:, j]
    return data


@dataclass(frozen=True)
class ColumnDiff:
    """The comparison of one column: largest |run - baseline|, where, and its tolerance."""

    column: str
    max_abs: float
    at_time: float
    tol: float

    @property
    def ok(self) -> bool:
        return self.max_abs <= self.tol


def compare(result: "Result", baseline: np.ndarray, columns: Sequence[str] | None,
            tol: float | Mapping[str, float]) -> tuple[list[ColumnDiff], dict[str, np.ndarray]]:
    """Per-column deviation of ``result`` from ``baseline`` at the baseline's times.

    Returns
    -------
    diffs : list of ColumnDiff
    traces : dict
        ``time`` and, per column, the run's values at the baseline's times (for a plot).

    Raises
    ------
    BaselineError
        A column missing from the run or the baseline, a tolerance for no compared column,
        or a run that does not cover the baseline's time span.
    """
    base_cols = [c for c in baseline.dtype.names if c != "time"]
    cols = list(columns) if columns else base_cols
    tols = dict(tol) if isinstance(tol, Mapping) else {c: float(tol) for c in cols}
    for c in cols:
        if c not in base_cols:
            raise BaselineError(f"column {c!r} is not in the baseline (it has: {', '.join(base_cols)})")
        if c not in result.columns:
            raise BaselineError(f"column {c!r} was not recorded in this run")
        if c not in tols:
            raise BaselineError(f"no tolerance for column {c!r} (tolerances given for: {', '.join(tols)})")
    t_base, t_run = baseline["time"], np.asarray(result["time"], float)
    if t_run[-1] < t_base[-1] - 1e-9 or t_run[0] > t_base[0] + 1e-9:
        raise BaselineError(f"the run covers {t_run[0]:g}..{t_run[-1]:g} s, the baseline {t_base[0]:g}.."
                            f"{t_base[-1]:g} s: run at least as long as the baseline")
    traces = {"time": t_base}
    diffs = []
    for c in cols:
        run = np.interp(t_base, t_run, np.asarray(result[c], float))
        dev = np.abs(run - baseline[c])
        dev = np.where(np.isfinite(dev), dev, np.inf)
        k = int(np.argmax(dev))
        traces[c] = run
        diffs.append(ColumnDiff(c, float(dev[k]), float(t_base[k]), float(tols[c])))
    return diffs, traces


def plot_difference(baseline: np.ndarray, traces: Mapping[str, np.ndarray], diffs: Sequence[ColumnDiff],
                    path: str | os.PathLike[str]) -> Path:
    """Write a figure with, per column, the run over the baseline and their difference within +-tol."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = traces["time"]
    fig, axes = plt.subplots(len(diffs), 2, figsize=(10, 2.4 * len(diffs) + 0.6), squeeze=False, sharex=True)
    for (ax_v, ax_d), d in zip(axes, diffs):
        ax_v.plot(t, baseline[d.column], "k--", linewidth=1.0, label="baseline")
        ax_v.plot(t, traces[d.column], label="this run")
        ax_v.set_ylabel(d.column)
        ax_v.legend(loc="best", fontsize="small")
        ax_d.plot(t, traces[d.column] - baseline[d.column], color="C3" if not d.ok else "C2")
        ax_d.axhspan(-d.tol, d.tol, color="0.85", label=f"+-tol {d.tol:g}")
        ax_d.set_ylabel("run - baseline")
        ax_d.legend(loc="best", fontsize="small")
        for ax in (ax_v, ax_d):
            ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
