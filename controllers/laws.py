"""Discrete control laws for the IP02 plants, pure Python (no FMI import).

Every law is a small class with explicit state:

* ``step(measurements, reference) -> voltage`` is called once per sample instant k T with the
  plant's measured positions (``ipcosim.fmus.physics.MEASURED[kind]`` order: cart position and pendulum
  angle for the single mass; active cart, passive cart and pendulum angle for the double mass)
  and the reference position of the motor-driven cart; it returns the voltage to hold until the
  next instant, already limited to ``+-voltage_limit``.
* ``reset()`` returns the law to its initial state (the first ``step`` initializes the velocity
  estimates from the first measurement, so the output at t = 0 is defined by the inputs at t = 0).
* ``sample_period`` [s] and ``voltage_limit`` [V] are attributes.

A law never reads a true velocity: velocities come from filtered differentiation
(``FilteredDerivative``) or from the LQR's observer. Laws with an integrator stop integrating
while the output is saturated in the direction the integrator pushes (conditional integration,
the clamping anti-windup).

Sign conventions (``ipcosim.fmus.physics``): a positive voltage pushes the motor cart towards +x; the
pendulum angle is counter-clockwise from upright, so pushing the cart towards +x makes the
angle grow, and the pendulum leans towards +x for a *negative* angle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from operator import mul
from typing import Any, Sequence

from ipcosim.controllers.errors import ControllerParameterError, DesignError
from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus.expm import Matrix, as_matrix, expm
from ipcosim.fmus.params import KINDS
from ipcosim.fmus.physics import MEASURED

G = 9.81


class LawParameterError(ControllerParameterError):
    """A control-law parameter is invalid; ``parameter`` names it."""


class LawInputError(IpcosimError, ValueError):
    """A measurement or reference handed to ``step`` is not a finite number."""


def _check_finite(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise LawParameterError(name, f"parameter {name} = {value!r} is not a number") from None
    if not math.isfinite(v):
        raise LawParameterError(name, f"parameter {name} = {v} is not finite")
    return v


def _check_nonneg(name: str, value: float) -> float:
    v = _check_finite(name, value)
    if v < 0:
        raise LawParameterError(name, f"parameter {name} = {v} must be >= 0")
    return v


def _check_positive(name: str, value: float) -> float:
    v = _check_finite(name, value)
    if v <= 0:
        raise LawParameterError(name, f"parameter {name} = {v} must be > 0")
    return v


def _check_kind(kind: str) -> str:
    if kind not in KINDS:
        raise LawParameterError("kind", f"unknown plant kind {kind!r}; {closest(kind, KINDS)}")
    return kind


def check_sample_period(sample_period: float, name: str = "sample_period") -> float:
    """A sample period must be a positive finite number of seconds (raises ``DesignError`` naming it)."""
    try:
        T = float(sample_period)
    except (TypeError, ValueError):
        raise DesignError(name, f"{name} = {sample_period!r} s is not a number") from None
    if not (math.isfinite(T) and T > 0):
        raise DesignError(name, f"{name} = {T} s must be positive and finite")
    return T


def zoh_lists(A: Sequence[Sequence[float]], B: Sequence[float], T: float) -> tuple[Matrix, list[float]]:
    """Exact zero-order-hold discretization ``(Ad, Bd)`` of ``x' = A x + B u`` (one input), in plain Python."""
    n = len(A)
    aug = [[float(a) * T for a in row] + [float(b) * T] for row, b in zip(A, B)] + [[0.0] * (n + 1)]
    E = expm(aug)
    return [row[:n] for row in E[:n]], [row[n] for row in E[:n]]


def output_filter_lists(time_constant: float, sample_period: float) -> tuple[Matrix, list[float], list[float]]:
    """Discrete ``1/(tau s + 1)^2`` filter (zero-order hold) as ``(Ad, Bd, Cd)`` of a 2-state system,
    state ``[y1, y2]`` with ``y1' = (u - y1)/tau``, ``y2' = (y1 - y2)/tau``, output ``y2``."""
    a = 1.0 / time_constant
    Ad, Bd = zoh_lists([[-a, 0.0], [a, -a]], [a, 0.0], sample_period)
    return Ad, Bd, [0.0, 1.0]


def rest_state(states: Sequence[str]) -> tuple[float, ...]:
    """The design state at rest per metre of reference: 1 for every cart position, 0 for the velocities
    and the pendulum angle (both carts stand at the reference, the pendulum upright)."""
    return tuple(1.0 if s.endswith("cart_position") else 0.0 for s in states)


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(map(mul, a, b))


def saturate(v: float, limit: float) -> float:
    """``v`` clipped to ``+-limit``."""
    return limit if v > limit else (-limit if v < -limit else v)


class FilteredDerivative:
    """Derivative with a first-order low-pass, ``s / (tau s + 1)``, discretized by backward Euler.

    ``d[k] = (tau d[k-1] + y[k] - y[k-1]) / (tau + T)``; ``tau = 0`` gives the backward difference.
    The first sample initializes ``y[k-1] = y[0]`` and ``d = 0`` (a plant at rest).
    """

    def __init__(self, sample_period: float, time_constant: float) -> None:
        self.T = sample_period
        self.tau = time_constant
        self.reset()

    def reset(self) -> None:
        """Forget the past samples."""
        self._prev: float | None = None
        self.value = 0.0

    def update(self, y: float) -> float:
        """Feed the sample of this instant; return the derivative estimate."""
        if self._prev is None:
            self._prev = y
            self.value = 0.0
            return 0.0
        self.value = (self.tau * self.value + (y - self._prev)) / (self.tau + self.T)
        self._prev = y
        return self.value


