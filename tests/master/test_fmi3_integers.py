"""Every FMI 3.0 integer type carried exactly: ``--set`` values, connections, ``results.csv`` and the
Python result keep every bit of Int8 ... UInt64 (FMI 3.0 section 2.2.2: each type has the range of
its C type), and a value a connection cannot carry (out of the destination type's range) or a
``--set`` value out of the variable's range is an error naming it, never a wrapped value.

The test FMU is ``Ints3`` (``tests/data/cfmu/ints3.c``): each integer type in and out, and an
Int64 and a UInt64 parameter copied to outputs. The expected values below are the types' ranges,
written out, not the master's output.
"""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

import cfmu
import numpy as np
import pytest
from ssd_helpers import component, connection, connector, ssd, write_scenario

import ipcosim
from ipcosim.errors import IpcosimError
from ipcosim.harness import cli

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

#: One value per type at the edge of its range (FMI 3.0: the C types' ranges), and 5e9 / 4e9, the
#: values a 32-bit carrier turned into 705032704 and -294967296.
EDGES = {"i8": -128, "u8": 255, "i16": -32768, "u16": 65535, "i32": -2147483648, "u32": 4000000000,
         "i64": 5000000000, "u64": 18446744073709551615}
PARAMETERS = {"p64": -9223372036854775808, "pu64": 9223372036854775808}
DTYPES = {"i8": np.int8, "u8": np.uint8, "i16": np.int16, "u16": np.uint16, "i32": np.int32, "u32": np.uint32,
          "i64": np.int64, "u64": np.uint64}


@pytest.fixture(scope="module")
def ints3(tmp_path_factory) -> Path:
    return cfmu.build(cfmu.INTS3, tmp_path_factory.mktemp("ints3"))


def connectors(spec: cfmu.Spec = cfmu.INTS3) -> list[str]:
    return [connector(v.name, v.causality, None, "Integer") for v in spec.variables
            if v.causality in ("input", "output")]


def scenario(tmp_path: Path, ints3: Path, links: list[tuple[str, str]], stop: float = 0.3,
             source: Path | None = None) -> Path:
    """Components ``a`` and ``b`` (Ints3) and, with ``source``, ``src`` (Source3), connected by ``links``."""
    comps = [component("a", "Ints3", connectors()), component("b", "Ints3", connectors())]
    fmus = {"Ints3": ints3}
    if source is not None:
        comps.append(component("src", "Source3", [connector("count", "output", None, "Integer")]))
        fmus["Source3"] = source
    text = ssd("ints", comps, [connection(x, y) for x, y in links], stop=stop, step=0.1)
    return write_scenario(tmp_path / "ints", text, fmus)


def error_lines(capsys) -> list[str]:
    """The run's error lines on stderr (the unconnected inputs' warnings aside)."""
    return [line for line in capsys.readouterr().err.splitlines() if ": error:" in line]


def read_csv(path: Path) -> dict[str, list[str]]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return {name: [r[k] for r in rows[1:]] for k, name in enumerate(rows[0])}


def test_every_integer_type_keeps_every_bit_from_set_through_a_connection_to_the_record(tmp_path, ints3, capsys):
    folder = scenario(tmp_path, ints3, [(f"a.{t}_out", f"b.{t}_in") for t in EDGES])
    sets = [f"a.{t}_in={x}" for t, x in EDGES.items() if t != "i64"] + ["a.i64_in=5e9"]
    sets += [f"a.{k}={x}" for k, x in PARAMETERS.items()]
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet",
                   *(arg for s in sets for arg in ("--set", s))])
    assert rc == 0, capsys.readouterr().err
    col = read_csv(tmp_path / "out" / "results.csv")
    for t, x in EDGES.items():
        for name in (f"a.{t}_in", f"a.{t}_out", f"b.{t}_in", f"b.{t}_out"):
            assert col[name] == [str(x)] * 4, name
    assert col["a.p64_out"] == ["-9223372036854775808"] * 4
    assert col["a.pu64_out"] == ["9223372036854775808"] * 4
    # the Python API: the same values, each column in its type
    with ipcosim.prepare(folder) as prepared:
        r = prepared.run(set={**{f"a.{t}_in": x for t, x in EDGES.items()},
                              **{f"a.{k}": x for k, x in PARAMETERS.items()}})
    for t, x in EDGES.items():
        assert r.data.dtype[f"b.{t}_out"] == DTYPES[t]
        assert [int(v) for v in r[f"b.{t}_out"]] == [x] * 4 and [int(v) for v in r[f"b.{t}_in"]] == [x] * 4
    assert int(r["b.u64_out"][-1]) == 2 ** 64 - 1 and int(r["b.u32_out"][-1]) == 4 * 10 ** 9
    assert int(r["b.i64_out"][-1]) == 5 * 10 ** 9
    assert int(r["a.pu64_out"][0]) == 2 ** 63 and int(r["a.p64_out"][0]) == -2 ** 63


