"""A sweep's results read back column by column, in memory independent of the sweep's size.

:class:`ResultColumns` reads ``results.csv`` once, a row at a time, into one binary file of float64
per column asked for (NaN where a run has no finite number; true and false as 1 and 0) and one of
status codes, in a temporary folder; its :meth:`~ResultColumns.chunks` then give a column's values
(of the runs with given statuses) a chunk at a time, as often as asked.

:func:`distribution` is the summary of one metric (``n``, mean, std, min, p5, median, p90, p95,
max): numpy's own functions on the values held in memory when there are at most
:data:`IN_MEMORY_VALUES` of them, else :func:`stream_distribution`, the same numbers from passes
over the chunks (the mean and standard deviation exactly rounded sums, the percentiles numpy's
linear interpolation between order statistics found exactly by :func:`order_statistic`).
"""
from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from ipcosim.harness.studies.store import iter_results

#: Values of one metric taken into memory at once (0.5 MB) to summarize them with numpy's functions;
#: a metric of more runs is summarized from passes over its values on disk.
IN_MEMORY_VALUES = 1 << 16
#: Values handled at a time.
CHUNK = 1 << 14
#: Rows of the results file parsed at a time (about 1.5 kB each).
ROW_BLOCK = 1024
#: Percentiles of the summary (with the median, numpy's middle value or mean of the two middle ones).
PERCENTILES = {"p5": 5.0, "p90": 90.0, "p95": 95.0}

Chunks = Callable[[], Iterable[np.ndarray]]


def _number(value: Any) -> float:
    if isinstance(value, bool):
        return 1.0 if value else 0.0
    if isinstance(value, (int, float)) and math.isfinite(value):
        return float(value)
    return math.nan


class ResultColumns:
    """Columns ``names`` of a results file on disk, read in chunks (a context manager: the temporary
    folder is removed on leaving it).

    Attributes
    ----------
    runs : int
        Rows read.
    counts : dict
        Runs per status, in the order first seen.
    present : set of str
        The names that had a number (a finite one, or true or false) in some row.
    """

    def __init__(self, path: str | os.PathLike, names: Sequence[str], chunk: int | None = None) -> None:
        self.names = list(dict.fromkeys(names))
        self.chunk = chunk or CHUNK
        block_rows = ROW_BLOCK
        self._dir = tempfile.TemporaryDirectory(prefix="ipcosim-columns-")
        self.runs = 0
        self.counts: dict[str, int] = {}
        self.present: set[str] = set()
        codes: dict[str, int] = {}
        _, rows = iter_results(path)
        files = {n: open(self._file(n), "wb") for n in self.names}
        status_file = open(self._file(None), "wb")
        try:
            block: list[Any] = []
            for row in rows:
                block.append(row)
                if len(block) == block_rows:
                    self._write(block, files, status_file, codes)
                    block = []
            self._write(block, files, status_file, codes)
        finally:
            rows.close()
            for f in (*files.values(), status_file):
                f.close()
        self._codes = codes

    def _file(self, name: str | None) -> Path:
        return Path(self._dir.name) / ("status" if name is None else f"{self.names.index(name)}.f64")

    def _write(self, block: list[Any], files: dict[str, Any], status_file: Any, codes: dict[str, int]) -> None:
        if not block:
            return
        for r in block:
            self.counts[r["status"]] = self.counts.get(r["status"], 0) + 1
            codes.setdefault(r["status"], len(codes))
        np.array([codes[r["status"]] for r in block], dtype=np.uint8).tofile(status_file)
        for name, f in files.items():
            x = np.array([_number(r.get(name)) for r in block], dtype=np.float64)
            if name not in self.present and any(isinstance(r.get(name), (bool, int, float)) for r in block):
                self.present.add(name)
            x.tofile(f)
        self.runs += len(block)

    def __enter__(self) -> "ResultColumns":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Remove the temporary folder."""
        self._dir.cleanup()

    def chunks(self, name: str, statuses: Iterable[str] | None = None) -> Iterator[np.ndarray]:
        """The finite values of column ``name`` of the runs with one of ``statuses`` (all runs: None), in
        file order, at most ``chunk`` (default :data:`CHUNK`) at a time."""
        wanted = None if statuses is None else np.array(sorted(self._codes[s] for s in statuses if s in self._codes),
                                                        dtype=np.uint8)
        with open(self._file(name), "rb") as values, open(self._file(None), "rb") as status:
            while True:
                x = np.fromfile(values, dtype=np.float64, count=self.chunk)
                if x.size == 0:
                    return
                code = np.fromfile(status, dtype=np.uint8, count=x.size)
                keep = np.isfinite(x)
                if wanted is not None:
                    keep &= np.isin(code, wanted)
                if keep.any():
                    yield x[keep]

    def source(self, name: str, statuses: Iterable[str] | None = None) -> Chunks:
        """A callable giving :meth:`chunks` afresh on each call (for what passes over the values more than once)."""
        statuses = None if statuses is None else tuple(statuses)
        return lambda: self.chunks(name, statuses)


def count(chunks: Chunks) -> int:
    """Number of values."""
    return sum(int(c.size) for c in chunks())


def gather(chunks: Chunks, limit: int) -> np.ndarray | None:
    """Every value in one array, in order, when there are at most ``limit`` of them; else None."""
    parts, n = [], 0
    for c in chunks():
        n += c.size
        if n > limit:
            return None
        parts.append(c)
    return np.concatenate(parts) if parts else np.zeros(0)


def order_statistic(chunks: Chunks, k: int, limit: int = IN_MEMORY_VALUES, bins: int = 1024) -> float:
    """The value of rank ``k`` (0: the smallest) of the values ``chunks()`` gives, exactly, holding at most ``limit``
    of them: each round passes over them to take the count, least and greatest inside an interval known to hold
    rank ``k`` (at first every value), then, while more than ``limit`` are inside, again to count them in
    ``bins`` equal parts of that range and narrow it to the part holding rank ``k``.

    Raises
    ------
    IndexError
        ``k`` is not a rank of the values.
    """
    lo, hi, below = -math.inf, math.inf, 0  # rank k lies in (lo, hi]; ``below`` values are <= lo
    while True:
        inside, least, most = 0, math.inf, -math.inf
        for c in chunks():
            x = c[(c > lo) & (c <= hi)]
            if x.size:
                inside += x.size
                least, most = min(least, float(x.min())), max(most, float(x.max()))
        if not 0 <= k - below < inside:
            raise IndexError(f"rank {k} of {below + inside} values")
        if least == most:
            return least
        if inside <= limit:
            x = np.concatenate([c[(c > lo) & (c <= hi)] for c in chunks()])
            return float(np.partition(x, k - below)[k - below])
        edges = np.linspace(least, most, bins + 1)
        counts = np.zeros(bins + 1, dtype=np.int64)  # part j: (edges[j-1], edges[j]]; part 0: the least value
        for c in chunks():
            x = c[(c > lo) & (c <= hi)]
            counts += np.bincount(np.searchsorted(edges, x, side="left"), minlength=bins + 1)
        cumulative = np.cumsum(counts)
        j = int(np.searchsorted(cumulative, k - below, side="right"))
        before = int(cumulative[j - 1]) if j else 0
        lo, hi, below = (lo if j == 0 else float(edges[j - 1])), float(edges[j]), below + before


def _lerp(a: float, b: float, t: float) -> float:
    """numpy's linear interpolation of a percentile between neighbouring order statistics."""
    diff = b - a
    return b - diff * (1 - t) if t >= 0.5 else a + diff * t


