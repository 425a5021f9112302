"""The Real columns of ``results.csv`` formatted in C: the lines :func:`~ipcosim.harness.master.results.csv_text`
writes, byte for byte, at about half its CPU time.

Each value is formatted by the interpreter's own ``PyOS_double_to_string(value, 'g', 17, 0)``, the function
``"%.17g" % value`` calls, so the digits are Python's on every platform (not the C library's ``printf``,
whose ``%.17g`` differs in places: ``-nan``). What C saves is the interpreter's work around each call (one
string object per value, the format string parsed again, the joins); a value equal to the one above it in
its column (a constant setpoint, a saturated voltage) is not formatted again.

The library is compiled once, like the stepping loop (:func:`~ipcosim.harness.master.cloop.compiled`), and
loaded with :class:`ctypes.PyDLL` (the GIL held: the interpreter's allocator is called). Where it cannot be
built or loaded (no C compiler, an interpreter that does not export its functions), :func:`lines` returns
None and the caller formats in Python: the same bytes.
"""
from __future__ import annotations

import ctypes
from typing import Any, Sequence

import numpy as np

SOURCE = r"""/* ipcosim results.csv lines (see harness/master/cformat.py) */
#include <stddef.h>
#include <string.h>

char *PyOS_double_to_string(double val, char format_code, int precision, int flags, int *type);
void PyMem_Free(void *p);

#define FIELD 32 /* "%.17g" of a double: at most 24 characters */

/* rows x cols values (row-major); each line the fields pick[0..n), each "%.17g" of its column's value, comma
   separated, '\n' ended, written to out (rows * (n * 25 + 1) bytes at least). Returns the bytes written, or
   -1 when the interpreter could not format a value (out of memory). */
long long ipcosim_csv(const double *v, long long rows, long long cols, const long long *pick, long long n,
                      char *out, char *text, size_t *len, double *last)
{
    char *o = out;
    long long r, c, j;
    for (r = 0; r < rows; r++) {
        for (c = 0; c < cols; c++) {
            const double x = v[r * cols + c];
            if (r == 0 || memcmp(&x, &last[c], sizeof x) != 0) {
                char *s = PyOS_double_to_string(x, 'g', 17, 0, NULL);
                size_t k;
                if (s == NULL)
                    return -1;
                k = strlen(s);
                if (k >= FIELD) {
                    PyMem_Free(s);
                    return -1;
                }
                memcpy(text + c * FIELD, s, k);
                PyMem_Free(s);
                len[c] = k;
                last[c] = x;
            }
        }
        for (j = 0; j < n; j++) {
            memcpy(o, text + pick[j] * FIELD, len[pick[j]]);
            o += len[pick[j]];
            *o++ = j + 1 < n ? ',' : '\n';
        }
    }
    return (long long)(o - out);
}
"""
#: Bytes of one field at most: "%.17g" of a double (24 characters) and its separator.
FIELD_BYTES = 25
#: Bytes the library keeps for the text of one value (``FIELD`` in :data:`SOURCE`).
FIELD_CHARS = 32

_FUNCTION: list[Any] = []  # [the loaded function, or None when it cannot be had]


def _function() -> Any:
    """``ipcosim_csv`` of the compiled library, or None where it cannot be built or loaded."""
    if not _FUNCTION:
        from ipcosim.harness.master.cloop import LoopUnavailable, compiled

        try:
            fn = ctypes.PyDLL(str(compiled(SOURCE))).ipcosim_csv
        except (LoopUnavailable, OSError, AttributeError):
            fn = None
        if fn is not None:
            fn.argtypes = [ctypes.c_void_p, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_void_p, ctypes.c_longlong,
                           ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
            fn.restype = ctypes.c_longlong
        _FUNCTION.append(fn)
    return _FUNCTION[0]


def lines(columns: Sequence[np.ndarray]) -> bytearray | None:
    """The CSV lines of equally long float64 ``columns``, each value as ``"%.17g" % value``; None where the
    library is not available (the caller formats in Python).

    Parameters
    ----------
    columns : sequence of numpy.ndarray
        The columns in the order of the fields of a line (the same array may come more than once).
    """
    fn = _function()
    if fn is None or not columns:
        return None
    unique: dict[bytes, int] = {}
    firsts: list[np.ndarray] = []
    pick = []
    for col in columns:
        key = col.tobytes()
        if key not in unique:
            unique[key] = len(firsts)
            firsts.append(col)
        pick.append(unique[key])
    values = np.ascontiguousarray(np.column_stack(firsts), dtype=np.float64)
    rows, cols = values.shape
    picks = np.array(pick, dtype=np.longlong)
    out = bytearray(rows * (len(pick) * FIELD_BYTES + 1))
    text = bytearray(cols * FIELD_CHARS)
    length = np.zeros(cols, dtype=np.uintp)
    last = np.zeros(cols, dtype=np.float64)
    out_view, text_view = ctypes.c_char.from_buffer(out), ctypes.c_char.from_buffer(text)
    written = fn(values.ctypes.data, rows, cols, picks.ctypes.data, len(pick), ctypes.addressof(out_view),
                 ctypes.addressof(text_view), length.ctypes.data, last.ctypes.data)
    del out_view, text_view  # the buffers' exports, before the resize
    if written < 0:
        return None
    del out[written:]
    return out
