"""The control laws as linear discrete-time systems: the builder their linear models are written with.

Each law module transcribes its law's per-sample arithmetic, line by line, into a linear state-space model
``x[k+1] = A x[k] + B y[k]``, ``u[k] = C x[k] + D y[k]`` from the measured positions ``y`` (the plant kind's
``MEASURED`` order) to the voltage ``u``, with the reference held at 0 (the loop is analysed about the upright
equilibrium); what is not linear is replaced by its linearization at rest and said so in the notes.

The transcription uses a tiny builder: every signal is a linear expression (a dict from a state or input to
its coefficient); ``state()`` declares a delay element and ``feed(state, expr)`` its next value. numpy is
imported only to realize the matrices, so the law modules stay importable with the standard library alone.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

from ipcosim.errors import IpcosimError

if TYPE_CHECKING:
    import numpy as np


class LinearizationError(IpcosimError, TypeError):
    """A law that has no linear model here (an unknown law class)."""


class Lin(dict):
    """A linear expression: ``{('x', i) or ('y', j): coefficient}``."""

    def __add__(self, other: "Lin") -> "Lin":
        out = Lin(self)
        for k, v in other.items():
            out[k] = out.get(k, 0.0) + v
        return out

    def __sub__(self, other: "Lin") -> "Lin":
        return self + other * -1.0

    def __mul__(self, c: float) -> "Lin":
        return Lin({k: v * float(c) for k, v in self.items()})

    __rmul__ = __mul__


def lsum(items: Sequence[Lin]) -> Lin:
    """Sum of linear expressions."""
    out = Lin()
    for it in items:
        out = out + it
    return out


class Builder:
    """Collects delay elements and their updates; ``realize`` gives (A, B, C, D)."""

    def __init__(self, n_inputs: int) -> None:
        self.n_inputs = n_inputs
        self.next: list[Lin | None] = []

    def input(self, j: int) -> Lin:
        """The j-th measurement."""
        return Lin({("y", j): 1.0})

    def state(self) -> Lin:
        """A new delay element (value at the previous sample, 0 at rest)."""
        self.next.append(None)
        return Lin({("x", len(self.next) - 1): 1.0})

    def feed(self, state: Lin, value: Lin) -> None:
        """Set the next value of a delay element created by ``state``."""
        (key,) = state.keys()
        self.next[key[1]] = value

    def derivative(self, y: Lin, T: float, tau: float) -> Lin:
        """``FilteredDerivative``: d[k] = (tau d[k-1] + y[k] - y[k-1]) / (tau + T)."""
        prev, dprev = self.state(), self.state()
        d = (dprev * tau + y - prev) * (1.0 / (tau + T))
        self.feed(prev, y)
        self.feed(dprev, d)
        return d

    def integral(self, e: Lin, T: float) -> Lin:
        """Running sum I[k] = I[k-1] + T e[k] (the value including this sample).

        Callers leave out an integral whose gain is 0: it would add a pole at z = 1 that nothing
        sees or drives.
        """
        prev = self.state()
        i = prev + e * T
        self.feed(prev, i)
        return i

    def _row(self, expr: Lin) -> tuple[np.ndarray, np.ndarray]:
        import numpy as np  # noqa: PLC0415 -- the analysis stack, imported only to analyse

        a, b = np.zeros(len(self.next)), np.zeros(self.n_inputs)
        for (kind, idx), v in expr.items():
            (a if kind == "x" else b)[idx] += v
        return a, b

    def realize(self, out: Lin) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """State-space matrices of the system whose output is ``out``."""
        import numpy as np  # noqa: PLC0415

        n = len(self.next)
        A, B = np.zeros((n, n)), np.zeros((n, self.n_inputs))
        for i, nxt in enumerate(self.next):
            if nxt is None:
                raise LinearizationError(f"delay element {i} has no update")
            A[i], B[i] = self._row(nxt)
        c, d = self._row(out)
        return A, B, c.reshape(1, n), d.reshape(1, self.n_inputs)


@dataclass(frozen=True)
class LinearLaw:
    """A law as ``x+ = A x + B y, u = C x + D y`` (sample period ``T``), and what was linearized."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    T: float
    inputs: tuple[str, ...]
    notes: tuple[str, ...]

    def simulate(self, ys: np.ndarray) -> np.ndarray:
        """Voltages for the measurement sequence ``ys`` (rows: samples), from rest."""
        import numpy as np  # noqa: PLC0415

        x = np.zeros(self.A.shape[0])
        out = np.empty(len(ys))
        for k, y in enumerate(np.asarray(ys, dtype=float)):
            out[k] = float((self.C @ x + self.D @ y)[0])
            x = self.A @ x + self.B @ y
        return out
