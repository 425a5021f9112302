"""``ipcosim view``: a finished run's folder (results.csv and metrics.json) on the live page, or a
sweep's folder (results.csv, one row per run) as its table.

A run folder is told from a sweep's by its ``metrics.json``: ``ipcosim run`` writes one, a sweep
writes ``metadata.json`` and ``summary.json`` beside its table instead.
"""
from __future__ import annotations

import csv
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ipcosim.errors import IpcosimError
from ipcosim.harness.live.scene import scene
from ipcosim.harness.live.server import MAX_ROWS, LiveServer, finite_rows

#: A finished run is shown with at most this many rows (every n-th row of a longer one).
VIEW_ROWS = 20000


class ViewError(IpcosimError, ValueError):
    """A folder ``ipcosim view`` cannot show (names the folder and what is missing)."""


def _number(text: str) -> float:
    """A CSV cell as a float (``True``/``False`` as 1/0); NaN for text."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return 1.0 if low == "true" else 0.0
    try:
        return float(text)
    except ValueError:
        return math.nan


def _positive(value: Any) -> float | None:
    """A positive number from metrics.json, else None (a folder written before the key, or a run without a limit)."""
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0 else None


def read_results(path: Path) -> tuple[list[str], np.ndarray]:
    """The numeric columns of a run's results.csv (text columns such as a card's ``last_error`` are left
    out) and their rows.

    Raises
    ------
    ViewError
        A file without a ``time`` column or without rows.
    """
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, [])
            rows = [row for row in reader if row]
    except (OSError, UnicodeDecodeError) as exc:
        raise ViewError(f"{path}: cannot read it ({exc})") from None
    if not header or header[0] != "time":
        raise ViewError(f"{path}: not a run's results (its first column is not 'time')")
    if not rows:
        raise ViewError(f"{path}: no rows")
    keep = [j for j, name in enumerate(header) if j == 0 or not math.isnan(_number(rows[0][j]))
            or rows[0][j].strip().lower() in ("nan", "")]
    data = np.array([[_number(row[j]) if j < len(row) else math.nan for j in keep] for row in rows])
    return [header[j] for j in keep], data


class FinishedRun:
    """A run's folder as a page :class:`~ipcosim.harness.live.server.Source` (no stop button)."""

    live = False

    def __init__(self, folder: Path) -> None:
        self.names, rows = read_results(folder / "results.csv")
        every = max(1, math.ceil(len(rows) / VIEW_ROWS))
        self.rows = rows[::every] if every > 1 else rows
        if every > 1 and self.rows[-1, 0] != rows[-1, 0]:
            self.rows = np.vstack([self.rows, rows[-1:]])
        try:
            self.metrics: dict[str, Any] = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ViewError(f"{folder / 'metrics.json'}: cannot read it ({exc})") from None
        self.title = folder.resolve().name
        limit = _positive(self.metrics.get("voltage_limit_V"))  # the run's, recorded since the key exists
        self._scene = {"scene": scene(self.names, self.title, voltage_limit=limit), "names": self.names}
        step = float(rows[1, 0] - rows[0, 0]) if len(rows) > 1 else 0.0
        self.info = {"start_time": float(rows[0, 0]), "stop_time": float(rows[-1, 0]), "step": step,
                     "paced": "realtime_steps" in self.metrics}
        self.pacing = ({"steps": self.metrics["realtime_steps"], "late_steps": self.metrics.get("overruns", 0),
                        "overrun_budget": self.metrics.get("overrun_budget", 0.01), "tolerance_s": step / 2}
                       if "realtime_steps" in self.metrics else None)

    def scene(self) -> dict[str, Any]:
        return self._scene

    def samples(self, since: int) -> dict[str, Any]:
        end = min(len(self.rows), since + MAX_ROWS)
        fault = self.metrics.get("rig_fault")
        return {"rows": finite_rows(self.rows[since:end]), "next": end, "more": end < len(self.rows),
                "state": "failed" if fault else "finished", "message": fault or "", "info": self.info,
                "pacing": self.pacing, "rig": None, "metrics": self.metrics}

    def stop(self) -> bool:
        return False


class Table:
    """A page of its own (a sweep's table): nothing to poll, nothing to stop."""

    live = False

    def scene(self) -> None:
        return None

    def samples(self, since: int) -> dict[str, Any]:
        return {"rows": [], "next": 0, "more": False, "state": "finished"}

    def stop(self) -> bool:
        return False


def sweep_page(folder: Path) -> str:
    """A sweep's results.csv as an HTML table (every row, every column; plain HTML, nothing fetched)."""
    path = folder / "results.csv"
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = [row for row in csv.reader(fh) if row]
    except (OSError, UnicodeDecodeError) as exc:
        raise ViewError(f"{path}: cannot read it ({exc})") from None
    if not rows:
        raise ViewError(f"{path}: empty")
    head = "".join(f"<th>{html.escape(c)}</th>" for c in rows[0])
    body = "\n".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows[1:])
    title = html.escape(f"sweep {folder.resolve().name}: {len(rows) - 1} runs")
    made = html.escape(_made_by(folder))
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title><style>"
            "body{font:13px/1.3 system-ui,sans-serif;margin:14px;background:#fafafa}"
            "table{border-collapse:collapse;background:#fff}th,td{border:1px solid #ddd;padding:2px 6px;"
            "text-align:right;white-space:nowrap}th{background:#f0f0f0;position:sticky;top:0}"
            "tr:nth-child(even) td{background:#f7f7f7}</style></head>"
            f"<body><h1 style=\"font-size:17px\">{title}</h1>\n<p id=\"made\">{made}</p>\n"
            f"<table id=\"sweep\"><thead><tr>{head}</tr></thead>"
            f"<tbody>\n{body}\n</tbody></table></body></html>\n")


def _made_by(folder: Path) -> str:
    """Where a sweep's table comes from (its metadata.json: scenario, start, the ipcosim that ran it)
    and the ipcosim showing it."""
    from ipcosim.harness.support.paths import distribution_version

    shown = f"shown by ipcosim {distribution_version()}"
    try:
        meta = json.loads((folder / "metadata.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return f"metadata.json not readable ({type(exc).__name__}): what made these runs is unknown; {shown}"
    if not isinstance(meta, dict):
        return f"metadata.json holds no object: what made these runs is unknown; {shown}"
    packages = meta.get("packages") if isinstance(meta.get("packages"), dict) else {}
    made = ", ".join(f"{key} {meta[key]}" for key in ("scenario", "started") if key in meta)
    return f"{made + '; ' if made else ''}run by ipcosim {packages.get('ipcosim', '(not recorded)')}; {shown}"


def view_server(folder: str | Path, host: str = "127.0.0.1", port: int = 0, token: str | None = None) -> LiveServer:
    """Serve ``folder``: a run's page, or a sweep's table.

    Raises
    ------
    ViewError
        Neither a run's folder (results.csv and metrics.json) nor a sweep's (results.csv).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ViewError(f"{folder}: not a folder (expected a run's or a sweep's output folder)")
    if not (folder / "results.csv").is_file():
        raise ViewError(f"{folder}: no results.csv (expected `ipcosim run --out` or `ipcosim sweep --out` output)")
    if (folder / "metrics.json").is_file():
        return LiveServer(FinishedRun(folder), host, port, token)
    return LiveServer(Table(), host, port, token, html=sweep_page(folder))
