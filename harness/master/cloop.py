"""The stepping loop in C: the same plan as the Python loop (:func:`~ipcosim.harness.master.plan.loop_plan`),
compiled once per structure and called a chunk of ticks at a time.

The C source holds only the system's *structure*: which component steps when, its step
multiple, which inputs take which outputs and whether a transfer has a factor and an offset.
Everything that differs between runs of the same structure (instance handles, FMI functions,
value-reference and value arrays, step sizes, tick count, time base, record addresses,
factors and offsets) travels in four arrays filled from Python at run time, so one compiled
library serves every run, scenario and sweep worker with the same wiring. The library lives in
``loops/<hash>.so`` of the build folder (:data:`ipcosim.harness.support.paths.LOOP_DIR`), written
under a temporary name and renamed into place (parallel workers may compile the same one).

Calls, arguments, their order and the floating-point operations are those of the Python loop
(times from integer nanoseconds, transfers ``factor * x + offset`` only where the Python loop
has them, no contraction into fused multiply-adds), so the records are bit for bit the same.
The library is called through :class:`ctypes.CDLL`, which releases the GIL for the whole
chunk: FMU functions are called as the Python loop's ctypes calls call them (pythonfmu's FMUs
take the GIL in every FMI function). Functions of a slave that are Python callables (a
Python slave of the master's tests, the FMI 3.0 adapter) are called through ctypes
callbacks, which take the GIL; an exception there ends the chunk and is re-raised.

Not covered: Integer, Boolean and String connectors (the Python loop runs those systems).
"""
from __future__ import annotations

import ctypes
import os
import platform
import sys
import tempfile
import time as _time
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.harness.master.algorithm import TimeBase
from ipcosim.harness.master.plan import FUNCTIONS, Block, Op, loop_plan
from ipcosim.toolchain import find_compiler, run_compiler

#: Flags of the compile: C99, no fused multiply-add (the Python loop rounds every operation).
CFLAGS = ("-std=c99", "-O2", "-shared", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra", "-pedantic")
#: Status a Python callback returns when it raised (the exception is re-raised after the chunk).
RAISED = 1000
LOOPS = ("auto", "c", "python")

DoStepProto = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
GetSetProto = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                               ctypes.POINTER(ctypes.c_double))


class LoopUnavailable(IpcosimError, RuntimeError):
    """The C loop cannot run this system here (the reason is the message)."""


# --------------------------------------------------------------------------- C source
_HEAD = """/* ipcosim stepping loop (generated from the system's structure; see harness/master/cloop.py) */
#if defined(__linux__)
#define _POSIX_C_SOURCE 200809L
#endif
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#if defined(__linux__)
#include <time.h>

/* The host's monotonic clock [ns] (Python's time.monotonic_ns). */
static long long ipc_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* The pacer's wait (realtime.wait_until): sleep to spin ns before the deadline (an absolute sleep: a
   signal or an early wake-up sleeps again), then read the clock up to the deadline; returns the clock. */
static long long ipc_wait(long long deadline, long long spin)
{
    long long now = ipc_now();
    while (deadline - now > spin) {
        const long long at = deadline - spin;
        struct timespec ts;
        ts.tv_sec = (time_t)(at / 1000000000LL);
        ts.tv_nsec = (long)(at %% 1000000000LL);
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
        now = ipc_now();
    }
    while (now < deadline)
        now = ipc_now();
    return now;
}
#else
static long long ipc_now(void) { return 0; }
static long long ipc_wait(long long deadline, long long spin) { (void)spin; return deadline; }
#endif

typedef void (*ipc_fn)(void);
typedef int (*ipc_step)(void *, double, double, int);
typedef int (*ipc_get)(void *, const unsigned int *, size_t, double *);
typedef int (*ipc_set)(void *, const unsigned int *, size_t, const double *);

/* p: per block handle, out vrs, in vrs, outputs, inputs, private outputs; then the value vector
   f: per block fmi2DoStep, fmi2GetReal, fmi2SetReal
   d: start, step, per block h and hl, per transfer factor and offset
   q: N, exact (times from nanoseconds), start_ns, step_ns, record_every, row bytes; pacing (0: none),
      the deadline of tick 0 [ns], period [ns], spin [ns], and the addresses of each tick's start and end [ns]
   fail: tick, block, function (0 set, 1 step, 2 get), status */
int ipcosim_loop(void *const *p, const ipc_fn *f, const double *d, const long long *q,
                 long long n0, long long n1, long long rb, long long *fail)
{
    const long long N = q[0], exact = q[1], start_ns = q[2], step_ns = q[3], every = q[4], rs = q[5];
    const long long pace = q[6], t0 = q[7], period = q[8], spin = q[9];
    long long *const starts = (long long *)(intptr_t)q[10], *const ends = (long long *)(intptr_t)q[11];
    const double start = d[0], step = d[1];
    const void *va = p[%(va)d];
    long long n;
    int s;
%(decls)s
    (void)N;
    (void)s;
    (void)fail;
    for (n = n0; n < n1; n++) {
        const double t = exact ? (double)(start_ns + n * step_ns) / 1e9 : start + (double)n * step;
        (void)t;
        if (pace)
            starts[n - n0] = ipc_wait(t0 + n * period, spin);
%(body)s
        if (pace)
            ends[n - n0] = ipc_now();
        if ((n + 1) %% every == 0)
            memcpy((void *)(intptr_t)(rb + ((n + 1) / every) * rs), va, (size_t)rs);
    }
    return 0;
}
"""


