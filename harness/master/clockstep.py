"""The Event Mode of a clocked FMU in C: one call per step instead of eight from Python.

:class:`~ipcosim.harness.master.clocked.ClockedSlave` hands the stepping loop three C functions
with the master's calling convention (``do_step(handle, t, h, flag)``, ``get_real`` and
``set_real(handle, vrs, n, values)``, :mod:`ipcosim.harness.master.slave`) over a :class:`Record` that
holds the FMU's functions and instance, its input clocks' ticks as integers (tick ``i`` of clock
``k`` is ``(first[k] + i every[k]) / scale[k]``, both below 2^53, so the division is the correctly
rounded time of the exact tick) and the clocked inputs and outputs. ``do_step`` runs ``fmi3DoStep``
and, when the step ends on a tick, the calls of :mod:`~ipcosim.harness.master.clocked` in their order.
The C loop (:mod:`ipcosim.harness.master.cloop`) can then call them directly.

Compiled on first use with the system's C compiler into the compiled loops' folder; without a
compiler, or for an FMU beyond :data:`MAX_CLOCKS` input clocks or :data:`MAX_VARS` clocked
variables, or with output clocks, the slave stays on its Python functions.
"""
from __future__ import annotations

import ctypes
import hashlib
from pathlib import Path
from typing import Any

MAX_CLOCKS = 8
MAX_VARS = 64
#: Which FMI function failed, by the code the C functions leave in ``Record.failed``.
FAILED = ("", "fmi3DoStep", "fmi3EnterEventMode", "fmi3SetClock", "fmi3SetFloat64", "fmi3GetFloat64",
          "fmi3UpdateDiscreteStates", "fmi3EnterStepMode", "fmi3UpdateDiscreteStates (did not converge)")

SOURCE = r"""
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#define MAXC %(clocks)d
#define MAXV %(vars)d
#define TERMINATE 16
typedef int (*DoStepF)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*ModeF)(void *);
typedef int (*SetClockF)(void *, const unsigned *, size_t, const bool *);
typedef int (*SetF)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*GetF)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*UpdateF)(void *, bool *, bool *, bool *, bool *, bool *, double *);
typedef struct {
    void *inst;
    DoStepF do_step; ModeF enter_event; ModeF enter_step; SetClockF set_clock; SetF set; GetF get; UpdateF update;
    int nclocks; unsigned clock_vr[MAXC]; long long first[MAXC], every[MAXC], scale[MAXC], ticks[MAXC];
    double next[MAXC], tol[MAXC];
    int nin; unsigned in_vr[MAXV]; unsigned in_mask[MAXV]; double pending[MAXV];
    int nout; unsigned out_vr[MAXV]; unsigned out_mask[MAXV]; double held[MAXV];
    int stepping; int failed; long long events;
} Record;

static int fail(Record *k, int code, int status) { k->failed = code; return status; }

int ipcosim_clocked_event(Record *k, double t, int entered) {
    unsigned mask = 0, vrs[MAXV];
    bool on[MAXC], need = true, term = false, b2 = false, b3 = false, defined = false;
    double values[MAXV], next_time = 0.0;
    int i, n, s, rounds;
    for (i = 0; i < k->nclocks; i++)
        if (fabs(t - k->next[i]) <= k->tol[i]) mask |= 1u << i;
    if (!mask && !entered) return 0;
    if (!entered && (s = k->enter_event(k->inst)) > 1) return fail(k, 2, s);
    if (mask) {
        for (i = n = 0; i < k->nclocks; i++)
            if (mask & (1u << i)) { vrs[n] = k->clock_vr[i]; on[n++] = true; }
        if ((s = k->set_clock(k->inst, vrs, (size_t)n, on)) > 1) return fail(k, 3, s);
        for (i = n = 0; i < k->nin; i++)
            if (k->in_mask[i] & mask) { vrs[n] = k->in_vr[i]; values[n++] = k->pending[i]; }
        if (n && (s = k->set(k->inst, vrs, (size_t)n, values, (size_t)n)) > 1) return fail(k, 4, s);
        for (i = n = 0; i < k->nout; i++)
            if (k->out_mask[i] & mask) vrs[n++] = k->out_vr[i];
        if (n && (s = k->get(k->inst, vrs, (size_t)n, values, (size_t)n)) > 1) return fail(k, 5, s);
        for (i = n = 0; i < k->nout; i++)
            if (k->out_mask[i] & mask) k->held[i] = values[n++];
    }
    for (rounds = 0; need; rounds++) {
        if (rounds == 100) return fail(k, 8, 3);
        if ((s = k->update(k->inst, &need, &term, &b2, &b3, &defined, &next_time)) > 1) return fail(k, 6, s);
        if (term) return TERMINATE;
    }
    for (i = 0; i < k->nclocks; i++)
        if (mask & (1u << i)) {
            k->ticks[i]++;
            k->next[i] = (double)(k->first[i] + k->ticks[i] * k->every[i]) / (double)k->scale[i];
        }
    k->events++;
    if ((s = k->enter_step(k->inst)) > 1) return fail(k, 7, s);
    k->stepping = 1;
    return 0;
}

int ipcosim_clocked_do_step(void *handle, double t, double h, int flag) {
    Record *k = (Record *)handle;
    bool ev = false, term = false, early = false;
    double last = 0.0;
    int s = k->do_step(k->inst, t, h, true, &ev, &term, &early, &last);
    (void)flag;
    if (s > 1) return fail(k, 1, s);
    if (term) return TERMINATE;
    return ipcosim_clocked_event(k, t + h, 0);
}

static int find(const unsigned *list, int n, unsigned vr) {
    int i;
    for (i = 0; i < n; i++)
        if (list[i] == vr) return i;
    return -1;
}

/* Between ticks the clocked outputs are those read at the last one; other variables go to the FMU. */
int ipcosim_clocked_get(void *handle, const unsigned *vrs, size_t n, double *out) {
    Record *k = (Record *)handle;
    size_t i;
    for (i = 0; i < n; i++) {
        int j = k->stepping ? find(k->out_vr, k->nout, vrs[i]) : -1;
        int s;
        if (j >= 0) { out[i] = k->held[j]; continue; }
        if ((s = k->get(k->inst, &vrs[i], 1, &out[i], 1)) > 1) return fail(k, 5, s);
    }
    return 0;
}

/* Clocked inputs wait for their clock's next tick (also set now in initialization); others go to the FMU. */
int ipcosim_clocked_set(void *handle, const unsigned *vrs, size_t n, const double *values) {
    Record *k = (Record *)handle;
    size_t i;
    for (i = 0; i < n; i++) {
        int j = find(k->in_vr, k->nin, vrs[i]);
        int s;
        if (j >= 0) k->pending[j] = values[i];
        if (j >= 0 && k->stepping) continue;
        if ((s = k->set(k->inst, &vrs[i], 1, &values[i], 1)) > 1) return fail(k, 4, s);
    }
    return 0;
}
"""


