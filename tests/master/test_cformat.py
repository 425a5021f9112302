"""results.csv's Real columns formatted in C: the bytes of Python's ``"%.17g" % value``, every value read back exact."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.harness.master import cformat
from ipcosim.harness.master.results import csv_bytes

#: Values whose text is easy to get wrong: signed zeros, the ends of the double range, subnormals, the
#: switch between fixed and exponent forms at 17 digits, ties, non-finite values.
SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.1, 1 / 3, 0.5, 2.5, 1e-5, 1e-4, 1e16, 1e17, 9999999999999998.0, 1e22,
           123456789012345678.0, 5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308,
           1.7976931348623157e308, -1.7976931348623157e308, math.inf, -math.inf, math.nan, -math.nan]


def python_lines(columns: list[np.ndarray]) -> bytes:
    rows = zip(*(["%.17g" % v for v in col.tolist()] for col in columns))
    return "".join(",".join(row) + "\n" for row in rows).encode()


def needs_library() -> None:
    if cformat._function() is None:
        pytest.skip("the formatting library cannot be built here (no C compiler)")


def test_special_values_as_python_formats_them() -> None:
    needs_library()
    col = np.array(SPECIAL * 3)
    columns = [col, col[::-1].copy(), col]  # a column twice, as an output and the input it feeds
    assert bytes(cformat.lines(columns)) == python_lines(columns)


def test_random_bit_patterns_and_repeats() -> None:
    needs_library()
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2 ** 64, size=(3, 20000), dtype=np.uint64).view(np.float64)
    steady = np.repeat(bits[0, :200], 100)  # runs of equal values: each formatted once, written each row
    columns = [bits[0], bits[1], steady, bits[2], steady]
    text = bytes(cformat.lines(columns))
    assert text == python_lines(columns)
    finite = [float(x) for line in text.decode().splitlines() for x in line.split(",") if x not in ("nan",)]
    assert finite == [v for row in zip(*(c.tolist() for c in columns)) for v in row if not math.isnan(v)]


def _neighbours(x: float, steps: int) -> list[float]:
    """``x`` and the ``steps`` doubles either side of it."""
    out, down, up = [x], x, x
    for _ in range(steps):
        down, up = math.nextafter(down, -math.inf), math.nextafter(up, math.inf)
        out += [down, up]
    return out


def test_values_a_run_records_and_the_roundings_between_them() -> None:
    """The magnitudes formatted in exact integer arithmetic (1e-16 .. 1e17) and either side of them: log-uniform
    values of both signs, the doubles beside each power of ten and each d * 10**k (where the 17 digits carry into
    another decimal exponent, or the form changes between fixed and exponent), and exact ties at the 17th digit
    (``(4e15 + odd) / 4``: 18 significant digits ending in 5, rounded half to even)."""
    needs_library()
    rng = np.random.default_rng(11)
    logs = np.sign(rng.standard_normal(60000)) * 10.0 ** rng.uniform(-18, 18, 60000)
    edges = [v for k in range(-18, 19) for d in range(1, 10) for v in _neighbours(d * 10.0 ** k, 6)]
    ties = [m / 4 for m in range(4 * 10**15 + 1, 4 * 10**15 + 2001, 2)]
    assert "%.17g" % ties[0] == "1000000000000000.2" and "%.17g" % ties[1] == "1000000000000000.8"
    crafted = np.array(edges + [-v for v in edges] + ties + [-v for v in ties])
    columns = [logs, np.resize(crafted, logs.size), np.cumsum(np.full(logs.size, 1e-3))]
    assert bytes(cformat.lines(columns)) == python_lines(columns)


def test_csv_bytes_without_the_library_are_the_same(monkeypatch: pytest.MonkeyPatch) -> None:
    data = np.zeros(50, dtype=[("time", "f8"), ("a.y", "f8")])
    data["time"] = np.arange(50) * 1e-3
    data["a.y"] = np.sin(np.arange(50))
    with_library = bytes(csv_bytes(data, ["time", "a.y", "a.y"]))
    monkeypatch.setattr(cformat, "_FUNCTION", [None])
    assert bytes(csv_bytes(data, ["time", "a.y", "a.y"])) == with_library == python_lines(
        [data["time"], data["a.y"], data["a.y"]])