class DiscreteLaw:
    """Base of the control laws: sample period, voltage limit, measurement checking.

    Parameters
    ----------
    kind : {'single-mass', 'double-mass'}
        Plant the law controls (fixes the measurement order).
    sample_period : float
        T [s] > 0.
    voltage_limit : float
        Output limit [V] > 0 (10 V: the Q4 card's analog output range).
    """

    def __init__(self, kind: str, sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        self.kind = _check_kind(kind)
        try:
            self.sample_period = check_sample_period(sample_period)
        except DesignError as exc:
            raise LawParameterError("sample_period", str(exc)) from None
        self.voltage_limit = _check_positive("voltage_limit", voltage_limit)
        self.measured = MEASURED[kind]
        self.ticks = 0
        self.voltage = 0.0

    @property
    def time(self) -> float:
        """Time since the law started, ``ticks * sample_period`` [s] (integer ticks)."""
        return self.ticks * self.sample_period

    def reset(self) -> None:
        """Return to the initial state."""
        self.ticks = 0
        self.voltage = 0.0

    def _inputs(self, measurements: Sequence[float], reference: float) -> tuple[tuple[float, ...], float]:
        try:
            y = tuple(map(float, measurements))
        except (TypeError, ValueError):
            raise LawInputError(f"{type(self).__name__}: measurements must be numbers, got {measurements!r}") from None
        if len(y) != len(self.measured):
            raise LawInputError(f"{type(self).__name__}: expected {len(self.measured)} measurements "
                                f"({', '.join(self.measured)}), got {len(y)}")
        if not all(map(math.isfinite, y)):
            bad = [n for n, v in zip(self.measured, y) if not math.isfinite(v)]
            raise LawInputError(f"{type(self).__name__}: measurement {', '.join(bad)} is not finite "
                                f"at t = {self.time:.6g} s")
        r = float(reference)
        if not math.isfinite(r):
            raise LawInputError(f"{type(self).__name__}: reference = {r} m is not finite at t = {self.time:.6g} s")
        return y, r

    def step(self, measurements: Sequence[float], reference: float) -> float:
        """Compute the voltage for this sample instant (see the module docstring)."""
        y, r = self._inputs(measurements, reference)
        v = saturate(self._compute(y, r), self.voltage_limit)
        self.voltage = v
        self.ticks += 1
        return v

    def _compute(self, y: Sequence[float], r: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    # positions by meaning
    def _motor_cart(self, y: Sequence[float]) -> float:
        return float(y[0])

    def _pendulum_cart(self, y: Sequence[float]) -> float:
        return float(y[0] if self.kind == "single-mass" else y[1])

    def _angle(self, y: Sequence[float]) -> float:
        return float(y[-1])


# ============================================================================================ PID

@dataclass(frozen=True)
class PIDGains:
    """Thesis single-loop PID on the motor-cart position error (3.2.1, 4.2.1).

    ``u = Kp e + Ki int e dt + Kd de/dt``, ``e = r - x_motor``, derivative filtered by
    ``derivative_time_constant``.
    """

    Kp: float = 2.009e6        # V/m
    Ki: float = 1.512e8        # V/(m s)
    Kd: float = 6676.0         # V s/m
    derivative_time_constant: float = 1e-3  # s

    UNITS = {"Kp": "V/m", "Ki": "V/m.s", "Kd": "V.s/m", "derivative_time_constant": "s"}
    DOCS = {"Kp": "proportional gain on the motor-cart position error",
            "Ki": "integral gain on the motor-cart position error",
            "Kd": "derivative gain on the motor-cart position error",
            "derivative_time_constant": "time constant of the derivative's low-pass filter"}


class PID(DiscreteLaw):
    """Single-loop PID from the motor-cart position error to the voltage (the thesis's PID).

    It ignores the pendulum: on the thesis's own model the tuner's gains ask for kilovolts, and
    within the +-10 V limit the loop does not keep the pendulum up (``tests/test_controllers.py``).
    """

    def __init__(self, kind: str, gains: PIDGains = PIDGains(), sample_period: float = 1e-3,
                 voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        for f in fields(gains):
            _check_finite(f.name, getattr(gains, f.name))
        _check_nonneg("derivative_time_constant", gains.derivative_time_constant)
        self.gains = gains
        self._d = FilteredDerivative(self.sample_period, gains.derivative_time_constant)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.integral = 0.0
        self._d.reset()

    def _compute(self, y: Sequence[float], r: float) -> float:
        g = self.gains
        e = r - self._motor_cart(y)
        de = -self._d.update(self._motor_cart(y))  # derivative on the measurement: no kick at steps
        u_pd = g.Kp * e + g.Kd * de
        integral = self.integral + e * self.sample_period
        u = u_pd + g.Ki * integral
        # conditional integration: keep the new integral unless it deepens a saturation
        if abs(u) <= self.voltage_limit or (u > 0) != (g.Ki * e > 0):
            self.integral = integral
        else:
            u = u_pd + g.Ki * self.integral
        return u


# ==================================================================================== Cascade PID

@dataclass(frozen=True)
class CascadeGains:
    """Cascade PID: inner loop on the pendulum angle, outer loop on the cart position.

    Outer loop (cart position -> pendulum angle setpoint)::

        theta_ref = -(Kp_x e + Ki_x int e_m dt - Kd_x (x_p' - v_f) + a_f)/g,  clipped to +-theta_ref_limit
        e = r_f - x_p    (x_p: the cart carrying the pendulum -- the passive cart for the double mass)
        e_m = r_f - x_m  (x_m: the motor-driven cart)

    Inner loop (angle -> voltage)::

        u = -Kp_th (theta - theta_ref) - Ki_th int (theta - theta_ref) dt - Kd_th theta' - Kv_m (x_m' - v_f)

    A pendulum balanced at a constant angle theta makes its cart accelerate at -g theta, so the
    outer loop is a PD on the cart position acting through the acceleration -g theta_ref; the
    inner loop must be much faster than the outer one. Velocities are filtered differences.

    Reference model (the second degree of freedom): with ``reference_time_constant`` tau_r > 0 the
    loops track ``r_f``, the reference through ``1/(tau_r s + 1)^3`` (exact zero-order hold, started
    at rest at the measured position x_p), with its velocity ``v_f`` and acceleration ``a_f`` fed
    forward; a step then asks for a continuous acceleration, starting at 0.
    It acts on the reference only: the feedback from the measurements, hence every margin at the
    plant input, is the same for any tau_r, so a slow robust feedback loop can still follow a step
    at the reference model's speed. tau_r = 0 tracks the raw reference (``r_f = r``,
    ``v_f = a_f = 0``).
    """

    Kp_th: float = 30.0     # V/rad
    Ki_th: float = 0.0      # V/(rad s)
    Kd_th: float = 3.0      # V s/rad
    Kp_x: float = 4.0       # (m/s^2)/m
    Ki_x: float = 0.0       # (m/s^2)/(m s)
    Kd_x: float = 4.0       # (m/s^2)/(m/s)
    Kv_m: float = 0.0       # V s/m
    theta_ref_limit: float = 0.15   # rad
    derivative_time_constant: float = 0.005  # s
    reference_time_constant: float = 0.0  # s

    UNITS = {"Kp_th": "V/rad", "Ki_th": "V/rad.s", "Kd_th": "V.s/rad", "Kp_x": "1/s2", "Ki_x": "1/s3",
             "Kd_x": "1/s", "Kv_m": "V.s/m", "theta_ref_limit": "rad", "derivative_time_constant": "s",
             "reference_time_constant": "s"}
    DOCS = {"Kp_th": "inner loop: proportional gain on the angle error theta - theta_ref",
            "Ki_th": "inner loop: integral gain on the angle error",
            "Kd_th": "inner loop: derivative gain on the pendulum angle",
            "Kp_x": "outer loop: proportional gain, cart position error -> cart acceleration demand",
            "Ki_x": "outer loop: integral gain on the motor-cart position error",
            "Kd_x": "outer loop: derivative gain on the cart velocity",
            "Kv_m": "velocity damping of the motor-driven cart (voltage per velocity)",
            "theta_ref_limit": "limit of the angle setpoint produced by the outer loop",
            "derivative_time_constant": "time constant of the derivative low-pass filters",
            "reference_time_constant": "time constant of the reference model 1/(tau s + 1)^3 whose position, "
                                       "velocity and acceleration the loops track (0: the raw reference)"}


class CascadePID(DiscreteLaw):
    """Inner angle loop + outer cart-position loop (see ``CascadeGains``), anti-windup on both integrators."""

    def __init__(self, kind: str, gains: CascadeGains = CascadeGains(), sample_period: float = 1e-3,
                 voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        for f in fields(gains):
            _check_finite(f.name, getattr(gains, f.name))
        _check_positive("theta_ref_limit", gains.theta_ref_limit)
        _check_nonneg("derivative_time_constant", gains.derivative_time_constant)
        _check_nonneg("reference_time_constant", gains.reference_time_constant)
        self.gains = gains
        tau = gains.derivative_time_constant
        self._dth = FilteredDerivative(self.sample_period, tau)
        self._dxp = FilteredDerivative(self.sample_period, tau)
        self._dxm = FilteredDerivative(self.sample_period, tau)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.int_x = 0.0
        self.int_th = 0.0
        self.theta_ref = 0.0
        self.ref_states = [0.0, 0.0, 0.0]
        for d in (self._dth, self._dxp, self._dxm):
            d.reset()

    def _compute(self, y: Sequence[float], r: float) -> float:
        g, T = self.gains, self.sample_period
        xm, xp, th = self._motor_cart(y), self._pendulum_cart(y), self._angle(y)
        vth, vxp, vxm = self._dth.update(th), self._dxp.update(xp), self._dxm.update(xm)
        rf, vf, af = self._reference_model(r, xp)
        e, em = rf - xp, rf - xm
        int_x = self.int_x + em * T
        a_unsat = g.Kp_x * e + g.Ki_x * int_x - g.Kd_x * (vxp - vf) + af
        th_ref = saturate(-a_unsat / G, g.theta_ref_limit)
        outer_sat = abs(-a_unsat / G) > g.theta_ref_limit
        eth = th - th_ref
        int_th = self.int_th + eth * T
        u_unsat = -g.Kp_th * eth - g.Ki_th * int_th - g.Kd_th * vth - g.Kv_m * (vxm - vf)
        inner_sat = abs(u_unsat) > self.voltage_limit
        # conditional integration: an integrator is frozen while its loop saturates
        if not (outer_sat or inner_sat):
            self.int_x = int_x
        if not inner_sat:
            self.int_th = int_th
        self.theta_ref = th_ref
        return u_unsat

    def _reference_model(self, r: float, x0: float) -> tuple[float, float, float]:
        """``(r_f, v_f, a_f)`` of this instant (see ``CascadeGains``), then the model advanced one sample
        with ``r`` held; ``(r, 0, 0)`` when ``reference_time_constant`` is 0. The first sample starts
        the model at rest at ``x0``.

        The model is three first-order lags ``y1, y2, y3 = r_f`` of time constant tau in a row;
        relative to ``r`` one sample h advances them as ``e_i <- a sum_m (h/tau)^m / m! e_(i-m)``,
        ``a = exp(-h/tau)``."""
        tau, h = self.gains.reference_time_constant, self.sample_period
        if not tau > 0.0:
            return r, 0.0, 0.0
        if self.ticks == 0:
            self.ref_states = [x0, x0, x0]
        y1, y2, y3 = self.ref_states
        vf, af = (y2 - y3) / tau, (y1 - 2.0 * y2 + y3) / (tau * tau)
        a, q = math.exp(-h / tau), h / tau
        e1, e2, e3 = y1 - r, y2 - r, y3 - r
        self.ref_states = [r + a * e1, r + a * (e2 + q * e1), r + a * (e3 + q * e2 + 0.5 * q * q * e1)]
        return y3, vf, af


# ============================================================================================ LQR

@dataclass(frozen=True)
class LQRCoefficients:
    """Everything the LQR law computes with, as plain floats (design-model state order).

    ``K`` (n), ``N``: the feedback ``u = -K x^ + N r``; ``M`` (n x p): the current-estimator gain;
    ``Ad`` (n x n), ``Bd`` (n): the zero-order-hold model for ``sample_period``; ``C`` (p x n): the
    measured rows. Made from an ``ipcosim.controllers.design.LQRDesign`` (:meth:`from_design`) or
    from gains stored in a controller FMU (no numpy needed).
    """

    states: tuple[str, ...]
    outputs: tuple[str, ...]
    sample_period: float
    K: tuple[float, ...]
    N: float
    M: tuple[tuple[float, ...], ...]
    Ad: tuple[tuple[float, ...], ...]
    Bd: tuple[float, ...]
    C: tuple[tuple[float, ...], ...]

    @classmethod
    def from_design(cls, design: Any) -> LQRCoefficients:
        """The coefficients of an ``LQRDesign`` (numpy arrays become tuples of floats)."""
        def rows(m: Any) -> tuple[tuple[float, ...], ...]:
            return tuple(tuple(float(v) for v in row) for row in as_matrix(m))
        return cls(states=tuple(design.model.states), outputs=tuple(design.model.outputs),
                   sample_period=float(design.sample_period), K=rows(design.K)[0], N=float(design.N),
                   M=rows(design.M), Ad=rows(design.Ad), Bd=tuple(r[0] for r in rows(design.Bd)),
                   C=rows(design.model.C))


def _right_inverse(C: Sequence[Sequence[float]]) -> Matrix:
    """``C' (C C')^-1`` (the pseudo-inverse of a full-row-rank C; ``C'`` itself for selection rows)."""
    from ipcosim.fmus.expm import matmul, solve  # noqa: PLC0415

    Ct = [list(col) for col in zip(*C)]
    return [list(r) for r in zip(*solve(matmul(as_matrix(C), Ct), [list(r) for r in zip(*Ct)]))]


class CurrentEstimatorLaw(DiscreteLaw):
    """Base of the laws on a discrete current estimator (``coefficients`` with ``C``, ``M``, ``states``):
    ``x^[k] = x-[k] + M (y[k] - C x-[k])``, the first prediction the plant at rest at the measured
    positions. Subclasses predict ``x_pred`` for the next instant."""

    coefficients: Any
    _Cpinv: Matrix

    def reset(self) -> None:
        super().reset()
        self.x_pred: list[float] | None = None
        self.x_hat = [0.0] * len(self.coefficients.states)

    def _correct(self, y: Sequence[float]) -> list[float]:
        """The corrected estimate ``x^`` of this instant (also kept as ``x_hat``)."""
        d = self.coefficients
        xp = self.x_pred
        if xp is None:  # plant assumed at rest at the measured positions
            xp = [sum(map(mul, row, y)) for row in self._Cpinv]
        innovation = [v - sum(map(mul, row, xp)) for v, row in zip(y, d.C)]
        self.x_hat = x_hat = [a + sum(map(mul, row, innovation)) for a, row in zip(xp, d.M)]
        return x_hat


class LQR(CurrentEstimatorLaw):
    """LQR state feedback on a discrete current estimator, ``u = sat(-K x^ + N r)``
    (see ``ipcosim.controllers.design``).

    Parameters
    ----------
    kind : str
        Plant kind.
    design : LQRDesign or LQRCoefficients
        From ``ipcosim.controllers.design.design_lqr`` (its ``sample_period`` is the law's), or the
        plain coefficients (what a controller FMU runs on).
    voltage_limit : float
        [V].
    output_filter_time_constant : float
        If > 0, each measured position passes through ``1/(tau s + 1)^2`` (zero-order-hold
        discretized) before the estimator: the thesis's double-mass filters, tau = 0.0008 s.
    """

    def __init__(self, kind: str, design: Any, voltage_limit: float = 10.0,
                 output_filter_time_constant: float = 0.0) -> None:
        coef = design if isinstance(design, LQRCoefficients) else LQRCoefficients.from_design(design)
        super().__init__(kind, coef.sample_period, voltage_limit)
        if coef.outputs != tuple(self.measured):
            raise LawParameterError("design", f"LQR design is for outputs {coef.outputs}, the "
                                              f"{kind} plant measures {self.measured}")
        self.design = design
        self.coefficients = coef
        tau = _check_nonneg("output_filter_time_constant", output_filter_time_constant)
        self.filter = output_filter_lists(tau, self.sample_period) if tau > 0 else None
        self._Cpinv = _right_inverse(coef.C)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self._filt: list[list[float]] | None = None

    def _filter(self, y: Sequence[float]) -> Sequence[float]:
        if self.filter is None:
            return y
        Ad, Bd, Cd = self.filter
        if self._filt is None:  # start at rest at the first measurement
            self._filt = [[v, v] for v in y]
        out = [_dot(s, Cd) for s in self._filt]
        self._filt = [[_dot(Ad[0], s) + Bd[0] * v, _dot(Ad[1], s) + Bd[1] * v] for s, v in zip(self._filt, y)]
        return out

    def _compute(self, y: Sequence[float], r: float) -> float:
        d = self.coefficients
        x_hat = self._correct(self._filter(y))
        u = d.N * r - sum(map(mul, d.K, x_hat))
        limit = self.voltage_limit
        u_applied = limit if u > limit else (-limit if u < -limit else u)
        self.x_pred = [sum(map(mul, row, x_hat)) + b * u_applied for row, b in zip(d.Ad, d.Bd)]
        return u


# ============================================================================================ LQG

@dataclass(frozen=True)
class LQGCoefficients:
    """Everything the LQG law computes with, as plain floats (design-model state order).

    ``K`` (n), ``K_voltage``, ``K_integral``: the feedback ``u = -K (x^ - x_r r) - K_voltage v -
    K_integral q`` (``ipcosim.controllers.lqg``); ``M`` (n x p): the Kalman current-estimator gain;
    ``Ad`` (n x n), ``Bd`` (n): the zero-order-hold model; ``C`` (p x n): the measured rows;
    ``reference_states`` (n): ``x_r``. The Coulomb friction model of each cart (``coulomb_model``; empty:
    none): ``friction_states`` the index of its velocity state, ``friction_columns`` (n) what a force of
    1 N on it held over a sample adds to the state, ``friction_leads`` (n) the state offset per newton at
    which the loop holds that force (the spring's deflection for the passive cart), ``volts_per_newton``
    the motor voltage of 1 N at standstill.
    """

    states: tuple[str, ...]
    outputs: tuple[str, ...]
    sample_period: float
    K: tuple[float, ...]
    K_voltage: float
    K_integral: float
    M: tuple[tuple[float, ...], ...]
    Ad: tuple[tuple[float, ...], ...]
    Bd: tuple[float, ...]
    C: tuple[tuple[float, ...], ...]
    reference_states: tuple[float, ...]
    friction_states: tuple[int, ...] = ()
    friction_columns: tuple[tuple[float, ...], ...] = ()
    friction_leads: tuple[tuple[float, ...], ...] = ()
    volts_per_newton: float = 0.0

    @classmethod
    def from_design(cls, design: Any) -> LQGCoefficients:
        """The coefficients of an ``ipcosim.controllers.lqg.LQGDesign``."""
        def rows(m: Any) -> tuple[tuple[float, ...], ...]:
            return tuple(tuple(float(v) for v in row) for row in as_matrix(m))
        n = len(design.model.states)
        ka = rows(design.K_augmented)[0]
        return cls(states=tuple(design.model.states), outputs=tuple(design.model.outputs),
                   sample_period=float(design.sample_period), K=ka[:n], K_voltage=ka[n], K_integral=ka[n + 1],
                   M=rows(design.M), Ad=rows(design.Ad), Bd=tuple(r[0] for r in rows(design.Bd)),
                   C=rows(design.model.C), reference_states=tuple(map(float, design.reference_states)))


def coulomb_estimate(v: float, b: float, threshold: float, demand: float = 0.0, gain: float = 0.0) -> float:
    """The Coulomb force [N] the LQG compensates on a cart of estimated velocity ``v`` [m/s]: 0 for
    ``|v| <= threshold``, ``b sign(v)`` for ``|v| >= 2 threshold``, linear in between (no compensation of a
    cart at rest, whose velocity estimate is noise, and no slope at small signals).

    With a breakaway ``gain`` g > 0, the share of ``b`` the velocity leaves uncompensated goes to a cart near
    rest in the direction the loop pushes it: ``(1 - w) clip(g demand, -b, b)``, ``demand`` [N] the net force
    the frictionless model puts on the cart, ``w`` the sliding share above (slope g at small signals; the
    clip written with ``abs``, which has no branch)."""
    a = abs(v) / threshold - 1.0
    w = 0.0 if a <= 0.0 else (1.0 if a >= 1.0 else a)
    sliding = b * w if v > 0.0 else -b * w
    push = gain * demand
    return sliding + (1.0 - w) * 0.5 * (abs(push + b) - abs(push - b))


def dead_zone(e: float, band: float) -> float:
    """``e`` less the band ``+-band`` (0 inside it)."""
    return e - band if e > band else (e + band if e < -band else 0.0)


class LQG(CurrentEstimatorLaw):
    """Discrete LQG with integral action and a one-sample computation delay (``ipcosim.controllers.lqg``).

    At instant k the law outputs the voltage ``v[k]`` it computed at instant k - 1 (0 V at the first
    instant), corrects its estimate with the measurements of instant k, and computes the voltage
    for instant k + 1. The integral of the motor-cart position error (measured) is frozen while the
    new voltage saturates in the direction the integral pushes. With ``reference_time_constant`` tau > 0
    the law follows the reference through a first-order lag ``1/(tau s + 1)`` (sampled exactly), started
    at the first measured motor-cart position: a step then does not wind the integrator up.

    Coulomb friction compensation: from the estimated velocity of each cart the law estimates the
    cart's Coulomb force (:func:`coulomb_estimate` with the magnitude ``friction[c]``), adds the voltage
    that cancels it (the motor cart's directly, the passive cart's through the spring: the motor cart
    then leads by the deflection that pushes the passive cart with that force) and predicts the next
    state with it (the Kalman filter's model includes the friction it estimates).

    Parameters
    ----------
    kind : str
        Plant kind.
    coefficients : LQGCoefficients
        The design's numbers (``LQGCoefficients.from_design``, or gains a controller FMU holds).
    voltage_limit : float
        [V].
    reference_time_constant : float
        tau [s] of the reference lag; 0 = the reference as given.
    friction : sequence of float
        Coulomb force compensated on each cart of ``coefficients.friction_states`` [N] (0 = none).
    friction_velocity : float
        The compensation's threshold [m/s] (:func:`coulomb_estimate`), > 0.
    integrator_dead_band : float
        The integral ignores this much of the motor-cart position error [m] (:func:`dead_zone`); 0 = none.
    friction_breakaway_gain : float
        g of :func:`coulomb_estimate`: a cart near rest is compensated by g times the net force the
        frictionless model puts on it (the loop's demand), up to its Coulomb force; 0 = none.
    dither_amplitude : float
        [V] of a square wave at half the sample rate added to the computed voltage (its sign alternates every
        sample; the filter's model is given the voltage with it). Larger than the cart's breakaway voltage, it
        keeps a cart near rest from sticking, so stick-slip no longer turns the loop into a hunting cycle
        (dither: Armstrong-Helouvry, Dupont & Canudas de Wit, *Automatica* 30, 1994); 0 = none.
    """

    def __init__(self, kind: str, coefficients: LQGCoefficients, voltage_limit: float = 10.0,
                 reference_time_constant: float = 0.0, friction: Sequence[float] = (),
                 friction_velocity: float = 1e-3, integrator_dead_band: float = 0.0,
                 friction_breakaway_gain: float = 0.0, dither_amplitude: float = 0.0) -> None:
        super().__init__(kind, coefficients.sample_period, voltage_limit)
        if coefficients.outputs != tuple(self.measured):
            raise LawParameterError("design", f"LQG design is for outputs {coefficients.outputs}, the "
                                              f"{kind} plant measures {self.measured}")
        self.coefficients = coefficients
        tau = _check_nonneg("reference_time_constant", reference_time_constant)
        self.reference_pole = math.exp(-self.sample_period / tau) if tau > 0 else 0.0
        self.friction = tuple(_check_nonneg("friction", b) for b in friction)
        if self.friction and len(self.friction) != len(coefficients.friction_states):
            raise LawParameterError("friction", f"need {len(coefficients.friction_states)} Coulomb forces (one per "
                                                f"cart of the friction model), got {len(self.friction)}")
        self.friction_velocity = _check_positive("friction_velocity", friction_velocity)
        self.integrator_dead_band = _check_nonneg("integrator_dead_band", integrator_dead_band)
        self.friction_breakaway_gain = _check_nonneg("friction_breakaway_gain", friction_breakaway_gain)
        self.dither_amplitude = _check_nonneg("dither_amplitude", dither_amplitude)
        self._Cpinv = _right_inverse(coefficients.C)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.applied = 0.0
        self.integral = 0.0
        self.dither_sign = 1.0
        self.reference_filtered: float | None = None

    def _compute(self, y: Sequence[float], r: float) -> float:
        d = self.coefficients
        a = self.reference_pole
        rf = self._motor_cart(y) if self.reference_filtered is None else self.reference_filtered
        self.reference_filtered = r = a * rf + (1.0 - a) * r
        x_hat = self._correct(y)
        applied = self.applied
        free = [sum(map(mul, row, x_hat)) + b * applied for row, b in zip(d.Ad, d.Bd)]  # the model, no friction
        v0, g = self.friction_velocity, self.friction_breakaway_gain
        forces = [coulomb_estimate(x_hat[i], b, v0, (free[i] - x_hat[i]) / column[i], g)
                  for i, b, column in zip(d.friction_states, self.friction, d.friction_columns)]
        target = [xr * r for xr in d.reference_states]
        for f, lead in zip(forces, d.friction_leads):
            target = [t + f * c for t, c in zip(target, lead)]
        feedback = d.K_voltage * applied + sum(k * (x - t) for k, x, t in zip(d.K, x_hat, target))
        u = d.volts_per_newton * sum(forces) - feedback - d.K_integral * self.integral
        u = u + self.dither_amplitude * self.dither_sign
        self.dither_sign = -self.dither_sign
        error = dead_zone(r - self._motor_cart(y), self.integrator_dead_band)
        integral = self.integral + error * d.sample_period  # the design's T (a gain)
        limit = self.voltage_limit
        if abs(u) <= limit or (u > 0) != (-d.K_integral * (integral - self.integral) > 0):
            self.integral = integral
        self.applied = limit if u > limit else (-limit if u < -limit else u)
        x_pred = free
        for f, column in zip(forces, d.friction_columns):
            x_pred = [x - f * c for x, c in zip(x_pred, column)]
        self.x_pred = x_pred
        return applied


# =========================================================================== Hierarchical SMC

@dataclass(frozen=True)
class SubsystemModel:
    """``x_(2i)' = f_i(x) + b_i u`` with ``f_i(x) = a . x`` linear in the state (design-model order)."""

    a: tuple[float, ...]
    b: float


@dataclass(frozen=True)
class HSMCGains:
    """Hierarchical sliding-mode law (thesis 3.2.3, 4.2.3 after Qian, Yi & Zhao 2008).

    Subsystems (error coordinates, positions minus the reference)::

        single: (th, th'), (xc - r, xc')
        double: (th, th'), (xc - r, xc'), (xa - r, xa')        xc passive, xa active (motor) cart

    ``s_i = c_i x_(2i-1) + x_(2i)``; layers ``S_1 = s_1``, ``S_i = lambda_(i-1) S_(i-1) + s_i``, and the
    single-mass top layer weights its own subsystem by ``top_weight`` (the thesis's lambda2 = 1):
    ``S_n = sum_r alpha_r s_r``. Reaching law ``S_n' = -k S_n - eta tanh(tanh_gain S_n) - KI int S_n``.
    """

    c: tuple[float, ...]
    lam: tuple[float, ...]
    k: float
    eta: float
    KI: float = 0.0
    top_weight: float = 1.0
    tanh_gain: float = 10.0
    derivative_time_constant: float = 0.002
    denominator_min: float = 1e-3

    def alphas(self) -> tuple[float, ...]:
        """Coefficients alpha_r of s_r in the top layer S_n."""
        n = len(self.c)
        alpha = [0.0] * n
        alpha[n - 1] = self.top_weight
        prod = 1.0
        for r in range(n - 2, -1, -1):  # alpha_r = lambda_r lambda_(r+1) ... lambda_(n-1)
            prod *= self.lam[r]
            alpha[r] = prod
        return tuple(alpha)


@dataclass(frozen=True)
class Schedule:
    """``value(t) = base + delta exp(-rate t)`` (thesis 3.2.4, 4.2.4)."""

    base: float
    delta: float = 0.0
    rate: float = 0.0

    def __call__(self, t: float) -> float:
        return self.base + self.delta * math.exp(-self.rate * t) if self.delta else self.base


class HSMC(DiscreteLaw):
    """Hierarchical sliding-mode controller (two layers single mass, three double mass).

    The law is the unique input that makes the top layer follow the reaching law exactly on
    the subsystem models ``x_(2i)' = f_i + b_i u``::

        S_n' = sum_r alpha_r (c_r x_(2r) + f_r) + (sum_r alpha_r b_r) u
        u = -[sum_r alpha_r (c_r x_(2r) + f_r) + k S_n + eta tanh(g S_n) + KI int S_n] / sum_r alpha_r b_r

    which is Qian, Yi & Zhao's ``u = (sum_r alpha_r b_r u_eq,r + u_sw) / sum_r alpha_r b_r`` with
    ``b_r u_eq,r = -(c_r x_(2r) + f_r)``. The denominator ``sum_r alpha_r b_r`` must stay away from 0:
    a set of gains for which ``|sum alpha_r b_r| < denominator_min`` is rejected. The integral of
    S_n is frozen while the output saturates in the direction the integral pushes.

    Parameters
    ----------
    kind : str
        Plant kind.
    gains : HSMCGains
        Surface and reaching-law constants.
    models : sequence of SubsystemModel
        ``f_i, b_i`` of each subsystem, in the design-model state order (``subsystem_models``).
    """

    def __init__(self, kind: str, gains: HSMCGains, models: Sequence[SubsystemModel],
                 sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        n_layers = 2 if kind == "single-mass" else 3
        self.n_layers = n_layers
        n_states = 2 * n_layers
        if len(gains.c) != n_layers:
            raise LawParameterError("c", f"HSMC on the {kind} plant needs {n_layers} surface slopes c, got "
                                         f"{len(gains.c)}")
        if len(gains.lam) != n_layers - 1:
            raise LawParameterError("lambda", f"HSMC on the {kind} plant needs {n_layers - 1} layer weights "
                                              f"lambda, got {len(gains.lam)}")
        if len(models) != n_layers:
            raise LawParameterError("model", f"HSMC needs {n_layers} subsystem models, got {len(models)}")
        for i, ci in enumerate(gains.c, 1):
            _check_positive(f"c{i}", ci)
        for i, li in enumerate(gains.lam, 1):
            _check_finite(f"lambda{i}", li)
        for name in ("k", "eta", "KI"):
            _check_nonneg(name, getattr(gains, name))
        _check_finite("top_weight", gains.top_weight)
        _check_positive("tanh_gain", gains.tanh_gain)
        _check_nonneg("derivative_time_constant", gains.derivative_time_constant)
        _check_positive("denominator_min", gains.denominator_min)
        for i, m in enumerate(models, 1):
            if len(m.a) != n_states:
                raise LawParameterError(f"a{i}", f"subsystem {i} model needs {n_states} coefficients, got {len(m.a)}")
            for j, aj in enumerate(m.a, 1):
                _check_finite(f"a{i}_{j}", aj)
            _check_finite(f"b{i}", m.b)
        self.gains = gains
        self.models = tuple(models)
        # Constants of the top layer, as plain floats for the per-sample arithmetic:
        # S_n = sum alpha_r (c_r pos_r + vel_r),  S_n' = sum alpha_r c_r vel_r + w . x + den u,
        # with w = alpha A and den = alpha . b.
        alpha = gains.alphas()
        self._den = self._check_denominator(gains, _dot(alpha, [float(m.b) for m in models]))
        self._alpha = tuple(float(a) for a in alpha)
        self._w = tuple(_dot(alpha, [float(m.a[j]) for m in models]) for j in range(n_states))
        self._c = tuple(float(ci) for ci in gains.c)
        tau = gains.derivative_time_constant
        self._d = [FilteredDerivative(self.sample_period, tau) for _ in range(n_layers)]
        self.reset()

    @staticmethod
    def _check_denominator(gains: HSMCGains, den: float) -> float:
        if not math.isfinite(den) or abs(den) < gains.denominator_min:
            raise LawParameterError("lambda", f"parameters lambda1, lambda2: the HSMC denominator sum(alpha_r b_r) "
                                              f"= {den:.6g} is below denominator_min = {gains.denominator_min:g}: the "
                                              "top sliding layer cannot be moved by the input (change the layer "
                                              "weights or the model's b_i)")
        return den

    def reset(self) -> None:
        super().reset()
        self.integral = 0.0
        self.S = 0.0
        for d in self._d:
            d.reset()

    #: Output = force_gain * (law's u) + emf_gain * (motor-cart velocity): 1 and 0 when the subsystem
    #: models are voltage models; ``drive_through_motor`` sets them for force models.
    force_gain = 1.0
    emf_gain = 0.0

    def drive_through_motor(self, force_per_volt: float, emf_per_velocity: float) -> "HSMC":
        """Treat the law's ``u`` as a force [N] and apply the voltage that makes the motor produce it.

        The cart force of the DC motor (inductance neglected) is ``F = Kf (V - Ke v)`` with
        ``Kf = N Kt/(Ra rg)`` [N/V] and ``Ke = N Kb/rg`` [V s/m], ``v`` the motor-cart velocity, so
        ``V = F/Kf + Ke v``. Needed when the subsystem models ``f_i + b_i u`` describe a force-driven
        cart (the thesis's App. A.5 constants); returns the law.
        """
        self.force_gain = 1.0 / _check_positive("force_per_volt", force_per_volt)
        self.emf_gain = _check_nonneg("emf_per_velocity", emf_per_velocity)
        return self

    def _state(self, y: Sequence[float], r: float) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """Design-model state estimate in error coordinates (ipcosim.fmus.physics order without the current),
        and the (positions, velocities) of the subsystems: pendulum, pendulum cart, (motor cart)."""
        d = self._d
        if self.kind == "single-mass":
            xc, th = float(y[0]) - r, float(y[1])
            xcd, thd = d[1].update(float(y[0])), d[0].update(th)
            return (xc, xcd, th, thd), (th, xc), (thd, xcd)
        xa, xc, th = float(y[0]) - r, float(y[1]) - r, float(y[2])
        xad, xcd, thd = d[2].update(float(y[0])), d[1].update(float(y[1])), d[0].update(th)
        return (xa, xad, xc, xcd, th, thd), (th, xc, xa), (thd, xcd, xad)

    def _lower_layer_terms(self, c: tuple[float, ...], pos: tuple[float, ...], vel: tuple[float, ...]) -> float:
        """Reaching terms of the first layer added to the top layer's (0 for HSMC; see AdaptiveHSMC)."""
        return 0.0

    def current_gains(self) -> tuple[tuple[float, ...], float, float, float]:
        """(c, k, eta, KI) in effect at the law's time (constant for HSMC)."""
        g = self.gains
        return self._c, g.k, g.eta, g.KI

    def _compute(self, y: Sequence[float], r: float) -> float:
        x, pos, vel = self._state(y, r)
        c, k, eta, KI = self.current_gains()
        S = num = 0.0
        for a, ci, p, v in zip(self._alpha, c, pos, vel):
            S += a * (ci * p + v)
            num += a * ci * v
        for w, xi in zip(self._w, x):
            num += w * xi
        num += self._lower_layer_terms(c, pos, vel)
        den = self._den
        integral = self.integral + S * self.sample_period
        u_rest = -(num + k * S + eta * math.tanh(self.gains.tanh_gain * S)) / den
        if self.emf_gain or self.force_gain != 1.0:  # a force model: the voltage that gives the force
            den = den / self.force_gain
            u_rest = u_rest * self.force_gain + self.emf_gain * vel[-1]
        u = u_rest - KI * integral / den
        if abs(u) <= self.voltage_limit or (u > 0) != (-KI * S / den > 0):
            self.integral = integral
        else:
            u = u_rest - KI * self.integral / den
        self.S = S
        return u


@dataclass(frozen=True)
class AdaptiveSchedules:
    """Time schedules of the adaptive HSMC; ``None`` keeps the HSMC's constant."""

    k: Schedule | None = None
    eta: Schedule | None = None
    KI: Schedule | None = None
    c: tuple[Schedule | None, ...] = ()
    #: First-layer reaching gains (thesis App. A.6 KP1/deltaKP, KI1/deltaKI): the top layer's law gains
    #: ``alpha_1 (k1 S1 + KI1 int S1)``, so that the part of S_n carried by S1 reaches like S1' = -k1 S1 - KI1 int S1.
    k1: Schedule | None = None
    KI1: Schedule | None = None


class AdaptiveHSMC(HSMC):
    """HSMC whose gains follow time schedules ``p(t) = p0 + dp exp(-rate t)`` (thesis 3.2.4, 4.2.4).

    t is the law's own time ``ticks * sample_period`` (since its start or last reset). High reaching
    gain early (fast rise), lower later (less overshoot); integral gain small early, full later.
    """

    def __init__(self, kind: str, gains: HSMCGains, models: Sequence[SubsystemModel],
                 schedules: AdaptiveSchedules, sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__(kind, gains, models, sample_period, voltage_limit)
        for name in ("k", "eta", "KI", "k1", "KI1"):
            sch = getattr(schedules, name)
            if sch is not None:
                for part in ("base", "delta", "rate"):
                    _check_finite(f"{name}_{part}", getattr(sch, part))
                _check_nonneg(f"{name}_rate", sch.rate)
                if min(sch.base, sch.base + sch.delta) < 0:
                    raise LawParameterError(f"{name}_delta", f"parameter {name}_delta = {sch.delta}: the schedule "
                                                             f"{name}(t) = {sch.base} + {sch.delta} exp(-{sch.rate} t) "
                                                             "goes negative")
        if schedules.c and len(schedules.c) != self.n_layers:
            raise LawParameterError("c", f"need {self.n_layers} c schedules (or none), got {len(schedules.c)}")
        for i, sch in enumerate(schedules.c, 1):
            if sch is not None:
                for part in ("base", "delta", "rate"):
                    _check_finite(f"c{i}_{part}", getattr(sch, part))
                _check_nonneg(f"c{i}_rate", sch.rate)
                if min(sch.base, sch.base + sch.delta) <= 0:
                    raise LawParameterError(f"c{i}_delta", f"parameter c{i}_delta = {sch.delta}: the schedule "
                                                           f"c{i}(t) = {sch.base} + {sch.delta} exp(-{sch.rate} t) "
                                                           "must stay > 0")
        self.schedules = schedules

    def reset(self) -> None:
        super().reset()
        self.integral1 = 0.0

    def _lower_layer_terms(self, c: tuple[float, ...], pos: tuple[float, ...], vel: tuple[float, ...]) -> float:
        sc = self.schedules
        if sc.k1 is None and sc.KI1 is None:
            return 0.0
        t = self.time
        S1 = c[0] * pos[0] + vel[0]
        self.integral1 += S1 * self.sample_period
        k1 = sc.k1(t) if sc.k1 is not None else 0.0
        KI1 = sc.KI1(t) if sc.KI1 is not None else 0.0
        return self._alpha[0] * (k1 * S1 + KI1 * self.integral1)

    def current_gains(self) -> tuple[tuple[float, ...], float, float, float]:
        t = self.time
        g, sc = self.gains, self.schedules
        c = tuple(s(t) if s is not None else ci for s, ci in zip(sc.c or (None,) * len(self._c), self._c))
        k = sc.k(t) if sc.k is not None else g.k
        eta = sc.eta(t) if sc.eta is not None else g.eta
        KI = sc.KI(t) if sc.KI is not None else g.KI
        return c, k, eta, KI


# ============================================================================ Swing-up (not in the thesis)

@dataclass(frozen=True)
class SwingUpGains:
    """Energy-based swing-up (Astrom & Furuta, *Automatica* 36, 2000) with a hand-over to a balancing law.

    Pendulum energy about the pivot, zero upright at rest (``J = Mp Lp^2/3``, ``l = Lp/2``)::

        E = J th'^2 / 2 + Mp g l (cos th - 1)                  (-2 Mp g l hanging at rest)

    Since ``dE/dt = Mp l cos(th) th' xc''`` (without pivot friction), the cart acceleration

        a = sat_amax( k_energy g (E0 - E)/(2 Mp g l) sign(th' cos th) ) - kx xc - kv xc'

    pumps the energy to ``E0 = energy_target * 2 Mp g l``; ``kx``, ``kv`` keep the cart near the centre
    of the track. The acceleration is turned into volts by the design model's cart and motor,
    ``V = ((Meq + Mp) a + Beq xc')/Kf + Ke xc'``. Within ``catch_angle`` of upright the balancing law
    takes over (its estimator started from the swing-up's estimates); beyond ``release_angle`` the
    swing-up takes over again. A hanging start needs a kick: sign(0) is taken as +1.
    """

    # a grid search on thesis-ch3 (ideal and with encoder counts and 0.1 N Coulomb friction): the
    # smallest track excursion among the sets that swing up and stay up on both
    k_energy: float = 20.0
    accel_limit: float = 4.0       # m/s^2
    kx: float = 4.0                # 1/s^2
    kv: float = 4.0                # 1/s
    energy_target: float = 0.05    # fraction of 2 Mp g l
    catch_angle: float = 0.3       # rad
    release_angle: float = 0.7     # rad
    derivative_time_constant: float = 0.005  # s

    UNITS = {"k_energy": "1", "accel_limit": "m/s2", "kx": "1/s2", "kv": "1/s", "energy_target": "1",
             "catch_angle": "rad", "release_angle": "rad", "derivative_time_constant": "s"}
    DOCS = {"k_energy": "energy-pumping gain: cart acceleration g k_energy per unit of normalized energy error",
            "accel_limit": "largest cart acceleration the swing-up asks for",
            "kx": "cart-centring gain on the position during the swing-up",
            "kv": "cart-centring gain on the velocity during the swing-up",
            "energy_target": "pendulum energy aimed at, as a fraction of 2 Mp g l (0 = upright at rest)",
            "catch_angle": "|angle| from upright below which the balancing LQR takes over",
            "release_angle": "|angle| from upright above which the swing-up takes over again",
            "derivative_time_constant": "velocity estimates during the swing-up: filtered differences"}


def wrap_angle(th: float) -> float:
    """``th`` wrapped to [-pi, pi) (upright = 0)."""
    return (th + math.pi) % (2 * math.pi) - math.pi


class SwingUp(DiscreteLaw):
    """Swing-up from hanging and hand-over to a balancing LQR (``SwingUpGains``), single mass only.

    Parameters
    ----------
    gains : SwingUpGains
    balance : LQR
        The balancing law (same sample period and limit).
    cart : tuple of float
        ``(Meq + Mp, Beq, Kf, Ke, Mp, Lp, g)`` of the design model: cart mass [kg], viscous damping
        [N s/m], force per volt N Kt/(Ra rg) [N/V], back-EMF per velocity N Kb/rg [V s/m], pendulum
        mass [kg] and length [m], gravity [m/s^2].
    """

    def __init__(self, gains: SwingUpGains, balance: "LQR", cart: tuple[float, ...],
                 sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__("single-mass", sample_period, voltage_limit)
        for f in fields(gains):
            _check_nonneg(f.name, getattr(gains, f.name))
        if not 0 < gains.catch_angle < gains.release_angle:
            raise LawParameterError("catch_angle", f"parameters catch_angle = {gains.catch_angle} rad and "
                                                   f"release_angle = {gains.release_angle} rad: need "
                                                   "0 < catch < release")
        self.gains = gains
        self.balance = balance
        self.m, self.beq, self.kf, self.ke, mp, lp, g = (float(v) for v in cart)
        self.J, self.mgl = mp * lp * lp / 3, mp * g * lp / 2
        self.mgl2 = 2 * self.mgl
        tau = gains.derivative_time_constant
        self._dx, self._dth = FilteredDerivative(self.sample_period, tau), FilteredDerivative(self.sample_period, tau)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.balancing = False
        self.catches = 0
        self.energy = 0.0
        self._dx.reset()
        self._dth.reset()
        self.balance.reset()

    def _compute(self, y, r: float) -> float:
        g = self.gains
        x, th = float(y[0]), float(y[1])
        v, w = self._dx.update(x), self._dth.update(th)
        thw = wrap_angle(th)
        self.energy = 0.5 * self.J * w * w + self.mgl * (math.cos(th) - 1.0)
        if self.balancing and abs(thw) > g.release_angle:
            self.balancing = False
        if not self.balancing and abs(thw) < g.catch_angle:
            self.balancing = True
            self.catches += 1
            self.balance.reset()
            self.balance.x_pred = [x, v, thw, w]
        if self.balancing:
            self.balance.ticks = self.ticks
            return self.balance._compute((x, thw), r)
        s = w * math.cos(th)
        sign = 1.0 if s >= 0 else -1.0
        pump = g.k_energy * 9.81 * (g.energy_target * self.mgl2 - self.energy) / self.mgl2 * sign
        a = saturate(pump, g.accel_limit) - g.kx * (x - r) - g.kv * v
        return (self.m * a + self.beq * v) / self.kf + self.ke * v
