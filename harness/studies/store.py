"""A sweep's results on disk: ``DIR/results.csv`` (one row per run: index, seed, status, success,
error message, parameter values, metrics, run time; appended and flushed as each run finishes,
sorted by index at the end) and ``DIR/metadata.json`` (scenario hash, variations,
seeds, executor and :func:`package_versions`).

The file is read back a row at a time (:func:`iter_results`) and sorted in chunks
(:func:`sort_results`), so neither holds more than a chunk of a sweep's rows whatever its size.
"""
from __future__ import annotations

import csv
import functools
import heapq
import itertools
import os
import platform
import tempfile
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence, TextIO

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
    columns, rows = iter_results(path)
    return columns, list(rows)


def iter_results(path: str | os.PathLike) -> tuple[list[str], Iterator[dict[str, Any]]]:
    """A results CSV a row at a time: (columns, an iterator of typed flat dicts). A row of
    another width, or a trailing incomplete line (a sweep killed while writing), is skipped."""
    fh = open(path, newline="")
    try:
        columns = next(csv.reader(_complete_lines(fh)), [])
    except BaseException:
        fh.close()
        raise

    def rows() -> Iterator[dict[str, Any]]:
        with fh:
            for record in csv.reader(_complete_lines(fh)):
                if len(record) == len(columns):
                    yield {c: _parse(c, v) for c, v in zip(columns, record)}

    return columns, rows()


def _complete_lines(fh: TextIO) -> Iterator[str]:
    """The lines of ``fh`` that end in a newline (a half-written last line is left out)."""
    for line in fh:
        if line.endswith("\n"):
            yield line


#: Rows of a results file sorted in memory at once by :func:`sort_results` (about 0.3 kB each).
SORT_CHUNK = 4096
#: Sorted chunks merged at once by :func:`sort_results` (each an open file with its 8 kB buffer).
MERGE_FILES = 64


def _row_index(line: bytes) -> int:
    """The run index a results row starts with (-1 for a line that starts with none)."""
    try:
        return int(line.split(b",", 1)[0])
    except ValueError:
        return -1


def sort_results(path: Path, keep: Callable[[int], bool] = lambda index: True, chunk: int | None = None) -> None:
    """Sort a results file by run index in place, atomically, holding at most ``chunk`` rows.

    Each row keeps its text as written. Rows whose index ``keep`` refuses are dropped, so is a half-written
    last line; of two rows with the same index the first one stays. Chunks of ``chunk`` rows are sorted
    in memory (default :data:`SORT_CHUNK`) and merged from temporary files (a merge of many chunks in rounds of
    at most :data:`MERGE_FILES`).
    """
    chunk = chunk or SORT_CHUNK
    with open(path, "rb") as fh, tempfile.TemporaryDirectory(prefix="ipcosim-sort-") as tmp:
        header = fh.readline()
        if not header.endswith(b"\n"):
            return
        lines = (line for line in fh if line.endswith(b"\n") and _row_index(line) >= 0 and keep(_row_index(line)))
        spills: list[Path] = []
        order = itertools.count()
        while True:
            block = sorted(((_row_index(line), next(order), line) for line in itertools.islice(lines, chunk)))
            if not block:
                break
            spill = Path(tmp) / f"{len(spills)}.csv"
            with open(spill, "wb") as out:
                out.writelines(line for _, _, line in block)
            spills.append(spill)
        while len(spills) > MERGE_FILES:  # merge in rounds: never more files open than that
            merged = Path(tmp) / f"{len(spills)}-{next(order)}.csv"
            _merge(spills[:MERGE_FILES], merged)
            spills = [merged, *spills[MERGE_FILES:]]  # the earliest rows first, as they were
        result = path.with_suffix(".csv.tmp")
        with open(result, "wb") as out:
            out.write(header)
        _merge(spills, result, append=True, unique=True)
    os.replace(result, path)


def _merge(parts: Sequence[Path], target: Path, append: bool = False, unique: bool = False) -> None:
    """Merge files of rows sorted by index into ``target`` (of rows with the same index, the earlier file's
    first; with ``unique``, only that one)."""
    files = [open(p, "rb") for p in parts]
    try:
        streams = [((_row_index(line), k, line) for line in f) for k, f in enumerate(files)]
        with open(target, "ab" if append else "wb") as out:
            merged = heapq.merge(*streams)
            if unique:
                for _, group in itertools.groupby(merged, key=lambda item: item[0]):
                    out.write(next(group)[2])
            else:
                out.writelines(line for _, _, line in merged)
    finally:
        for f in files:
            f.close()


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
