"""Floors of the master's stepping loops: the least a loop over the same FMUs can cost.

Both run a prepared scenario's FMUs (instantiated, parameters set and initialized through fmpy's
``FMU2Slave`` outside the timing) for the same ticks, components in the master's order and step
multiples, each input taken from the output it is linked to; no recording, no observers, no
status handling beyond stopping on an error:

* :func:`c_floor` -- a hand-written C loop (:data:`C_SOURCE`) calling the FMUs' ``fmi2SetReal``,
  ``fmi2DoStep`` and ``fmi2GetReal`` through their addresses: the floor of the master's C loop;
* :func:`python_floor` -- a plain Python loop calling the same three functions through ctypes on
  arrays allocated once: the floor of the master's Python loop.

Each returns the seconds of its stepping loop alone, to be read against ``loop_wall_time_s``.
"""
from __future__ import annotations

import ctypes
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

#: The C floor, in the calling convention of the master's compiled loops
#: (``harness/master/cloop.py``: ``p`` pointers, ``f`` functions, ``d`` doubles, ``q`` integers).
C_SOURCE = r"""
#include <stddef.h>
typedef int (*step_fn)(void *, double, double, int);
typedef int (*io_fn)(void *, const unsigned int *, size_t, double *);

/* per component i: p[6i..6i+5] = instance, output vrs, input vrs, output values, input values,
   input sources (double *[]); f[3i..3i+2] = doStep, getReal, setReal; q[0] = components,
   q[1 + 3i..] = outputs, inputs, step multiple; d[0] = step [s] */
int ipcosim_loop(void **p, void **f, double *d, long long *q, long long n0, long long n1, long long rb,
                 long long *fail) {
    long long nc = q[0], n, i, k;
    double h = d[0];
    (void)rb;
    for (n = n0; n < n1; n++) {
        for (i = 0; i < nc; i++) {
            long long no = q[1 + 3 * i], ni = q[2 + 3 * i], m = q[3 + 3 * i];
            double *iv = (double *)p[6 * i + 4];
            double **src = (double **)p[6 * i + 5];
            int s = 0;
            if ((n + 1) % m) continue;
            for (k = 0; k < ni; k++) iv[k] = *src[k];
            if (ni) s = ((io_fn)f[3 * i + 2])(p[6 * i], (const unsigned int *)p[6 * i + 2], (size_t)ni, iv);
            if (s <= 1) s = ((step_fn)f[3 * i])(p[6 * i], (double)(n + 1 - m) * h, (double)m * h, 1);
            if (s <= 1 && no)
                s = ((io_fn)f[3 * i + 1])(p[6 * i], (const unsigned int *)p[6 * i + 1], (size_t)no,
                                          (double *)p[6 * i + 3]);
            if (s > 1) { fail[0] = n; fail[1] = i; fail[3] = s; return 1; }
        }
    }
    return 0;
}
"""
#: The FMI functions both floors call (fmpy's raw ctypes functions, as the master calls them).
FUNCTIONS = ("fmi2DoStep", "fmi2GetReal", "fmi2SetReal")


class _Component:
    """One instance of the plan: its slave, value references and value arrays (allocated once)."""

    def __init__(self, slave: Any, out_vrs: list[int], in_vrs: list[int], multiple: int) -> None:
        self.slave, self.multiple = slave, multiple
        self.out_vrs = (ctypes.c_uint * len(out_vrs))(*out_vrs)
        self.in_vrs = (ctypes.c_uint * len(in_vrs))(*in_vrs)
        self.out_values = (ctypes.c_double * max(1, len(out_vrs)))()
        self.in_values = (ctypes.c_double * max(1, len(in_vrs)))()
        self.n_out, self.n_in = len(out_vrs), len(in_vrs)
        self.sources: list[tuple[int, int]] = []  # (component index, output index) per input


