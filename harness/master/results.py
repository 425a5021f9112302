"""Results of a run: the recorded trajectories, the metrics and the metadata, and writing them
as ``results.csv`` (columns ``time`` then ``component.variable``), ``metrics.json`` and,
on request, ``plot.png``.
"""
from __future__ import annotations

import fnmatch
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ipcosim.harness.errors import IpcosimError, UsageError

#: Plant outputs that the metrics read, by preference: the motor-driven cart's position.
POSITION_COLUMNS = ("plant.cart_position", "plant.active_cart_position")
ANGLE_COLUMNS = ("plant.pendulum_angle",)
REFERENCE_COLUMNS = ("setpoint.reference", "controller.reference")
VOLTAGE_COLUMNS = ("controller.voltage", "plant.voltage")


class SimulationError(IpcosimError, RuntimeError):
    """A run that failed; ``result`` holds everything recorded up to the failure."""

    def __init__(self, message: str, result: "Result | None" = None) -> None:
        super().__init__(message)
        self.result = result


@dataclass
class Result:
    """The outcome of one run.

    Attributes
    ----------
    data : numpy structured array
        Field ``time`` [s], then one field ``component.variable`` per recorded connector
        (SI units), one row per recorded communication point (row 0 is the initial state).
    metrics : dict
        ``metrics.json`` content (see DESIGN.md): the task metrics, ``wall_time_s`` (the whole
        run: load, instantiate, initialize, step, write), ``real_time_factor`` (simulated /
        wall_time_s) and ``loop_real_time_factor`` (simulated / stepping-loop seconds).
    metadata : dict
        Scenario, algorithm, step, order, step multiples, FMUs, overrides, swaps, warnings,
        status and error.
    error : str or None
        One-line description of the failure, None for a complete run.
    """

    data: np.ndarray
    metrics: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def columns(self) -> list[str]:
        return list(self.data.dtype.names or ())

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    def select(self, patterns: Sequence[str] | None) -> list[str]:
        """Column names matching ``patterns`` (exact names or shell patterns such as
        ``plant.*``), in result order, ``time`` first. None selects every column.

        Raises
        ------
        UsageError
            If a pattern matches no column.
        """
        cols = self.columns
        if not patterns:
            return cols
        chosen = {"time"}
        for p in patterns:
            hits = [c for c in cols if fnmatch.fnmatchcase(c, p)]
            if not hits:
                raise UsageError(f"--record {p}: no such variable (recorded: {', '.join(cols[1:])})")
            chosen.update(hits)
        return [c for c in cols if c in chosen]

    def plot(self, path: str | Path | None = None) -> Any:
        """The run's figure: reference and cart position(s), pendulum angle, voltage.

        Parameters
        ----------
        path : path, optional
            Write the figure there as PNG and return the path; without it, return the
            matplotlib Figure (to show or save).
        """
        from ipcosim.harness.plot import figure, plot_result

        return figure(self) if path is None else plot_result(self, path)

    def write(self, out_dir: str | Path, variables: Sequence[str] | None = None, plot: bool = False) -> dict[str, Path]:
        """Write ``results.csv``, ``metrics.json`` (and ``plot.png``) into ``out_dir``.

        Returns
        -------
        dict
            File kind -> path written.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = {"results": out / "results.csv", "metrics": out / "metrics.json"}
        write_csv(self.data, files["results"], self.select(variables))
        self.write_metrics(files["metrics"])  # before the plot, which may fail (a missing extra)
        if plot:
            from ipcosim.harness.plot import plot_result

            files["plot"] = plot_result(self, out / "plot.png")
        return files

    def write_metrics(self, path: Path) -> None:
        """Write ``metrics.json``."""
        path.write_text(json.dumps(json_safe(self.metrics), indent=2) + "\n")


def write_csv(data: np.ndarray, path: Path, columns: Sequence[str]) -> None:
    """Write selected fields of a structured array as CSV, each column in its type: Real with
    full double precision, Integer as integers, Boolean as ``true``/``false``, String quoted
    where CSV needs it (the field's numpy type says which, see ``execution.COLUMN_DTYPE``)."""
    n = len(data)
    with open(path, "w", newline="") as fh:
        fh.write(",".join(columns) + "\n")
        if n == 0:
            return
        if all(data.dtype[c].kind == "f" for c in columns):
            matrix = np.column_stack([np.asarray(data[c], dtype=float) for c in columns])
            np.savetxt(fh, matrix, fmt="%.17g", delimiter=",")
            return
        import csv

        text = [_csv_column(data[c]) for c in columns]
        csv.writer(fh, lineterminator="\n").writerows(zip(*text))


def _csv_column(values: np.ndarray) -> list[str]:
    kind = values.dtype.kind
    if kind == "f":
        return ["%.17g" % v for v in values]
    if kind == "b":
        return ["true" if v else "false" for v in values]
    if kind in "iu":
        return [str(int(v)) for v in values]
    return [str(v) for v in values]


def json_safe(value: Any) -> Any:
    """A JSON-serializable copy: numpy scalars as Python numbers, non-finite floats as null."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Path):
        return str(value)
    return value


def first_column(columns: Sequence[str], candidates: Sequence[str]) -> str | None:
    for c in candidates:
        if c in columns:
            return c
    return None


def task_metrics(data: np.ndarray) -> dict[str, Any]:
    """The DESIGN.md metrics of a pendulum run (``ipcosim.harness.metrics.compute_metrics``), from the
    plant's motor-cart position and angle, the reference and the controller's voltage; an
    empty dict when the result lacks those columns or has fewer than two rows."""
    cols = list(data.dtype.names or ())
    pos, ang = first_column(cols, POSITION_COLUMNS), first_column(cols, ANGLE_COLUMNS)
    ref, volt = first_column(cols, REFERENCE_COLUMNS), first_column(cols, VOLTAGE_COLUMNS)
    if None in (pos, ang, ref, volt) or len(data) < 2:
        return {}
    try:
        from ipcosim.harness.metrics import compute_metrics
    except ImportError:
        return {}
    out = dict(compute_metrics(np.asarray(data["time"], float), np.asarray(data[pos], float),
                               np.asarray(data[ref], float), np.asarray(data[ang], float),
                               np.asarray(data[volt], float)))
    from ipcosim.harness.metrics import upright_metrics
    out.update(upright_metrics(np.asarray(data["time"], float), np.asarray(data[pos], float),
                               np.asarray(data[ang], float)))
    return out