class _CEmitter:
    """C lines of a loop plan; the transfers' factors and offsets are numbered into ``d``."""

    def __init__(self, blocks: Sequence[Block]) -> None:
        self.blocks = blocks
        self.lines: list[str] = []
        self.params: list[float] = []  # factors and offsets, in the order of the plan
        self.used: set[str] = set()

    def render(self, plan: Sequence[Op], indent: str) -> None:
        for op in plan:
            getattr(self, "op_" + op[0])(indent, *op[1:])

    def use(self, *names: str) -> None:
        self.used.update(names)

    def check(self, indent: str, i: int, call: str, function: str) -> None:
        code = FUNCTIONS.index(function)
        self.lines += [f"{indent}s = {call};",
                       f"{indent}if (s > 1) {{ fail[0] = n; fail[1] = {i}; fail[2] = {code}; fail[3] = s; return 1; }}"]

    def op_if(self, indent: str, cond: tuple, body: Sequence[Op]) -> None:
        if not body:
            return
        m = cond[1]
        # the last tick always closes a period: when the run is a whole number of periods it
        # is the end of one anyway, so the test does not depend on N (a run-time value)
        test = f"n % {m} == 0" if cond[0] == "start" else f"(n + 1) % {m} == 0 || n == N - 1"
        self.lines.append(f"{indent}if ({test}) {{")
        self.render(body, indent + "    ")
        self.lines.append(f"{indent}}}")

    def op_transfer(self, indent: str, i: int, k: int, src: int, j: int, factor: float, offset: float) -> None:
        expr = f"O{src}[{j}]"
        self.use(f"O{src}", f"I{i}")
        if factor != 1.0:
            expr = f"d[{self._param(factor)}] * {expr}"
        if offset != 0.0:
            expr = f"{expr} + d[{self._param(offset)}]"
        self.lines.append(f"{indent}I{i}[{k}] = {expr};")

    def _param(self, value: float) -> int:
        self.params.append(float(value))
        return 2 + 2 * len(self.blocks) + len(self.params) - 1

    def op_set(self, indent: str, i: int) -> None:
        self.use(f"c{i}", f"vi{i}", f"I{i}", f"sr{i}")
        self.check(indent, i, f"sr{i}(c{i}, vi{i}, {self.blocks[i].n_in}, I{i})", "fmi2SetReal")

    def op_step(self, indent: str, i: int, multiple: int | None, last: str, partial: bool) -> None:
        # h and hl are equal when the last period is whole: the choice does not depend on N
        start = "t"
        if multiple is not None:
            start = (f"(exact ? (double)(start_ns + (n / {multiple}) * {multiple} * step_ns) / 1e9 "
                     f": start + (double)((n / {multiple}) * {multiple}) * step)")
        tick = "N - 1" if last == "end" else f"((N - 1) / {self.blocks[i].multiple}) * {self.blocks[i].multiple}"
        self.use(f"c{i}", f"ds{i}", f"h{i}", f"hl{i}")
        self.check(indent, i, f"ds{i}(c{i}, {start}, n != {tick} ? h{i} : hl{i}, 1)", "fmi2DoStep")

    def op_get(self, indent: str, i: int, private: bool) -> None:
        target = f"{'P' if private else 'O'}{i}"
        self.use(f"c{i}", f"vo{i}", f"gr{i}", target)
        self.check(indent, i, f"gr{i}(c{i}, vo{i}, {self.blocks[i].n_out}, {target})", "fmi2GetReal")

    def op_publish(self, indent: str, i: int) -> None:
        self.use(f"O{i}", f"P{i}")
        self.lines.append(f"{indent}memcpy(O{i}, P{i}, {self.blocks[i].n_out} * sizeof(double));")

    def declarations(self) -> list[str]:
        """The locals the body uses, loaded from the run-time arrays."""
        out = []
        for b in self.blocks:
            i = b.index
            table = [(f"c{i}", f"void *c{i} = p[{6 * i}];"),
                     (f"vo{i}", f"const unsigned int *vo{i} = p[{6 * i + 1}];"),
                     (f"vi{i}", f"const unsigned int *vi{i} = p[{6 * i + 2}];"),
                     (f"O{i}", f"double *O{i} = p[{6 * i + 3}];"),
                     (f"I{i}", f"double *I{i} = p[{6 * i + 4}];"),
                     (f"P{i}", f"double *P{i} = p[{6 * i + 5}];"),
                     (f"ds{i}", f"ipc_step ds{i} = (ipc_step)f[{3 * i}];"),
                     (f"gr{i}", f"ipc_get gr{i} = (ipc_get)f[{3 * i + 1}];"),
                     (f"sr{i}", f"ipc_set sr{i} = (ipc_set)f[{3 * i + 2}];"),
                     (f"h{i}", f"const double h{i} = d[{2 + 2 * i}];"),
                     (f"hl{i}", f"const double hl{i} = d[{3 + 2 * i}];")]
            out += [f"    {decl}" for name, decl in table if name in self.used]
        return out