class Record(ctypes.Structure):
    """The C ``Record`` of :data:`SOURCE` (field for field)."""

    _fields_ = [("inst", ctypes.c_void_p), *[(n, ctypes.c_void_p) for n in (
        "do_step", "enter_event", "enter_step", "set_clock", "set", "get", "update")],
        ("nclocks", ctypes.c_int), ("clock_vr", ctypes.c_uint * MAX_CLOCKS),
        *[(n, ctypes.c_longlong * MAX_CLOCKS) for n in ("first", "every", "scale", "ticks")],
        ("next", ctypes.c_double * MAX_CLOCKS), ("tol", ctypes.c_double * MAX_CLOCKS),
        ("nin", ctypes.c_int), ("in_vr", ctypes.c_uint * MAX_VARS), ("in_mask", ctypes.c_uint * MAX_VARS),
        ("pending", ctypes.c_double * MAX_VARS),
        ("nout", ctypes.c_int), ("out_vr", ctypes.c_uint * MAX_VARS), ("out_mask", ctypes.c_uint * MAX_VARS),
        ("held", ctypes.c_double * MAX_VARS),
        ("stepping", ctypes.c_int), ("failed", ctypes.c_int), ("events", ctypes.c_longlong)]


_LIB: dict[str, Any] = {}


def functions() -> Any | None:
    """The compiled library (its four functions typed), or None without a C compiler."""
    from ipcosim.harness.master.cloop import CFLAGS, LoopUnavailable, _compile
    from ipcosim.harness.support.paths import LOOP_DIR
    from ipcosim.toolchain import find_compiler

    source = SOURCE % {"clocks": MAX_CLOCKS, "vars": MAX_VARS}
    cc = find_compiler()
    if cc is None:
        return None
    key = hashlib.sha256("\0".join([source, cc, *CFLAGS]).encode()).hexdigest()[:20]
    if key in _LIB:
        return _LIB[key]
    so = Path(LOOP_DIR) / f"clocked-{key}.so"
    try:
        if not so.is_file():
            _compile(source, so, cc)
        lib = ctypes.CDLL(str(so))
    except (LoopUnavailable, OSError):
        return None
    vp, u, d = ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_double)
    lib.ipcosim_clocked_do_step.argtypes = [vp, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    lib.ipcosim_clocked_event.argtypes = [ctypes.POINTER(Record), ctypes.c_double, ctypes.c_int]
    for name in ("ipcosim_clocked_get", "ipcosim_clocked_set"):
        getattr(lib, name).argtypes = [vp, u, ctypes.c_size_t, d]
    for name in ("ipcosim_clocked_do_step", "ipcosim_clocked_event", "ipcosim_clocked_get", "ipcosim_clocked_set"):
        getattr(lib, name).restype = ctypes.c_int
    _LIB[key] = lib
    return lib
