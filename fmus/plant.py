"""Stateful plant model: the one stepping object behind the plant FMUs and the virtual rig."""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable, Sequence

from ipcosim.fmus.instruments import Instruments, Readout, end_stop_state, tap_velocity_change
from ipcosim.fmus.integrator import FastETDRK4
from ipcosim.fmus.params import DoubleMassParams, PlantParams, SingleMassParams, kind_of, validate
from ipcosim.fmus.physics import (
    MEASURED,
    rhs_for,
    single_mass_momentum_rhs,
    single_mass_to_momentum,
    state_names,
)


class PlantStepError(FloatingPointError):
    """The plant state became non-finite during a step (reported with time and state)."""


def single_mass_internal_rhs(p: SingleMassParams) -> Callable[..., tuple[float, ...]]:
    """``f(xc, p1, th, p2, i, vA)``: ``ipcosim.fmus.physics.single_mass_momentum_rhs`` with the parameters folded
    into constants and the voltage already clipped (same arithmetic; checked equal in the tests)."""
    sin, cos, tanh = math.sin, math.cos, math.tanh
    ml = 0.5 * p.Mp * p.Lp
    m11 = p.Meq + p.Mp
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    mlg = ml * p.g
    kf, ke, beq, bp, ra, la = p.force_per_amp, p.emf_per_velocity, p.Beq, p.Bp, p.Ra, p.La
    b, cv = p.b, p.coulomb_velocity

    def f(xc: float, p1: float, th: float, p2: float, i: float, vA: float) -> tuple[float, ...]:
        s = sin(th)
        m12 = -ml * cos(th)
        det = m11 * m22 - m12 * m12
        xd = (m22 * p1 - m12 * p2) / det
        thd = (m11 * p2 - m12 * p1) / det
        fric = b * tanh(xd / cv) if b else 0.0
        return (xd, kf * i - beq * xd - fric, thd, mlg * s - bp * thd + ml * s * thd * xd,
                (vA - ra * i - ke * xd) / la)
    return f


def single_mass_output_map(p: SingleMassParams) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """``ipcosim.fmus.physics.single_mass_from_momentum`` with the parameters folded into constants
    (same arithmetic, so the same numbers)."""
    cos = math.cos
    ml = 0.5 * p.Mp * p.Lp
    m11 = p.Meq + p.Mp
    m22 = p.Mp * p.Lp * p.Lp / 3.0

    def out(z: Sequence[float]) -> tuple[float, ...]:
        xc, p1, th, p2, i = z
        m12 = -ml * cos(th)
        det = m11 * m22 - m12 * m12
        return (xc, (m22 * p1 - m12 * p2) / det, th, (m11 * p2 - m12 * p1) / det, i)
    return out


def double_mass_internal_rhs(p: DoubleMassParams) -> Callable[..., tuple[float, ...]]:
    """``f(xa, xa', xc, xc', th, th', i, vA)``: ``ipcosim.fmus.physics.double_mass_rhs`` with the parameters folded
    into constants and the voltage already clipped (same arithmetic; checked equal in the tests)."""
    sin, cos, tanh = math.sin, math.cos, math.tanh
    K, kf, ke, ra, la = p.K, p.force_per_amp, p.emf_per_velocity, p.Ra, p.La
    Ba, Bf, Bc, Bp, Ma_eq = p.Ba, p.Bf, p.Bc, p.Bp, p.Ma_eq
    b1, b2, cv = p.b1, p.b2, p.coulomb_velocity
    ml = 0.5 * p.Mp * p.Lp
    m11 = p.Mc + p.Mp
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    mlg = ml * p.g
    bfc = Bf + Bc

    def f(xa: float, xad: float, xc: float, xcd: float, th: float, thd: float, i: float,
          vA: float) -> tuple[float, ...]:
        spring = K * (xa - xc)
        fa = b1 * tanh(xad / cv) if b1 else 0.0
        fc = b2 * tanh(xcd / cv) if b2 else 0.0
        xadd = (kf * i - Ba * xad + Bf * xcd - spring - fa) / Ma_eq
        s = sin(th)
        m12 = -ml * cos(th)
        r1 = Bf * xad - bfc * xcd + spring - ml * thd * thd * s - fc
        r2 = mlg * s - Bp * thd
        det = m11 * m22 - m12 * m12
        return (xad, xadd, xcd, (m22 * r1 - m12 * r2) / det, thd, (m11 * r2 - m12 * r1) / det,
                (vA - ra * i - ke * xad) / la)
    return f