@pytest.mark.parametrize("src, dst, value", [
    ("i64", "i32", 5000000000),              # a 64-bit integer into a 32-bit input
    ("u32", "i32", 4000000000),              # above 2**31 - 1 into Int32
    ("i32", "u32", -1),                      # a negative into unsigned
    ("u64", "i64", 9223372036854775808),     # 2**63 into Int64
    ("i16", "u8", 256),                      # out of range
    ("i64", "u64", -9223372036854775808),
])
def test_a_value_the_connection_cannot_carry_is_an_error_naming_it(tmp_path, ints3, capsys, src, dst, value):
    folder = scenario(tmp_path, ints3, [(f"a.{src}_out", f"b.{dst}_in")])
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet", "--set", f"a.{src}_in={value}"])
    err = error_lines(capsys)
    assert rc != 0 and len(err) == 1, err
    assert f"a.{src}_out -> b.{dst}_in" in err[0] and str(value) in err[0], err
    with pytest.raises(IpcosimError, match=f"a.{src}_out -> b.{dst}_in cannot carry {value}"):
        ipcosim.run(folder, set={f"a.{src}_in": value})


@pytest.mark.parametrize("src, dst, value", [("i64", "i32", -2147483648), ("u64", "i8", 127), ("i32", "u64", 0)])
def test_a_value_in_range_crosses_a_narrower_connection_unchanged(tmp_path, ints3, src, dst, value):
    folder = scenario(tmp_path, ints3, [(f"a.{src}_out", f"b.{dst}_in")])
    r = ipcosim.run(folder, set={f"a.{src}_in": value})
    assert [int(v) for v in r[f"b.{dst}_out"]] == [value] * 4


def test_a_connection_fails_in_the_step_its_source_leaves_the_range_and_keeps_the_rows_before(tmp_path, ints3):
    """Source3's step counter (Int32) into an Int8 input: the count reaches 128 after 128 steps
    of 0.1 s; the run fails in the step from t = 12.7 s, naming the connection and 128, and the
    rows up to t = 12.7 s (count 127) are the result."""
    source = cfmu.build(cfmu.SOURCE3, tmp_path / "src-fmu")
    folder = scenario(tmp_path, ints3, [("src.count", "a.i8_in")], stop=20.0, source=source)
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet"])
    assert rc != 0
    col = read_csv(tmp_path / "out" / "results.csv")
    assert col["a.i8_out"] == [str(n) for n in range(128)]
    assert float(col["time"][-1]) == pytest.approx(12.7)
    with pytest.raises(IpcosimError, match=r"src.count -> a.i8_in cannot carry 128: Int8 holds -128 .. 127.*12\.7 s"):
        ipcosim.run(folder)


@pytest.mark.parametrize("assignment, message", [
    ("a.u8_in=256", "256' is out of the range of UInt8 (0 .. 255)"),
    ("a.i64_in=9223372036854775808", "out of the range of Int64"),
    ("a.pu64=18446744073709551616", "out of the range of UInt64"),
    ("a.pu64=-1", "out of the range of UInt64"),
    ("a.i32_in=1.5", "is not a valid Int32 value"),
])
def test_a_set_value_out_of_the_type_is_refused_naming_it(tmp_path, ints3, capsys, assignment, message):
    folder = scenario(tmp_path, ints3, [])
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet", "--set", assignment])
    err = error_lines(capsys)
    assert rc != 0 and len(err) == 1 and message in err[0] and assignment.split("=")[0] in err[0], err


def test_jacobi_records_no_value_its_connection_cannot_deliver(tmp_path, ints3):
    """Jacobi delivers the count of row r in the step after it: the count 128 is recorded at
    t = 12.8 s as what the connection would deliver into the Int8 input, which it cannot; the
    rows before it are written (a.i8_in = the count r, a.i8_out one step behind), none after."""
    source = cfmu.build(cfmu.SOURCE3, tmp_path / "src-fmu")
    folder = scenario(tmp_path, ints3, [("src.count", "a.i8_in")], stop=20.0, source=source)
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet", "--algorithm", "jacobi"])
    assert rc != 0
    col = read_csv(tmp_path / "out" / "results.csv")
    assert col["a.i8_in"] == [str(n) for n in range(128)]
    assert col["a.i8_out"] == ["0"] + [str(n) for n in range(127)]
    with pytest.raises(IpcosimError, match=r"src.count -> a.i8_in cannot carry 128: Int8 holds -128 .. 127.*12\.8 s"):
        ipcosim.run(folder, algorithm="jacobi")


def test_integer_values_parse_exactly_and_hold_their_types_ranges():
    from ipcosim.harness.master import integers

    assert integers.exact_integer("5e9") == 5 * 10 ** 9 and integers.exact_integer(5e9) == 5 * 10 ** 9
    assert integers.exact_integer("18446744073709551615") == 2 ** 64 - 1  # no detour through a double
    for bad in ("1.5", 1.5, True, float("inf"), "nan", "x"):
        with pytest.raises(ValueError):
            integers.exact_integer(bad)
    # UInt64 in the int64 vector: the same 64 bits, and back
    assert integers.stored(2 ** 64 - 1, "UInt64") == -1 and integers.value(-1, "UInt64") == 2 ** 64 - 1
    assert integers.stored(2 ** 63, "UInt64") == -2 ** 63 and integers.value(-2 ** 63, "Int64") == -2 ** 63
    assert not integers.narrowing("Int32", "Int64") and not integers.narrowing("UInt8", "Int16")
    assert integers.narrowing("UInt32", "Int32") and integers.narrowing("Int8", "UInt64")
    assert integers.integer_type("Enumeration", "3.0") == "Int64" and integers.integer_type("Enumeration") == "Integer"
