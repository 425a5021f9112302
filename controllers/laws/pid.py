"""The thesis's single-loop PID and the cascade PID (inner angle loop, outer cart loop): the laws,
their parameters and sets, their linear models and their registry entries."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping, Sequence

from ipcosim.controllers.laws.base import (
    DiscreteLaw,
    FilteredDerivative,
    G,
    LawEntry,
    ParamSpec,
    check_finite,
    check_nonneg,
    check_positive,
    saturate,
)
from ipcosim.controllers.linear import Builder, Lin


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
    within the +-10 V limit the loop does not keep the pendulum up (docs/controllers.md, PID).
    """

    def __init__(self, kind: str, gains: PIDGains = PIDGains(), sample_period: float = 1e-3,
                 voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        for f in fields(gains):
            check_finite(f.name, getattr(gains, f.name))
        check_nonneg("derivative_time_constant", gains.derivative_time_constant)
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


def _pid_specs(kind: str) -> list[ParamSpec]:
    g = PIDGains()
    return [ParamSpec(f, getattr(g, f), PIDGains.UNITS[f], PIDGains.DOCS[f],
                      "nonnegative" if f == "derivative_time_constant" else "finite")
            for f in ("Kp", "Ki", "Kd", "derivative_time_constant")]


def _pid_values(kind: str, parameter_set: str) -> dict[str, Any]:
    g = PIDGains()
    return {"Kp": g.Kp, "Ki": g.Ki, "Kd": g.Kd, "derivative_time_constant": g.derivative_time_constant}


def _build_pid(kind: str, v: Mapping[str, Any], backend: str) -> PID:
    g = PIDGains(**{f: float(v[f]) for f in ("Kp", "Ki", "Kd", "derivative_time_constant")})
    return PID(kind, g, float(v["sample_period"]), float(v["voltage_limit"]))


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
            check_finite(f.name, getattr(gains, f.name))
        check_positive("theta_ref_limit", gains.theta_ref_limit)
        check_nonneg("derivative_time_constant", gains.derivative_time_constant)
        check_nonneg("reference_time_constant", gains.reference_time_constant)
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


#: Tuned sets: single mass ``python -m ipcosim.controllers.tuning`` (rounded to 3 significant digits); double mass
#: the robust search of docs/controllers.md (``ipcosim tune --max-peak-sensitivity 6 --min-delay-margin 0.003
#: --min-phase-margin 30 --spread 0.1``, rounded to 4 digits): a slow, robust feedback, and a reference model
#: that sets how fast the cart follows the step.
TUNED_CASCADE: dict[str, CascadeGains] = {
    "single-mass": CascadeGains(Kp_th=79.2, Kd_th=12.9, Kp_x=10.9, Kd_x=6.74, Ki_x=6.37),
    "double-mass": CascadeGains(Kp_th=61.07, Kd_th=25.25, Ki_th=4.295, Kp_x=4.252, Kd_x=11.12, Ki_x=0.1017,
                                Kv_m=30.91, derivative_time_constant=0.00598, reference_time_constant=0.4258),
}


def _cascade_specs(kind: str) -> list[ParamSpec]:
    g = CascadeGains()
    pos = {"theta_ref_limit": "positive", "derivative_time_constant": "nonnegative",
           "reference_time_constant": "nonnegative"}
    return [ParamSpec(f, getattr(g, f), CascadeGains.UNITS[f], CascadeGains.DOCS[f], pos.get(f, "finite"))
            for f in CascadeGains.UNITS]


def _cascade_values(kind: str, parameter_set: str) -> dict[str, Any]:
    g = TUNED_CASCADE[kind]
    return {f: getattr(g, f) for f in CascadeGains.UNITS}


def _build_cascade(kind: str, v: Mapping[str, Any], backend: str) -> CascadePID:
    return CascadePID(kind, CascadeGains(**{f: float(v[f]) for f in CascadeGains.UNITS}), float(v["sample_period"]),
                      float(v["voltage_limit"]))


# ============================================================================ linear models

def linear_pid(law: PID, b: Builder) -> tuple[Lin, list[str]]:
    g, T = law.gains, law.sample_period
    x = b.input(0)
    e = x * -1.0
    de = b.derivative(x, T, g.derivative_time_constant) * -1.0
    u = e * g.Kp + de * g.Kd
    return (u + b.integral(e, T) * g.Ki if g.Ki else u), []


def linear_cascade(law: CascadePID, b: Builder) -> tuple[Lin, list[str]]:
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


PID_LAW = LawEntry("PID", {"single-mass": ("thesis",), "double-mass": ("thesis",)}, _pid_specs, _pid_values,
                   _build_pid, classes=(PID,), linear=linear_pid, pid_gain_search=True)
CASCADE_PID_LAW = LawEntry("CascadePID", {"single-mass": ("tuned",), "double-mass": ("tuned",)}, _cascade_specs,
                           _cascade_values, _build_cascade, classes=(CascadePID,), linear=linear_cascade)
