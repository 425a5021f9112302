"""The compiled C stepping loop against the Python loop: the same records bit for bit on every
kind of system the master's tests build (Gauss-Seidel, Jacobi, multi-rate, partial last period,
short last tick, record_every, unit conversions), the same failure reports and the same end of
a run a component ends itself; which loop ran in the metadata; the fallback without a compiler;
the cache keyed by the structure alone.

The mock components are Python slaves, which the C loop calls back through ctypes when forced
(``loop="c"``); the native and Python FMUs are in tests/native/test_native.py."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from master_mocks import DISCARD, ERROR, OK, Factory, loop_factory, loop_system, model, system

from ipcosim.harness.api.engine import Prepared
from ipcosim.harness.master import cloop
from ipcosim.harness.master.slave import TERMINATE
from ipcosim.toolchain import find_compiler

needs_cc = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC or install gcc/clang)")
pytestmark = needs_cc
H = 0.01


def run(sysm, factory_fn, loop, **kw):
    kw.setdefault("raise_on_error", False)
    algorithm = kw.pop("algorithm", "gauss-seidel")
    return Prepared(system=sysm, slave_factory=factory_fn(), algorithm=algorithm).run(loop=loop, **kw)


def both(sysm, factory_fn, **kw):
    """The run on the C loop and on the Python loop; checks the C loop ran."""
    c = run(sysm, factory_fn, "c", **kw)
    py = run(sysm, factory_fn, "python", **kw)
    assert c.metadata["loop"] == "c" and py.metadata["loop"] == "python (forced)"
    return c, py


def assert_same(c, py):
    assert c.data.dtype == py.data.dtype and len(c.data) == len(py.data)
    assert c.data.tobytes() == py.data.tobytes()  # bit for bit, NaNs and signed zeros included
    for key in ("status", "error", "ticks_done", "end_time", "terminated_by", "order", "step_multiples"):
        assert c.metadata[key] == py.metadata[key], key


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("case", [
    {"stop_time": 1.0},                                                     # one rate
    {"stop_time": 1.0, "set": {"controller.sample_period": 2 * H}},   # multi-rate, whole periods
    {"stop_time": 1.0, "set": {"controller.sample_period": 3 * H}},   # partial last period
    {"stop_time": 1.005},                                                   # short last tick
    {"stop_time": 0.995, "set": {"controller.sample_period": 4 * H}},  # both
    {"stop_time": 1.0, "record_every": 3},
    {"stop_time": 1.0, "start_time": 0.1},
    {"stop_time": 1.0, "step": 0.1 / 3, "set": {"controller.sample_period": 0.2 / 3}},  # no whole ns
], ids=["one-rate", "multi-rate", "partial-period", "short-tick", "partial-and-short", "record-every",
        "start-time", "float-times"])
def test_records_equal_the_python_loops(algorithm, case):
    kw = {"step": H, **case}
    c, py = both(loop_system(), loop_factory, algorithm=algorithm, **kw)
    assert c.ok and len(c.data) > 10
    assert_same(c, py)


def test_transfers_with_factor_and_offset_and_negative_zero():
    from ipcosim.harness.scenario.structure import Unit

    degc = Unit("degC", (0, 0, 0, 1, 0, 0, 0, 0), factor=1.0, offset=273.15)
    kelvin = Unit("K", (0, 0, 0, 1, 0, 0, 0, 0))
    mm = Unit("mm", (0, 1, 0, 0, 0, 0, 0, 0), factor=1e-3)
    m = Unit("m", (0, 1, 0, 0, 0, 0, 0, 0))
    src = model("Src", outputs=["temp", "len", "raw"], units={"temp": "degC", "len": "m"})
    dst = model("Dst", inputs=["temp", "len", "raw"], outputs=["v", "w"], units={"temp": "K", "len": "mm"},
                feedthrough={"v": ["temp", "len"], "w": ["raw"]})
    sysm = system([("a", src), ("b", dst)], [("a.temp", "b.temp"), ("a.len", "b.len"), ("a.raw", "b.raw")],
                  units={"degC": degc, "K": kelvin, "mm": mm, "m": m})
    assert {(lk.factor, lk.offset) for lk in sysm.links} == {(1.0, 273.15), (1000.0, 0.0), (1.0, 0.0)}

    def source(s):  # -0.0 passes an identity link as -0.0 (no "+ 0.0" where the link has no offset)
        t = len(s.steps)
        s["temp"], s["len"], s["raw"] = 0.1 * t - 3.0, -0.0 if t % 2 else 1e-3 * t, -0.0

    def sink(s):
        s["v"], s["w"] = s["temp"] + s["len"], s["raw"]

    c, py = both(sysm, lambda: Factory(a={"get_fn": source}, b={"get_fn": sink}), stop_time=0.5, step=H)
    assert c.ok
    assert_same(c, py)
    assert np.signbit(c["b.w"][1:]).all()  # the record's b.raw column is the source value + 0.0


def _failing_plant(status, at=0.5):
    def step(s, t, h):
        if t >= at - 1e-12:
            return status
        s["position"] = s["position"] + h * s["voltage"]
        return OK
    return step


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("status", [ERROR, DISCARD])
def test_a_failing_step_is_reported_the_same(algorithm, status):
    c, py = both(loop_system(), lambda: loop_factory(plant={"step_fn": _failing_plant(status)}),
                 algorithm=algorithm, stop_time=1.0, step=H)
    assert c.error and c.error.startswith("component plant (Plant): fmi2DoStep returned")
    assert_same(c, py)


def test_a_failing_get_and_a_python_exception_are_reported_the_same():
    def bad_get(s):
        if len(s.steps) == 7:
            raise RuntimeError("sensor cable unplugged")
    c, py = both(loop_system(), lambda: loop_factory(plant={"get_fn": bad_get}), stop_time=1.0, step=H)
    assert c.error == py.error and "sensor cable unplugged" in c.error
    assert_same(c, py)


def test_a_component_ending_the_simulation_ends_both_loops_alike():
    def stair(s, t, h):
        s["position"] = s["position"] + h * s["voltage"]
        if t >= 0.3 - 1e-12:
            s.terminate_requested = True
            return TERMINATE
        return OK
    c, py = both(loop_system(), lambda: loop_factory(plant={"step_fn": stair}), stop_time=1.0, step=H)
    assert c.ok and c.metadata["terminated_by"]["component"] == "plant"
    assert_same(c, py)


def test_python_slaves_run_on_the_python_loop_unless_c_is_forced():
    r = run(loop_system(), loop_factory, "auto", stop_time=0.1, step=H)
    assert r.metadata["loop"] == "python (components stepped by Python functions: setpoint, controller, plant)"


def test_without_a_compiler_the_run_completes_on_the_python_loop_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setenv("PATH", str(tmp_path))
    assert find_compiler() is None
    sysm, factory = loop_system(), loop_factory
    with pytest.raises(Exception, match=r"^--loop c: the C stepping loop cannot run: no C compiler$"):
        run(sysm, factory, "c", stop_time=0.1, step=H, raise_on_error=True)
    monkeypatch.setattr("ipcosim.harness.master.execution.python_functions", lambda blocks: [])  # all C, as it were
    r = run(sysm, factory, "auto", stop_time=0.1, step=H)
    assert r.ok and r.metadata["loop"] == "python (no C compiler)" and len(r.data) == 11


def test_a_failed_compile_runs_the_python_loop_and_says_why(tmp_path, monkeypatch):
    cc = tmp_path / "broken-cc"
    cc.write_text("#!/bin/sh\necho 'broken-cc: error: out of licences' >&2\nexit 1\n")
    cc.chmod(0o755)
    monkeypatch.setenv("CC", str(cc))
    monkeypatch.setattr("ipcosim.harness.support.paths.LOOP_DIR", tmp_path / "loops")
    monkeypatch.setattr("ipcosim.harness.master.execution.python_functions", lambda blocks: [])
    r = run(loop_system(), loop_factory, "auto", stop_time=0.1, step=H)
    assert r.ok and r.metadata["loop"] == "python (C compile failed: broken-cc: error: out of licences)"
    assert not list((tmp_path / "loops").iterdir())  # nothing left behind


def test_the_library_is_keyed_by_the_structure_alone(tmp_path, monkeypatch):
    monkeypatch.setattr("ipcosim.harness.support.paths.LOOP_DIR", tmp_path)
    runs = [({"stop_time": 1.0, "step": H}, "a"),
            ({"stop_time": 2.5, "step": 0.002, "start_time": 0.5, "set": {"controller.sample_period": 0.002}},
             "a"),
            ({"stop_time": 1.0, "step": H, "set": {"controller.k": 2.0}}, "a"),
            ({"stop_time": 1.0, "step": H, "set": {"controller.sample_period": 2 * H}}, "b")]
    seen = {}
    for kw, structure in runs:
        c, py = both(loop_system(), loop_factory, **kw)
        assert_same(c, py)
        seen.setdefault(structure, set()).update(p.name for p in tmp_path.glob("*.so"))
    assert len(seen["a"]) == 1 and len(seen["b"]) == 2  # a multiple of 2 is another structure
    assert not [p for p in tmp_path.iterdir() if p.suffix != ".so"]  # no temporary files left


def test_a_librarys_name_is_the_sha256_of_what_it_is_built_from_as_hashlib_computes_it(monkeypatch):
    import hashlib

    for text in ("", "int x;\0/usr/bin/cc\0x86_64\0-O2", "\u00e9\u4e2d" * 1000):
        assert cloop.sha256_hex(text) == hashlib.sha256(text.encode()).hexdigest()
    parts = ["int f(void) { return 1; }", "/bin/cc", "x86_64", *cloop.CFLAGS]
    monkeypatch.setattr(cloop, "find_compiler", lambda: "/bin/cc")
    monkeypatch.setattr(cloop.os.path, "realpath", lambda p: p)
    monkeypatch.setattr(cloop.platform, "machine", lambda: "x86_64")
    monkeypatch.setattr(cloop, "_compile", lambda *a: None)
    so = cloop.compiled(parts[0], cache=Path("/nonexistent-cache"))
    assert so.name == hashlib.sha256("\0".join(parts).encode()).hexdigest()[:20] + ".so"


def test_parallel_compiles_of_one_loop_each_end_with_a_whole_library(tmp_path):
    source = _source()
    code = ("import sys; from pathlib import Path; from ipcosim.harness.master import cloop; "
            "cloop.library(sys.stdin.read(), Path(sys.argv[1])); print('ok')")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(4)]
    outs = [p.communicate(source, timeout=120) for p in procs]
    assert all(p.returncode == 0 and out.strip() == "ok" for p, (out, _) in zip(procs, outs)), outs
    assert [p.suffix for p in tmp_path.iterdir()] == [".so"]
    assert cloop.library(source, tmp_path) is not None


def _source() -> str:
    """The C source of a multi-rate Jacobi loop with transfers (built without running it)."""
    from ipcosim.harness.master.algorithm import JACOBI, TimeBase
    from ipcosim.harness.master.plan import Block

    def block(i, n_out, n_in, m, transfers=()):
        return Block(index=i, name=f"b{i}", handle=None, do_step=None, get_real=None, set_real=None, out_vrs=None,
                     in_vrs=None, out_values=None, in_values=None, n_out=n_out, n_in=n_in, multiple=m,
                     transfers=transfers)
    blocks = [block(0, 2, 0, 1), block(1, 1, 2, 3, ((0, 0, 0, 2.0, 0.5), (1, 0, 1, 1.0, 0.0))),
              block(2, 0, 1, 1, ((0, 1, 0, 1.0, -1.0),))]
    return cloop.generate_c(blocks, [0, 1, 2], JACOBI, TimeBase.make(0.0, 1.0, 0.1))[0]


def test_the_generated_c_compiles_warning_free_as_c99(tmp_path):
    cc = find_compiler()
    for name in ("gcc", "clang"):
        path = shutil.which(name)
        if path is None and name != Path(cc).name:
            continue
        src = tmp_path / "loop.c"
        src.write_text(_source())
        proc = subprocess.run([path or cc, *cloop.CFLAGS, "-Werror", "-o", str(tmp_path / "loop.so"), str(src)],
                              capture_output=True, text=True)
        assert proc.returncode == 0 and not proc.stderr, proc.stderr


def test_the_loop_option_is_checked_where_the_command_line_checks_it():
    from ipcosim.errors import UsageError
    from ipcosim.harness.api.options import RunOptions

    assert RunOptions.create("single-mass-lqr", loop="c").loop == "c"
    with pytest.raises(UsageError, match=r"^--loop fast: expected one of auto, c, python$"):
        RunOptions.create("single-mass-lqr", loop="fast")
