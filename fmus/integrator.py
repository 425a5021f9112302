"""Fixed-step exponential integrator for the stiff IP02 plants.

Why this method. The armature circuit gives the plant an electrical pole at
-Ra/La ~ -14 400 rad/s next to mechanical poles of at most ~20 rad/s. An explicit
Runge-Kutta method is stable only for h < 2.8/14 400 ~ 0.19 ms, so a 1 ms
communication step needs >= 6 RK4 sub-steps (24 right-hand-side calls), while an
implicit method needs Jacobians and Newton iterations. But the stiffness is entirely
*linear*: the circuit equation ``La i' = vA - Ra i - (N Kb/rg) v`` is linear, and the
mechanical nonlinearities (sin/cos, centripetal term) are slow. So we split

    x' = L x + n(x, u),   L = the circuit's part of df/dx at the upright equilibrium,   n = f - L x,

(L: the current's row and column of the Jacobian, ``ipcosim.fmus.plant.Plant``), integrate the
linear part exactly through matrix exponentials and the non-stiff
remainder ``n`` with the 4th-order exponential Runge-Kutta scheme of Cox and Matthews
(ETDRK4, J. Comput. Phys. 176, 2002). The matrix functions e^{hL}, phi_1, phi_2,
phi_3 are computed once per step size from one ``expm`` of an augmented block matrix
(Al-Mohy and Higham; no cancellation for the singular L of a free cart), in plain Python
(``ipcosim.fmus.expm``: the FMU runtime imports no numpy). Four
right-hand-side calls per step, one step per communication interval; the stage products are
compiled once per step size into straight-line Python without the zero coefficients. The accuracy
is measured against scipy's Radau at rtol 1e-10 (docs/plant.md, Integration).
"""
from __future__ import annotations

import functools
from typing import Any, Callable, Sequence

from ipcosim.fmus.expm import Matrix, as_matrix, expm, identity, lincomb, matmul, matvec


def phi_functions(M: Sequence[Sequence[float]], order: int = 3) -> list[Matrix]:
    """Return ``[e^M, phi_1(M), ..., phi_order(M)]`` for a square matrix ``M``.

    ``phi_k(z) = sum_j z^j / (j + k)!``, computed as the top block row of the exponential
    of the block matrix ``[[M, I, 0..], [0, 0, I, ..], ..., [0 ... 0]]``.
    """
    M = as_matrix(M)
    n = len(M)
    size = n * (order + 1)
    Z = [[0.0] * size for _ in range(size)]
    for i in range(n):
        Z[i][:n] = M[i]
    for k in range(order):
        for i in range(n):
            Z[k * n + i][(k + 1) * n + i] = 1.0
    top = expm(Z)[:n]
    return [[row[k * n:(k + 1) * n] for row in top] for k in range(order + 1)]


def _scaled(c: float, M: Matrix) -> Matrix:
    return [[c * v for v in row] for row in M]


class ETDRK4:
    """ETDRK4 stepper for ``x' = L x + n(x)`` with a fixed step ``h`` (the textbook form).

    Parameters
    ----------
    L : nested sequence (n x n)
        The stiff linear part.
    h : float
        Step size [s].
    """

    def __init__(self, L: Sequence[Sequence[float]], h: float) -> None:
        self.L = as_matrix(L)
        self.h = h = float(h)
        E, p1, p2, p3 = phi_functions(_scaled(h, self.L))
        Eh, q1 = phi_functions(_scaled(h / 2, self.L), order=1)
        self.E = E
        self.E2 = Eh
        self.P2 = _scaled(h / 2, q1)
        self.F1 = lincomb((h, p1), (-3 * h, p2), (4 * h, p3))
        self.F2 = lincomb((2 * h, p2), (-4 * h, p3))
        self.F3 = lincomb((4 * h, p3), (-h, p2))

    def step(self, x: Sequence[float], nonlinear: Callable[[list[float]], Sequence[float]]) -> list[float]:
        """Advance ``x`` by one step ``h``; returns the new state (a new list)."""
        x = [float(v) for v in x]
        E2x = matvec(self.E2, x)
        P2 = self.P2
        nx = list(nonlinear(x))
        a = [u + v for u, v in zip(E2x, matvec(P2, nx))]
        na = list(nonlinear(a))
        b = [u + v for u, v in zip(E2x, matvec(P2, na))]
        nb = list(nonlinear(b))
        c = [u + v for u, v in zip(matvec(self.E2, a), matvec(P2, [2.0 * p - q for p, q in zip(nb, nx)]))]
        nc = list(nonlinear(c))
        parts = (matvec(self.E, x), matvec(self.F1, nx), matvec(self.F2, [p + q for p, q in zip(na, nb)]),
                 matvec(self.F3, nc))
        return [sum(col) for col in zip(*parts)]


