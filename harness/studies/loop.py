"""The control laws of ``ipcosim.controllers.laws`` as linear discrete-time systems.

Each law's per-sample arithmetic is transcribed, line by line, into a linear state-space model
``x[k+1] = A x[k] + B y[k]``, ``u[k] = C x[k] + D y[k]`` from the measured positions ``y`` (the
plant kind's ``MEASURED`` order) to the voltage ``u``, with the reference held at 0 (the loop is
analysed about the upright equilibrium). What is not linear is replaced by its linearization at
rest, and said so in ``LinearLaw.notes``: the voltage limit is left out, HSMC's
``eta tanh(g S)`` becomes ``eta g S``, and the adaptive HSMC's schedules are frozen at their final
values (t -> infinity). ``tests/test_analyze.py`` checks each model against the law it
transcribes: both driven by the same small random measurements give the same voltages.

The transcription uses a tiny builder: every signal is a linear expression (a dict from a state or
input to its coefficient); ``state()`` declares a delay element and ``feed(state, expr)`` its next
value.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ipcosim.controllers.laws import HSMC, LQG, LQR, PID, AdaptiveHSMC, CascadePID, DiscreteLaw
from ipcosim.errors import IpcosimError


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
        a, b = np.zeros(len(self.next)), np.zeros(self.n_inputs)
        for (kind, idx), v in expr.items():
            (a if kind == "x" else b)[idx] += v
        return a, b

    def realize(self, out: Lin) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """State-space matrices of the system whose output is ``out``."""
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
        x = np.zeros(self.A.shape[0])
        out = np.empty(len(ys))
        for k, y in enumerate(np.asarray(ys, dtype=float)):
            out[k] = float((self.C @ x + self.D @ y)[0])
            x = self.A @ x + self.B @ y
        return out


def _pid(law: PID, b: Builder) -> tuple[Lin, list[str]]:
    g, T = law.gains, law.sample_period
    x = b.input(0)
    e = x * -1.0
    de = b.derivative(x, T, g.derivative_time_constant) * -1.0
    u = e * g.Kp + de * g.Kd
    return (u + b.integral(e, T) * g.Ki if g.Ki else u), []


def _cascade(law: CascadePID, b: Builder) -> tuple[Lin, list[str]]:
    g, T, tau = law.gains, law.sample_period, law.gains.derivative_time_constant
    n = len(law.measured)
    xm, xp, th = b.input(0), b.input(0 if n == 2 else 1), b.input(n - 1)
    vth, vxp, vxm = b.derivative(th, T, tau), b.derivative(xp, T, tau), b.derivative(xm, T, tau)
    a = xp * -g.Kp_x - vxp * g.Kd_x
    if g.Ki_x:
        a = a + b.integral(xm * -1.0, T) * g.Ki_x
    eth = th + a * (1.0 / 9.81)
    u = eth * -g.Kp_th - vth * g.Kd_th - vxm * g.Kv_m
    if g.Ki_th:
        u = u - b.integral(eth, T) * g.Ki_th
    notes = ["angle setpoint limit theta_ref_limit left out"]
    if g.reference_time_constant:
        notes.append(f"reference model (tau {g.reference_time_constant:g} s) and its feedforward act on the "
                     "reference only: not in the loop")
    return u, notes


def _lqr(law: LQR, b: Builder) -> tuple[Lin, list[str]]:
    d = law.design
    p, n = len(law.measured), d.Ad.shape[0]
    ys = [b.input(j) for j in range(p)]
    notes = []
    if law.filter is not None:
        # the law's filter as plain lists (the controllers' stdlib runtime): Ad (2 x 2), Bd (2), Cd (2)
        Af, Bf, Cf = (np.asarray(m, dtype=float) for m in law.filter)
        Bf, Cf = Bf.reshape(2), Cf.reshape(2)
        filtered = []
        for y in ys:
            xf = [b.state(), b.state()]
            filtered.append(lsum([xf[i] * Cf[i] for i in range(2)]))
            for i in range(2):
                b.feed(xf[i], lsum([xf[j] * Af[i, j] for j in range(2)]) + y * Bf[i])
        ys = filtered
        notes.append("output filters 1/(tau s + 1)^2 included")
    xp = [b.state() for _ in range(n)]
    C, M, K = d.model.C, d.M, d.K
    innov = [ys[j] - lsum([xp[i] * C[j, i] for i in range(n)]) for j in range(p)]
    xh = [xp[i] + lsum([innov[j] * M[i, j] for j in range(p)]) for i in range(n)]
    u = lsum([xh[i] * -K[0, i] for i in range(n)])
    for i in range(n):
        b.feed(xp[i], lsum([xh[j] * d.Ad[i, j] for j in range(n)]) + u * d.Bd[i, 0])
    return u, notes


def _lqg(law: LQG, b: Builder) -> tuple[Lin, list[str]]:
    d, T = law.coefficients, law.sample_period
    p, n = len(law.measured), len(d.states)
    ys = [b.input(j) for j in range(p)]
    xp, applied, integral = [b.state() for _ in range(n)], b.state(), b.state()
    innov = [ys[j] - lsum([xp[i] * d.C[j][i] for i in range(n)]) for j in range(p)]
    xh = [xp[i] + lsum([innov[j] * d.M[i][j] for j in range(p)]) for i in range(n)]
    free = [lsum([xh[j] * d.Ad[i][j] for j in range(n)]) + applied * d.Bd[i] for i in range(n)]
    g = law.friction_breakaway_gain
    forces = [((free[i] - xh[i]) * (g / col[i]), col, lead)  # the breakaway term's slope g at rest
              for i, f, col, lead in zip(d.friction_states, law.friction, d.friction_columns, d.friction_leads)
              if g and f > 0]
    u = lsum([xh[i] * -d.K[i] for i in range(n)]) - applied * d.K_voltage - integral * d.K_integral
    u = lsum([u] + [f * (d.volts_per_newton + sum(k * g for k, g in zip(d.K, lead))) for f, _, lead in forces])
    for i in range(n):
        b.feed(xp[i], lsum([free[i]] + [f * -col[i] for f, col, _ in forces]))
    b.feed(applied, u)
    b.feed(integral, integral - ys[0] * T)
    notes = ["output: the voltage computed a sample earlier (one-sample computation delay)",
             "reference lag left out (the reference is 0)"]
    if any(law.friction):
        notes.append(f"Coulomb friction compensation of a sliding cart left out (zero below "
                     f"{law.friction_velocity:g} m/s: no small-signal slope)"
                     + (f"; its breakaway term at rest kept (slope {g:g} on the demand)" if forces else ""))
    if law.integrator_dead_band:
        notes.append(f"integrator dead band of {law.integrator_dead_band:g} m left out")
    if law.dither_amplitude:
        notes.append(f"dither of {law.dither_amplitude:g} V at half the sample rate left out (an input, not feedback)")
    return applied, notes


def _hsmc(law: HSMC, b: Builder) -> tuple[Lin, list[str]]:
    g, T, tau = law.gains, law.sample_period, law.gains.derivative_time_constant
    c, k, eta, KI = law.current_gains()
    notes = [f"eta tanh(g S) linearized as eta g S (g = {g.tanh_gain:g})"]
    if isinstance(law, AdaptiveHSMC):
        sc = law.schedules
        c = tuple(s.base if s is not None else ci for s, ci in zip(sc.c or (None,) * len(c), law._c))
        k, eta, KI = ((getattr(sc, n).base if getattr(sc, n) is not None else getattr(g, n))
                      for n in ("k", "eta", "KI"))
        k1, KI1 = (getattr(sc, n).base if getattr(sc, n) is not None else 0.0 for n in ("k1", "KI1"))
        notes.append("schedules frozen at their final values (t -> infinity)")
    else:
        k1 = KI1 = 0.0
    if law.kind == "single-mass":
        xc, th = b.input(0), b.input(1)
        vth, vxc = b.derivative(th, T, tau), b.derivative(xc, T, tau)
        x, pos, vel = (xc, vxc, th, vth), (th, xc), (vth, vxc)
    else:
        xa, xc, th = b.input(0), b.input(1), b.input(2)
        vth, vxc, vxa = b.derivative(th, T, tau), b.derivative(xc, T, tau), b.derivative(xa, T, tau)
        x, pos, vel = (xa, vxa, xc, vxc, th, vth), (th, xc, xa), (vth, vxc, vxa)
    S = lsum([(p * ci + v) * a for a, ci, p, v in zip(law._alpha, c, pos, vel)])
    num = lsum([v * (a * ci) for a, ci, v in zip(law._alpha, c, vel)]) + lsum([xi * w for w, xi in zip(law._w, x)])
    total = num + S * (k + eta * g.tanh_gain)
    if KI:
        total = total + b.integral(S, T) * KI
    S1 = pos[0] * c[0] + vel[0]
    if k1:
        total = total + S1 * (law._alpha[0] * k1)
    if KI1:
        total = total + b.integral(S1, T) * (law._alpha[0] * KI1)
    u = total * (-law.force_gain / law._den) + vel[-1] * law.emf_gain
    if law.emf_gain or law.force_gain != 1.0:
        notes.append("law output is a force, applied through the motor model")
    return u, notes


def linear_law(law: DiscreteLaw) -> LinearLaw:
    """The law's linear model from the measurements to the voltage (reference 0, no limit).

    Parameters
    ----------
    law : DiscreteLaw
        A PID, CascadePID, LQR, LQG, HSMC or AdaptiveHSMC of ``ipcosim.controllers.laws``.

    Returns
    -------
    LinearLaw

    Raises
    ------
    LinearizationError
        For a law class without a transcription here.
    """
    for cls, fn in ((PID, _pid), (CascadePID, _cascade), (LQR, _lqr), (LQG, _lqg), (HSMC, _hsmc)):
        if isinstance(law, cls):
            b = Builder(len(law.measured))
            u, notes = fn(law, b)
            break
    else:
        raise LinearizationError(f"no linear model for the law {type(law).__name__}")
    A, B, C, D = b.realize(u)
    notes = ["voltage limit left out (small signals)"] + notes
    return LinearLaw(A, B, C, D, law.sample_period, tuple(law.measured), tuple(notes))