def generate_c(blocks: Sequence[Block], order: Sequence[int], algorithm: str,
               time: TimeBase) -> tuple[str, list[float]]:
    """C source of the stepping loop of a Real-only system, and the transfers' factors and
    offsets in the order the source reads them from ``d``.

    Raises
    ------
    LoopUnavailable
        If a component has Integer, Boolean or String connectors.
    """
    typed = [b.name for b in blocks if b.channels]
    if typed:
        raise LoopUnavailable(f"Integer/Boolean/String connectors ({', '.join(typed)})")
    em = _CEmitter(blocks)
    em.render(loop_plan(blocks, order, algorithm, time), " " * 8)
    source = _HEAD % {"va": 6 * len(blocks), "decls": "\n".join(em.declarations()), "body": "\n".join(em.lines)}
    return source, em.params


# --------------------------------------------------------------------------- compile and cache
_LOADED: dict[Path, Any] = {}


def library(source: str, cache: Path | None = None) -> Any:
    """The compiled loop of ``source`` (compiled on first use, then from the cache).

    Raises
    ------
    LoopUnavailable
        No C compiler, or the compile failed (its first error line).
    """
    so = compiled(source, cache)
    if so in _LOADED:
        return _LOADED[so]
    try:
        lib = ctypes.CDLL(str(so))
    except OSError as exc:
        raise LoopUnavailable(f"cannot load the compiled loop {so}: {exc}") from None
    fn = lib.ipcosim_loop
    vp = ctypes.POINTER(ctypes.c_void_p)
    fn.argtypes = [vp, vp, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_longlong), ctypes.c_longlong,
                   ctypes.c_longlong, ctypes.c_longlong, ctypes.POINTER(ctypes.c_longlong)]
    fn.restype = ctypes.c_int
    _LOADED[so] = fn
    return fn