def etdrk4_f_form(L: Sequence[Sequence[float]], h: float) -> list[Matrix]:
    """ETDRK4 rewritten on the full right-hand side ``f = L x + n``: stage matrices.

    Every ETDRK4 stage (``a``, ``b``, ``c``) and the result are linear in the start value
    ``x`` and the right-hand sides ``f_x, f_a, f_b, f_c`` evaluated at the earlier stages
    (``n = f - L y``). Substituting once, here, gives matrices ``S_k`` with

        a   = S_0 @ [x, f_x]
        b   = S_1 @ [x, f_x, f_a]
        c   = S_2 @ [x, f_x, f_a, f_b]
        out = S_3 @ [x, f_x, f_a, f_b, f_c]

    which is the same scheme (equal up to rounding) with no ``L @ y`` products and four
    matrix-vector products per step instead of thirteen.

    Parameters
    ----------
    L : nested sequence (n x n)
        The stiff linear part.
    h : float
        Step size [s].

    Returns
    -------
    list of Matrix
        ``[S_0 (n x 2n), S_1 (n x 3n), S_2 (n x 4n), S_3 (n x 5n)]`` as lists of rows.
    """
    s = ETDRK4(L, h)
    L = s.L
    n = len(L)
    width = 5 * n
    eye = identity(n)

    def block(k: int) -> Matrix:  # selects f of stage k (0 = x itself, 1..4 = f_x..f_c)
        return [[0.0] * (k * n) + eye[i] + [0.0] * (width - (k + 1) * n) for i in range(n)]

    X, Fx, Fa, Fb, Fc = (block(k) for k in range(5))
    Nx = lincomb((1.0, Fx), (-1.0, matmul(L, X)))
    A = lincomb((1.0, matmul(s.E2, X)), (1.0, matmul(s.P2, Nx)))
    Na = lincomb((1.0, Fa), (-1.0, matmul(L, A)))
    B = lincomb((1.0, matmul(s.E2, X)), (1.0, matmul(s.P2, Na)))
    Nb = lincomb((1.0, Fb), (-1.0, matmul(L, B)))
    C = lincomb((1.0, matmul(s.E2, A)), (1.0, matmul(s.P2, lincomb((2.0, Nb), (-1.0, Nx)))))
    Nc = lincomb((1.0, Fc), (-1.0, matmul(L, C)))
    out = lincomb((1.0, matmul(s.E, X)), (1.0, matmul(s.F1, Nx)), (1.0, matmul(s.F2, lincomb((1.0, Na), (1.0, Nb)))),
                  (1.0, matmul(s.F3, Nc)))
    return [[row[:2 * n] for row in A], [row[:3 * n] for row in B], [row[:4 * n] for row in C], out]


class FastETDRK4:
    """ETDRK4 step on plain Python floats through the stage matrices of :func:`etdrk4_f_form`.

    The stage products are compiled once per (L, h) into one straight-line Python function (the
    coefficients as literals, exact zeros left out): plain-Python arithmetic without the per-row
    call overhead of a matrix-vector product, and no numpy. The start-value block of every stage
    matrix is the identity (a stationary point of ``f`` stays put: the scheme is exact for linear
    ``f``), so it is applied as ``x + ...`` instead of as a product, which also drops its rounding
    noise.

    Parameters
    ----------
    L : nested sequence (n x n)
        The stiff linear part (Jacobian of ``f`` at a reference point).
    h : float
        Step size [s].
    """

    def __init__(self, L: Sequence[Sequence[float]], h: float) -> None:
        self.h = float(h)
        self.n = len(L)
        self.S0, self.S1, self.S2, self.S3 = etdrk4_f_form(L, h)
        self._step = _compile_stages(self.n, (self.S0, self.S1, self.S2, self.S3))

    def step(self, x: Sequence[float], f: Callable[..., Sequence[float]], *args: float) -> list[float]:
        """Advance ``x`` by ``h`` for ``x' = f(*x, *args)``; returns the new state as a list."""
        return self._step(x, f, args)


def shared_etdrk4(L: Sequence[Sequence[float]], h: float) -> FastETDRK4:
    """The :class:`FastETDRK4` of ``(L, h)``, made once and shared by every caller with the same linear part and
    step (the same plant parameters): making one costs ~10 ms, most of a plant instance's set-up, and compiles
    its stages, whose local names the interpreter interns; a host instantiating an FMU again and again made it
    each time, and the names, interned again once the last stepper was collected, took new entries of the
    interpreter's interned-string table (0.34 an instantiation). It holds no state between steps. The
    :data:`SHARED_STEPPERS` most recently used are kept."""
    return _shared(tuple(tuple(float(v) for v in row) for row in L), float(h))


#: How many ``(L, h)`` steppers :func:`shared_etdrk4` keeps (a sweep over parameters makes a new one per set).
SHARED_STEPPERS = 16


@functools.lru_cache(maxsize=SHARED_STEPPERS)
def _shared(L: tuple[tuple[float, ...], ...], h: float) -> FastETDRK4:
    return FastETDRK4(L, h)


def _compile_stages(n: int, stages: Sequence[Matrix]) -> Callable[..., list[float]]:
    """Straight-line code for the four ETDRK4 stages of :class:`FastETDRK4`."""
    x = [f"x{i}" for i in range(n)]
    fs = [[f"f{k}_{i}" for i in range(n)] for k in range(4)]
    names = [f"a{i}" for i in range(n)], [f"b{i}" for i in range(n)], [f"c{i}" for i in range(n)], \
        [f"o{i}" for i in range(n)]
    lines = ["def _step(x, f, args):", f"    {', '.join(x)}, = x", f"    {', '.join(fs[0])}, = f(*x, *args)"]
    for k, S in enumerate(stages):
        for i, row in enumerate(S):
            terms = [x[i]]
            for j, c in enumerate(row[n:]):
                if c != 0.0:
                    terms.append(f"{c!r} * {fs[j // n][j % n]}")
            lines.append(f"    {names[k][i]} = {' + '.join(terms)}")
        if k < 3:
            lines.append(f"    {', '.join(fs[k + 1])}, = f({', '.join(names[k])}, *args)")
    lines.append(f"    return [{', '.join(names[3])}]")
    scope: dict[str, Any] = {}
    exec(compile("\n".join(lines), "<ipcosim ETDRK4 stages>", "exec"), scope)  # noqa: S102 -- generated above
    return scope["_step"]