class Plant:
    """Nonlinear IP02 plant advanced in fixed steps with the voltage held over each step.

    The integrator is ETDRK4 (``ipcosim.fmus.integrator``) with the stiff linear part taken at the
    upright equilibrium -- the armature circuit's row and column of the Jacobian (:meth:`_circuit_part`)
    --, on an internal state in which the motor current enters the slow
    equations with constant coefficients: the momentum form ``[xc, p1, th, p2, i]`` for the
    single mass (``ipcosim.fmus.physics``), the plain state for the double mass (there the current
    drives only the active cart, whose mass matrix is constant).

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
        Physical parameters (validated on construction).
    x0 : sequence of float, optional
        Initial state in ``ipcosim.fmus.physics.state_names(kind)`` order; zeros by default.
    t0 : float
        Initial time [s].
    """

    def __init__(self, params: PlantParams, x0: Sequence[float] | None = None, t0: float = 0.0) -> None:
        self.params = validate(params)
        self.kind = kind_of(params)
        self.state_names = state_names(self.kind)
        self._rhs = rhs_for(params)
        if self.kind == "single-mass":
            self._irhs = single_mass_momentum_rhs
            self._to_int = single_mass_to_momentum
            self._f = single_mass_internal_rhs(params)
            self._out: Callable[[Sequence[float]], Sequence[float]] | None = single_mass_output_map(params)
        else:
            self._out = None
            self._irhs = self._rhs
            self._to_int = lambda x, p: tuple(x)
            self._f = double_mass_internal_rhs(params)
        self._L = self._circuit_part(self._internal_jacobian())
        self._steppers: dict[float, FastETDRK4] = {}
        self._limit = params.voltage_limit
        self.t = float(t0)
        self.voltage = 0.0
        self._xl: list[float] = [0.0] * len(self.state_names)
        self._z: list[float] = list(self._to_int(self._xl, params))
        if x0 is not None:
            self.set_state(x0)

    def set_state(self, x: Sequence[float]) -> None:
        """Replace the state vector (checked for length and finiteness)."""
        try:
            values = [float(v) for v in x]
        except (TypeError, ValueError):
            raise ValueError(f"{self.kind} state must be a sequence of numbers, got {x!r}") from None
        if len(values) != len(self.state_names):
            raise ValueError(f"{self.kind} state needs {len(self.state_names)} values "
                             f"({', '.join(self.state_names)}), got {len(values)}")
        bad = [f"{n} = {v}" for n, v in zip(self.state_names, values) if not math.isfinite(v)]
        if bad:
            raise ValueError(f"initial state is not finite: {', '.join(bad)}")
        self._xl = values
        self._z = list(self._to_int(self._xl, self.params))

    @property
    def x(self) -> Any:
        """The state as a numpy array (a copy; for analysis code -- the FMUs use :attr:`state`,
        which needs no numpy)."""
        import numpy as np  # noqa: PLC0415 -- off the FMU runtime's path

        return np.array(self._xl)

    def do_step(self, t: float, h: float, voltage: float) -> None:
        """Advance from time ``t`` to ``t + h`` with ``voltage`` [V] held constant.

        Raises
        ------
        PlantStepError
            If the new state is not finite; the state is left at its value at ``t``.
        ValueError
            If ``h`` is not a positive finite number or ``voltage`` is not finite.
        """
        stepper = self._steppers.get(h)
        if stepper is None:
            if not (h > 0 and math.isfinite(h)):
                raise ValueError(f"step size h = {h} s must be positive and finite")
            stepper = self._steppers[h] = FastETDRK4(self._L, h)
        if not math.isfinite(voltage):
            raise ValueError(f"input voltage = {voltage} V at t = {t} s is not finite")
        limit = self._limit
        vA = limit if voltage > limit else (-limit if voltage < -limit else voltage)
        try:
            z = stepper.step(self._z, self._f, vA)
            x = z if self._out is None else self._out(z)
            finite = all(map(math.isfinite, x))
        except (ValueError, OverflowError, ZeroDivisionError):  # math.sin(inf), float overflow, ...
            finite = False
        if not finite:
            state = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.state_names, self._xl))
            raise PlantStepError(f"plant state became non-finite in the step from t = {t:.6g} s "
                                 f"(h = {h:g} s, voltage = {voltage:g} V); state at t: {state}")
        self._z = z
        self._xl = list(x)
        self.voltage = voltage
        self.t = t + h

    @property
    def state(self) -> list[float]:
        """The state as a list of floats (a copy), ``state_names`` order."""
        return list(self._xl)

    def _internal_jacobian(self, eps: float = 1e-6) -> list[list[float]]:
        """Jacobian of the internal right-hand side at the upright equilibrium (the stiff linear part)."""
        n = len(self.state_names)
        cols = []
        for j in range(n):
            dz = [0.0] * n
            dz[j] = eps
            fp = self._irhs(dz, 0.0, self.params)
            dz[j] = -eps
            fm = self._irhs(dz, 0.0, self.params)
            cols.append([(a - b) / (2 * eps) for a, b in zip(fp, fm)])
        return [list(row) for row in zip(*cols)]

    @staticmethod
    def _circuit_part(J: list[list[float]]) -> list[list[float]]:
        """The stiff linear part: the motor current's row and column of the Jacobian ``J`` (current last).

        The only stiff mode is the armature circuit's (-Ra/La); the mechanical eigenvalues are
        below ~20 rad/s (h |lambda| <= 0.02 at 1 ms), which the scheme's explicit part (RK4 where
        L vanishes) integrates to ~1e-7 m / 1e-6 rad over 2 s (``tests/test_integrator.py``). This
        sparse L makes most stage coefficients exact zeros: a step costs a third of the
        arithmetic of the full Jacobian's.
        """
        last = len(J) - 1
        return [[v if j == last or i == last else 0.0 for j, v in enumerate(row)] for i, row in enumerate(J)]

    def values(self) -> dict[str, float]:
        """Every state by name (SI units)."""
        return dict(zip(self.state_names, self._xl))

    def measured(self) -> tuple[float, ...]:
        """The encoder-measured positions (``ipcosim.fmus.physics.MEASURED``)."""
        v = self.values()
        return tuple(v[n] for n in MEASURED[self.kind])