def compiled(source: str, cache: Path | None = None) -> Path:
    """The shared library of the C ``source`` in the cache (``LOOP_DIR`` by default), compiled on first use.

    Raises
    ------
    LoopUnavailable
        No C compiler, or the compile failed (its first error line).
    """
    from ipcosim.harness.support.paths import LOOP_DIR

    cc = find_compiler()
    if cc is None:
        raise LoopUnavailable("no C compiler")
    parts = [source, os.path.realpath(cc), platform.machine(), *CFLAGS]
    key = sha256_hex("\0".join(parts))[:20]
    so = Path(cache or LOOP_DIR) / f"{key}.so"
    if not so.is_file():
        _compile(source, so, cc)
    return so


def sha256_hex(text: str) -> str:
    """The SHA-256 of ``text`` (UTF-8) in hex: by the interpreter's own implementation where it has one, as
    :mod:`random` takes its SHA-512 (importing :mod:`hashlib` loads OpenSSL: about 4 ms of every run's CPU), else by
    :mod:`hashlib`."""
    try:
        from _sha256 import sha256  # Python 3.11
    except ImportError:
        try:
            from _sha2 import sha256  # Python 3.12 and later
        except ImportError:
            from hashlib import sha256
    return sha256(text.encode()).hexdigest()


def _compile(source: str, so: Path, cc: str) -> None:
    """Compile to a temporary name beside ``so`` and rename it into place (atomic: parallel
    workers compiling the same loop each end with a whole library)."""
    try:
        so.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_c = tempfile.mkstemp(suffix=".c", prefix=so.stem + ".", dir=so.parent)
    except OSError as exc:
        raise LoopUnavailable(f"cannot write the loop cache {so.parent}: {exc.strerror}") from None
    tmp_so = tmp_c[:-2] + ".so.tmp"
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(source)
        proc = run_compiler([cc, *CFLAGS, "-o", tmp_so, tmp_c])
        if proc.returncode != 0:
            lines = [x for x in proc.stderr.splitlines() if "error" in x] or proc.stderr.splitlines()
            raise LoopUnavailable(f"C compile failed: {(lines or [f'exit status {proc.returncode}'])[0].strip()}")
        os.replace(tmp_so, so)
    except OSError as exc:
        raise LoopUnavailable(f"C compile failed: {exc}") from None
    finally:
        for leftover in (tmp_c, tmp_so):
            try:
                os.unlink(leftover)
            except OSError:
                pass


# --------------------------------------------------------------------------- binding
def _address(fn: Any) -> int | None:
    """The address of a ctypes foreign function, or None for a Python callable."""
    if isinstance(fn, ctypes._CFuncPtr):  # FMU functions as FMPy loads them
        return ctypes.cast(fn, ctypes.c_void_p).value
    return None


def python_functions(blocks: Sequence[Block]) -> list[str]:
    """Names of the components whose stepping functions are Python callables (called back
    from C: no gain over the Python loop)."""
    return [b.name for b in blocks if any(_address(fn) is None for fn in (b.do_step, b.get_real, b.set_real))]


