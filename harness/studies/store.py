"""A sweep's results on disk: ``DIR/results.csv`` (one row per run: index, seed, status, success,
error message, parameter values, metrics, run time; appended and flushed as each run finishes,
rewritten sorted by index at the end) and ``DIR/metadata.json`` (scenario hash, variations,
seeds, executor and :func:`package_versions`).
"""
from __future__ import annotations

import csv
import functools
import io
import os
import platform
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence, TextIO

BASE_COLUMNS = ("index", "seed", "status", "success", "error")


TAIL_COLUMNS = ("run_time_s",)


RESULTS_FILE = "results.csv"


METADATA_FILE = "metadata.json"


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return " ".join(value.split())
    return str(value)


def _parse(column: str, text: str) -> Any:
    if column in ("status", "error"):
        return text
    if column in ("index", "seed"):
        return int(text)
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    try:
        return float(text)
    except ValueError:
        return text


def flatten(row: Mapping[str, Any]) -> dict[str, Any]:
    """A result row as one flat dict (parameters and metrics as columns)."""
    flat = {k: row.get(k) for k in BASE_COLUMNS}
    flat.update(row.get("params", {}))
    flat.update(row.get("metrics", {}))
    flat["run_time_s"] = row.get("run_time_s")
    return flat


def read_results(path: str | os.PathLike) -> tuple[list[str], list[dict[str, Any]]]:
    """Read a results CSV: (columns, rows as typed flat dicts). A trailing incomplete line (a
    sweep killed while writing) is ignored."""
    text = Path(path).read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    try:
        columns = next(reader)
    except StopIteration:
        return [], []
    rows = []
    for record in reader:
        if len(record) != len(columns):
            continue
        rows.append({c: _parse(c, v) for c, v in zip(columns, record)})
    return columns, rows


class ResultsWriter:
    """Appends rows to a CSV file, one flushed line per finished run."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path = path
        self.columns = list(columns)
        self._fh: TextIO | None = None

    def open(self, existing: bool) -> None:
        if existing:
            data = self.path.read_bytes()
            if data and not data.endswith(b"\n"):  # drop a half-written last line
                with open(self.path, "r+b") as fh:
                    fh.truncate(data.rfind(b"\n") + 1)
            self._fh = open(self.path, "a", newline="")
        else:
            self._fh = open(self.path, "w", newline="")
            csv.writer(self._fh).writerow(self.columns)
            self._fh.flush()

    def append(self, flat: Mapping[str, Any]) -> None:
        assert self._fh is not None
        csv.writer(self._fh).writerow([_format(flat.get(c)) for c in self.columns])
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def rewrite_sorted(self, rows: Iterable[Mapping[str, Any]]) -> None:
        """Replace the file atomically by the given rows sorted by index."""
        self.close()
        tmp = self.path.with_suffix(".csv.tmp")
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(self.columns)
            for row in sorted(rows, key=lambda r: r["index"]):
                w.writerow([_format(row.get(c)) for c in self.columns])
        os.replace(tmp, self.path)


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages a run's results depend on."""
    return dict(_package_versions())


@functools.lru_cache(maxsize=1)
def _package_versions() -> tuple[tuple[str, str], ...]:
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("ipcosim", "numpy", "scipy", "control", "fmpy", "pythonfmu", "dask", "distributed"):
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return tuple(versions.items())


def discard_results(out: Path) -> None:
    """Remove a sweep's results from ``out`` (``results.csv``, ``metadata.json``, the summary and its figures),
    so that the sweep starts afresh; other files stay."""
    import shutil

    for name in (RESULTS_FILE, METADATA_FILE, "summary.md", "summary.json"):
        (out / name).unlink(missing_ok=True)
    shutil.rmtree(out / "figures", ignore_errors=True)