def stream_distribution(chunks: Chunks, limit: int = IN_MEMORY_VALUES) -> dict[str, float]:
    """:func:`distribution` of the values ``chunks()`` gives, from passes over them (at most ``limit`` held)."""
    n, least, most, parts = 0, math.inf, -math.inf, []
    for c in chunks():
        n += c.size
        least, most = min(least, float(c.min())), max(most, float(c.max()))
        parts.append(math.fsum(c.tolist()))
    if n == 0:
        return {"n": 0}
    mean = math.fsum(parts) / n
    std = math.sqrt(math.fsum(math.fsum(((c - mean) ** 2).tolist()) for c in chunks()) / n)

    def rank(k: int) -> float:
        return order_statistic(chunks, k, limit)

    def percentile(q: float) -> float:
        h = (n - 1) * q / 100.0
        k = math.floor(h)
        return rank(k) if k + 1 >= n else _lerp(rank(k), rank(k + 1), h - k)

    median = rank(n // 2) if n % 2 else (rank(n // 2 - 1) + rank(n // 2)) / 2.0
    out = {"n": n, "mean": mean, "std": std, "min": least, "p5": percentile(PERCENTILES["p5"]), "median": median,
           "p90": percentile(PERCENTILES["p90"]), "p95": percentile(PERCENTILES["p95"]), "max": most}
    return out


def array_distribution(x: np.ndarray) -> dict[str, float]:
    """``n``, mean, std, min, p5, median, p90, p95 and max of the values ``x`` (numpy's functions)."""
    if x.size == 0:
        return {"n": 0}
    return {"n": int(x.size), "mean": float(np.mean(x)), "std": float(np.std(x)),
            "min": float(np.min(x)), "p5": float(np.percentile(x, PERCENTILES["p5"])),
            "median": float(np.median(x)), "p90": float(np.percentile(x, PERCENTILES["p90"])),
            "p95": float(np.percentile(x, PERCENTILES["p95"])), "max": float(np.max(x))}


def distribution(chunks: Chunks, limit: int = IN_MEMORY_VALUES) -> dict[str, float]:
    """The summary of one metric's values: :func:`array_distribution` of them in memory when there are at most
    ``limit``, else :func:`stream_distribution`."""
    x = gather(chunks, limit)
    return array_distribution(x) if x is not None else stream_distribution(chunks, limit)
