"""Dense matrix exponential and products on plain Python lists (no numpy), for the FMU runtime.

The plant integrator needs ``e^M`` of a block matrix of size 10..28 once per step size, and the
controllers' zero-order-hold discretization needs it for 2..7 states: small enough for plain
Python, so that an FMU on its default path imports only the standard library.

:func:`expm` is the scaling and squaring method with the degree-13 Pade approximant (Higham,
SIAM J. Matrix Anal. Appl. 26(4), 2005, Algorithm 2.3; the method behind ``scipy.linalg.expm``);
it agrees with scipy's to 1e-13 relative (docs/plant.md, Integration).
"""
from __future__ import annotations

import math
from operator import mul
from typing import Sequence

from ipcosim.errors import IpcosimError

Matrix = list[list[float]]

#: Pade-13 numerator coefficients b_0..b_13 and the 1-norm bound theta_13 (Higham 2005, Table 2.3).
_B13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
        10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152


class SingularMatrixError(IpcosimError, ArithmeticError):
    """A linear system without a unique solution (a zero pivot)."""


def as_matrix(a: Sequence[Sequence[float]]) -> Matrix:
    """A copy of ``a`` (any nested sequence, numpy arrays included) as a list of lists of floats."""
    return [[float(v) for v in row] for row in a]


def identity(n: int) -> Matrix:
    """The n x n identity."""
    return [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]


def matmul(a: Matrix, b: Matrix) -> Matrix:
    """``a @ b``."""
    cols = list(zip(*b))
    return [[sum(map(mul, row, col)) for col in cols] for row in a]


def matvec(a: Matrix, x: Sequence[float]) -> list[float]:
    """``a @ x``."""
    return [sum(map(mul, row, x)) for row in a]


def lincomb(*terms: tuple[float, Matrix]) -> Matrix:
    """``sum(c_k * M_k)`` of equally shaped matrices."""
    (c0, m0), rest = terms[0], terms[1:]
    out = [[c0 * v for v in row] for row in m0]
    for c, m in rest:
        for orow, mrow in zip(out, m):
            for j, v in enumerate(mrow):
                orow[j] += c * v
    return out


def solve(a: Matrix, b: Matrix) -> Matrix:
    """``X`` with ``a @ X = b`` (Gaussian elimination with partial pivoting).

    Raises
    ------
    SingularMatrixError
        If ``a`` is singular to working precision.
    """
    n = len(a)
    rows = [list(ra) + list(rb) for ra, rb in zip(a, b)]
    for k in range(n):
        p = max(range(k, n), key=lambda i: abs(rows[i][k]))
        if rows[p][k] == 0.0:
            raise SingularMatrixError("singular matrix in solve")
        rows[k], rows[p] = rows[p], rows[k]
        pivot = rows[k]
        inv = 1.0 / pivot[k]
        for i in range(k + 1, n):
            f = rows[i][k] * inv
            if f:
                rows[i] = [u - f * v for u, v in zip(rows[i], pivot)]
    m = len(rows[0]) - n
    x = [[0.0] * m for _ in range(n)]
    for i in range(n - 1, -1, -1):
        row = rows[i]
        acc = row[n:]
        for j in range(i + 1, n):
            c = row[j]
            if c:
                acc = [u - c * v for u, v in zip(acc, x[j])]
        x[i] = [u / row[i] for u in acc]
    return x


def norm1(a: Matrix) -> float:
    """The 1-norm (largest absolute column sum)."""
    return max(sum(abs(v) for v in col) for col in zip(*a))


def expm(a: Sequence[Sequence[float]]) -> Matrix:
    """``e^a`` by scaling and squaring with the degree-13 Pade approximant.

    Parameters
    ----------
    a : nested sequence of float (n x n)
        The matrix (finite entries).

    Returns
    -------
    list of list of float
        ``e^a``.
    """
    a = as_matrix(a)
    n = len(a)
    nrm = norm1(a) if n else 0.0
    if not math.isfinite(nrm):
        raise ValueError("expm: the matrix has a non-finite entry")
    s = max(0, math.ceil(math.log2(nrm / _THETA13))) if nrm > _THETA13 else 0
    if s:
        scale = 2.0 ** -s
        a = [[scale * v for v in row] for row in a]
    b = _B13
    eye = identity(n)
    a2 = matmul(a, a)
    a4 = matmul(a2, a2)
    a6 = matmul(a4, a2)
    u = matmul(a, lincomb((1.0, matmul(a6, lincomb((b[13], a6), (b[11], a4), (b[9], a2)))),
                          (b[7], a6), (b[5], a4), (b[3], a2), (b[1], eye)))
    v = lincomb((1.0, matmul(a6, lincomb((b[12], a6), (b[10], a4), (b[8], a2)))),
                (b[6], a6), (b[4], a4), (b[2], a2), (b[0], eye))
    r = solve(lincomb((1.0, v), (-1.0, u)), lincomb((1.0, v), (1.0, u)))
    for _ in range(s):
        r = matmul(r, r)
    return r
