"""The Real columns of ``results.csv`` formatted in C: the lines :func:`~ipcosim.harness.master.results.csv_text`
writes, byte for byte, at a fifteenth of its CPU time (12 columns of 10,001 rows: 5 ms against 80 ms).

The text is Python's ``"%.17g" % value`` on every platform (not the C library's ``printf``, whose ``%.17g``
differs in places: ``-nan``). A value of magnitude in [1e-16, 1e17), nearly every value a run records, is
formatted in exact integer arithmetic (``fast17``: ``|value| * 10**q`` for the ``q`` that gives 17 digits, as a
128-bit integer shifted right, rounded half to even as the interpreter's ``dtoa`` rounds, then laid out as
its ``'g'`` format lays out 17 digits). Every other value (zero, subnormal, huge, non-finite), and every
value where the compiler has no 128-bit integers, is formatted by the interpreter's own
``PyOS_double_to_string(value, 'g', 17, 0)``, the function ``"%.17g" % value`` calls, whose big-number
arithmetic (17 digits are past its fast path) takes six times as long. The rest C saves is the interpreter's
work around each call (one string object per value, the format string parsed again, the joins); a value
equal to the one above it in its column (a constant setpoint, a saturated voltage) is not formatted again.

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
#include <stdint.h>
#include <string.h>

char *PyOS_double_to_string(double val, char format_code, int precision, int flags, int *type);
void PyMem_Free(void *p);

#define FIELD 32 /* "%.17g" of a double: at most 24 characters */

#if defined(__SIZEOF_INT128__)
__extension__ typedef unsigned __int128 u128;

/* "%.17g" of x, as PyOS_double_to_string(x, 'g', 17, 0) writes it, where 1e-16 <= |x| < 1e17: the 17 digits
   D = |x| * 10^q rounded half to even, q = 16 - k, k the decimal exponent of |x|; with |x| = m 2^e (m of 53
   bits), |x| 10^q = m 5^q 2^(q + e) exactly, m 5^q < 2^128 for q <= 32. Returns the characters written to s,
   or 0 (nothing written) for any other x: zero, subnormal, non-finite, outside the range. */
static size_t fast17(double x, char *s)
{
    const uint64_t lo = 10000000000000000ULL, hi = 100000000000000000ULL;
    uint64_t bits, m, d = 0;
    int biased, e, k, q = 0, sh = 0, tries, n, decpt, i;
    u128 big = 0;
    char digits[17], *o = s;
    static u128 p5[33]; /* 5^0 .. 5^32, filled on the first call (the interpreter's lock held) */

    if (p5[0] == 0)
        for (i = 0, p5[0] = 1; i < 32; i++)
            p5[i + 1] = p5[i] * 5;
    memcpy(&bits, &x, sizeof bits);
    biased = (int)((bits >> 52) & 0x7ff);
    if (biased == 0 || biased == 0x7ff)
        return 0;
    m = (bits & ((1ULL << 52) - 1)) | (1ULL << 52);
    e = biased - 1075;
    /* k from the binary exponent, off by one at most: corrected below */
    k = biased >= 1023 ? ((biased - 1023) * 78913) >> 18 : -(((1023 - biased) * 78913 + 262143) >> 18);
    for (tries = 0; tries < 4; tries++) {
        q = 16 - k;
        sh = -(q + e);
        if (q < 0 || q > 32 || sh <= 0 || sh >= 128)
            return 0;
        big = (u128)m * p5[q];
        if ((big >> sh) >= hi) {
            k++;
        } else if ((big >> sh) < lo) {
            k--;
        } else {
            break;
        }
    }
    if (tries == 4)
        return 0;
    d = (uint64_t)(big >> sh);
    {
        const u128 rest = big & ((((u128)1) << sh) - 1), half = ((u128)1) << (sh - 1);
        if (rest > half || (rest == half && (d & 1)))
            d++;
    }
    if (d == hi) {
        d = lo;
        k++;
    }
    if (k > 16)
        return 0;
    for (i = 16; i >= 0; i--, d /= 10)
        digits[i] = (char)('0' + d % 10);
    for (n = 17; n > 1 && digits[n - 1] == '0'; n--)
        ;
    decpt = k + 1;
    if (bits >> 63)
        *o++ = '-';
    if (decpt <= -4) { /* d.ddde-XX */
        const int ex = 1 - decpt;
        *o++ = digits[0];
        if (n > 1) {
            *o++ = '.';
            memcpy(o, digits + 1, (size_t)(n - 1));
            o += n - 1;
        }
        *o++ = 'e';
        *o++ = '-';
        *o++ = (char)('0' + ex / 10);
        *o++ = (char)('0' + ex % 10);
    } else if (decpt <= 0) { /* 0.000ddd */
        *o++ = '0';
        *o++ = '.';
        for (i = 0; i < -decpt; i++)
            *o++ = '0';
        memcpy(o, digits, (size_t)n);
        o += n;
    } else if (decpt < n) { /* dd.ddd */
        memcpy(o, digits, (size_t)decpt);
        o += decpt;
        *o++ = '.';
        memcpy(o, digits + decpt, (size_t)(n - decpt));
        o += n - decpt;
    } else { /* ddd00 */
        memcpy(o, digits, (size_t)n);
        o += n;
        for (i = n; i < decpt; i++)
            *o++ = '0';
    }
    return (size_t)(o - s);
}
#else
static size_t fast17(double x, char *s)
{
    (void)x;
    (void)s;
    return 0;
}
#endif

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
                char *s;
                size_t k = fast17(x, text + c * FIELD);
                if (k > 0) {
                    len[c] = k;
                    last[c] = x;
                    continue;
                }
                s = PyOS_double_to_string(x, 'g', 17, 0, NULL);
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