@contextmanager
def _plan(prepared: Any, stop: float, step: float) -> Iterator[tuple[list[_Component], int]]:
    """The prepared scenario's FMUs instantiated and initialized through fmpy, in the master's
    order; yields the components and the number of ticks, and frees the FMUs after."""
    from fmpy.fmi2 import FMU2Slave

    system = prepared.system
    execution = prepared.execution(stop_time=stop, step=step)  # the order and step multiples of the master
    order = [system.instances[i] for i in execution.order]
    comps: list[_Component] = []
    try:
        for inst in order:
            slave = FMU2Slave(guid=inst.model.guid, unzipDirectory=str(prepared.unzip_dirs[inst.name]),
                              modelIdentifier=inst.model.model_identifier, instanceName=inst.name)
            slave.instantiate()
            comps.append(_Component(slave, [v.vr for v in inst.outputs],
                                    [v.vr for v in inst.inputs if system.link_into(inst.name, v.name)],
                                    execution.multiples[inst.name]))
            _initialize(slave, inst, stop)
        names = [inst.name for inst in order]
        for comp, inst in zip(comps, order):
            for v in inst.inputs:
                link = system.link_into(inst.name, v.name)
                if link is not None:
                    src = system.instance(link.src)
                    comp.sources.append((names.index(link.src), [o.name for o in src.outputs].index(link.src_var.name)))
        for comp in comps:
            comp.slave.exitInitializationMode()
            if comp.n_out:
                comp.slave._functions["fmi2GetReal"](comp.slave.component, comp.out_vrs, comp.n_out, comp.out_values)
        yield comps, round(stop / step)
    finally:
        for comp in comps:
            comp.slave.terminate()
            comp.slave.freeInstance()


def _initialize(slave: Any, inst: Any, stop: float) -> None:
    slave.setupExperiment(startTime=0.0, stopTime=stop)
    reals = [(v.vr, x) for v, x in inst.parameters if v.type == "Real"]
    ints = [(v.vr, int(x)) for v, x in inst.parameters if v.type in ("Integer", "Enumeration")]
    if reals:
        slave.setReal([vr for vr, _ in reals], [x for _, x in reals])
    if ints:
        slave.setInteger([vr for vr, _ in ints], [x for _, x in ints])
    slave.enterInitializationMode()


def python_floor(prepared: Any, stop: float, step: float) -> float:
    """Seconds of the plain Python floor loop over ``prepared``'s FMUs (``stop`` at ``step``)."""
    with _plan(prepared, stop, step) as (comps, ticks):
        rows = [(*(c.slave._functions[name] for name in FUNCTIONS), c.slave.component, c.multiple,
                 c.out_vrs, c.n_out, c.out_values, c.in_vrs, c.n_in, c.in_values,
                 [(comps[i].out_values, j) for i, j in c.sources]) for c in comps]
        t0 = time.perf_counter()
        for n in range(ticks):
            for do_step, get, put, inst, m, ovr, no, ov, ivr, ni, iv, src in rows:
                if (n + 1) % m:
                    continue
                if ni:
                    for k, (values, j) in enumerate(src):
                        iv[k] = values[j]
                    if put(inst, ivr, ni, iv) > 1:
                        raise RuntimeError("python floor: fmi2SetReal failed")
                if do_step(inst, (n + 1 - m) * step, m * step, 1) > 1:
                    raise RuntimeError("python floor: fmi2DoStep failed")
                if no and get(inst, ovr, no, ov) > 1:
                    raise RuntimeError("python floor: fmi2GetReal failed")
        return time.perf_counter() - t0


def c_floor(prepared: Any, stop: float, step: float) -> float:
    """Seconds of the hand-written C floor loop over ``prepared``'s FMUs (``stop`` at ``step``)."""
    from ipcosim.harness.master.cloop import library

    fn = library(C_SOURCE, Path(tempfile.gettempdir()) / "ipcosim-bench-floor")
    with _plan(prepared, stop, step) as (comps, ticks):
        keep: list[Any] = []
        p: list[int | None] = []
        f: list[int | None] = []
        q = [len(comps)]
        for c in comps:
            sources = (ctypes.c_void_p * max(1, c.n_in))(
                *[ctypes.addressof(comps[i].out_values) + 8 * j for i, j in c.sources])
            keep.append(sources)
            p += [c.slave.component.value if hasattr(c.slave.component, "value") else c.slave.component] + [
                ctypes.addressof(a) for a in (c.out_vrs, c.in_vrs, c.out_values, c.in_values, sources)]
            f += [ctypes.cast(c.slave._functions[name], ctypes.c_void_p).value for name in FUNCTIONS]
            q += [c.n_out, c.n_in, c.multiple]
        pa, fa = (ctypes.c_void_p * len(p))(*p), (ctypes.c_void_p * len(f))(*f)
        da, qa, fail = (ctypes.c_double * 1)(step), (ctypes.c_longlong * len(q))(*q), (ctypes.c_longlong * 4)()
        t0 = time.perf_counter()
        status = fn(pa, fa, da, qa, 0, ticks, 0, fail)
        wall = time.perf_counter() - t0
    if status:
        raise RuntimeError(f"C floor: component {fail[1]} returned status {fail[3]} at tick {fail[0]}")
    return wall