class CLoop:
    """The C loop bound to one execution's blocks, with the Python loop's calling convention:
    ``run(n0, n1, rec_address, value_address, row_bytes, int_rec_address=0)`` -> None or
    ``(n, block index, function name, status)`` (see :func:`~ipcosim.harness.master.pyloop.generate_loop`)."""

    def __init__(self, blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase,
                 record_every: int, row_bytes: int, value_address: int, cache: Path | None = None) -> None:
        self.source, params = generate_c(blocks, order, algorithm, time)
        self._fn = library(self.source, cache)
        self._errors: list[BaseException] = []
        self._keep: list[Any] = []
        pointers: list[int | None] = []
        functions: list[int | None] = []
        for b in blocks:
            pointers += [_handle(b.handle)] + [ctypes.addressof(a) if a is not None else None for a in
                                               (b.out_vrs, b.in_vrs, b.out_values, b.in_values, b.private_out)]
            functions += [self._c_function(b.do_step, DoStepProto), self._c_function(b.get_real, GetSetProto),
                          self._c_function(b.set_real, GetSetProto)]
        pointers.append(value_address)
        self._p = (ctypes.c_void_p * len(pointers))(*pointers)
        self._f = (ctypes.c_void_p * len(functions))(*functions)
        doubles = [time.start, time.step]
        for b in blocks:
            doubles += [time.span(b.multiple), time.last_step(b.multiple)]
        self._d = (ctypes.c_double * (len(doubles) + len(params)))(*doubles, *params)
        exact = time.step_ns is not None
        self._q = (ctypes.c_longlong * 12)(time.ticks, int(exact), time.start_ns or 0, time.step_ns or 0,
                                           record_every, row_bytes)
        self._fail = (ctypes.c_longlong * 4)()
        self._row_bytes, self._value_address = row_bytes, value_address
        self._pacer: Any = None

    def pace(self, pacer: Any) -> bool:
        """Wait for each tick's deadline in the loop itself, as ``pacer`` would (a
        :class:`~ipcosim.harness.master.realtime.Pacer` on the host's monotonic clock and ``time.sleep``: the
        same deadlines, the same sleep then spin), and hand it each tick's start and end (``Pacer.took``), so
        that the ticks of a chunk run without Python in between; None: no more pacing. False where the loop
        has no absolute sleep (Linux only): the caller paces."""
        if pacer is None:
            self._q[6], self._pacer = 0, None
            return True
        if not sys.platform.startswith("linux"):
            return False
        self._q[6:10] = [1, pacer.deadline_ns(0), pacer.period_ns, pacer.spin_ns]
        self._pacer = pacer
        return True

    def _c_function(self, fn: Callable[..., int], proto: Any) -> int:
        address = _address(fn)
        if address is not None:
            return address
        errors = self._errors

        def call(*args: Any) -> int:
            try:
                return int(fn(*args))
            except BaseException as exc:  # noqa: BLE001 -- re-raised by run() after the C loop returns
                errors.append(exc)
                return RAISED

        callback = proto(call)
        self._keep.append(callback)
        return ctypes.cast(callback, ctypes.c_void_p).value

    def run(self, n0: int, n1: int, rb: int, va: int, rs: int, rbi: int = 0) -> tuple[int, int, str, int] | None:
        if va != self._value_address or rs != self._row_bytes:
            raise ValueError("the C loop was bound to another value vector or record layout")
        pacer, times = self._pacer, None
        if pacer is not None:
            times = (ctypes.c_longlong * (2 * (n1 - n0)))()
            self._q[10] = ctypes.addressof(times)
            self._q[11] = self._q[10] + ctypes.sizeof(ctypes.c_longlong) * (n1 - n0)
        failed = self._fn(self._p, self._f, self._d, self._q, n0, n1, rb, self._fail) != 0
        if times is not None:
            started = (int(self._fail[0]) + 1 if failed else n1) - n0
            ends = times[n1 - n0:n1 - n0 + started]
            if failed:      # the tick that failed ends now
                ends[-1] = _time.monotonic_ns()
            pacer.took(n0, times[:started], ends)
        if not failed:
            return None
        if self._errors:
            raise self._errors.pop(0)
        n, idx, code, status = (int(x) for x in self._fail)
        return n, idx, FUNCTIONS[code], status


def _handle(handle: Any) -> int | None:
    if handle is None or isinstance(handle, int):
        return handle
    if isinstance(handle, ctypes.c_void_p):
        return handle.value
    raise TypeError(f"instance handle {handle!r}: expected an address")