class InstrumentedPlant(Plant):
    """``Plant`` with the bench's instruments (``ipcosim.fmus.instruments``): encoder quantization and
    seeded noise on the measured positions (``readings``), and track end stops applied after each step.

    With ``Instruments()`` (the default, everything off) it behaves exactly as ``Plant`` and its
    readings are the true positions.
    """

    def __init__(self, params: PlantParams, x0: Sequence[float] | None = None, t0: float = 0.0,
                 instruments: Instruments | None = None) -> None:
        super().__init__(params, x0, t0)
        self.instruments = instruments or Instruments()
        names = self.state_names
        res = [self.instruments.pendulum_resolution if n == "pendulum_angle" else self.instruments.cart_resolution
               for n in MEASURED[self.kind]]
        self._readout = Readout(self.instruments, res)
        self._carts = [(names.index(n), names.index(n.replace("position", "velocity")))
                       for n in names if n.endswith("cart_position")]
        self.end_stop_hits = 0
        self.tapped = False
        self._delayed: list[float] = []
        self.readings = self._readout.read(self.measured())

    def _tap(self, t: float, h: float) -> None:
        inst = self.instruments
        if self.tapped or not (inst.tap_force_impulse or inst.tap_torque_impulse) or t + h <= inst.tap_time:
            return
        self.tapped = True
        p = self.params
        names = self.state_names
        cart = "cart" if self.kind == "single-mass" else "passive_cart"
        th = self._xl[names.index("pendulum_angle")]
        ml = 0.5 * p.Mp * p.Lp
        m11 = (p.Meq if self.kind == "single-mass" else p.Mc) + p.Mp
        dv, dw = tap_velocity_change((m11, -ml * math.cos(th), p.Mp * p.Lp * p.Lp / 3.0),
                                     inst.tap_force_impulse, inst.tap_torque_impulse)
        x = list(self._xl)
        x[names.index(f"{cart}_velocity")] += dv
        x[names.index("pendulum_velocity")] += dw
        self.set_state(x)

    def _delay(self, h: float, voltage: float) -> float:
        n = round(self.instruments.input_delay / h)
        if n <= 0:
            return voltage
        if not self._delayed:
            self._delayed = [0.0] * n
        self._delayed.append(voltage)
        return self._delayed.pop(0)

    def do_step(self, t: float, h: float, voltage: float) -> None:
        """``Plant.do_step`` with the delayed voltage and the taps, then the end stops and new readings."""
        self._tap(t, h)
        super().do_step(t, h, self._delay(h, voltage))
        stopped = end_stop_state(self._xl, self._carts, self.instruments.end_stop)
        if stopped is not None:
            self.set_state(stopped)
            self.end_stop_hits += 1
        self.readings = self._readout.read(self.measured())


def replay(params: PlantParams, voltages: Sequence[float], h: float, x0: Sequence[float] | None = None,
           instruments: Instruments | None = None) -> list[tuple[float, ...]]:
    """The measured positions (``MEASURED`` order, true values before the encoders) of the plant
    driven by a logged voltage: the one simulation behind identification.

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
    voltages : sequence of float
        The voltage [V] held over each step: ``voltages[k]`` from ``k h`` to ``(k + 1) h``.
    h : float
        Step [s].
    x0 : sequence of float, optional
        Initial state (``state_names`` order).
    instruments : Instruments, optional
        The bench between the command and the motion (input delay, end stops...); its encoder
        readout (resolutions, noise) is left out: the result is what the encoders look at.

    Returns
    -------
    list of tuple
        ``len(voltages) + 1`` rows: the start, then the positions after each step.
    """
    bench = replace(instruments or Instruments(), cart_resolution=0.0, pendulum_resolution=0.0, noise_counts=0.0)
    plant = InstrumentedPlant(params, x0, instruments=bench)
    rows = [plant.measured()]
    for k, v in enumerate(voltages):
        plant.do_step(k * h, h, v)
        rows.append(plant.measured())
    return rows
