"""The energy swing-up from hanging with a hand-over to the thesis's LQR (not in the thesis; single mass
only): the law, its parameters and set, and its registry entry (its gains are its balancing LQR's)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping

from ipcosim.controllers.laws.base import (
    Designed,
    DiscreteLaw,
    FilteredDerivative,
    LawEntry,
    LawParameterError,
    ParamSpec,
    check_nonneg,
    design_params_from,
    model_specs,
    saturate,
)
from ipcosim.controllers.laws.lqr import (
    LQR,
    LQR_LAW,
    lqr_design_from,
    lqr_from_gains,
    lqr_gain_specs,
    lqr_gains,
    lqr_specs,
    lqr_weight_parameters,
)


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
        The balancing law (same plant kind, sample period and limit).
    cart : tuple of float
        ``(Meq + Mp, Beq, Kf, Ke, Mp, Lp, g)`` of the design model: cart mass [kg], viscous damping
        [N s/m], force per volt N Kt/(Ra rg) [N/V], back-EMF per velocity N Kb/rg [V s/m], pendulum
        mass [kg] and length [m], gravity [m/s^2].
    """

    def __init__(self, gains: SwingUpGains, balance: LQR, cart: tuple[float, ...],
                 sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__(balance.kind, sample_period, voltage_limit)
        for f in fields(gains):
            check_nonneg(f.name, getattr(gains, f.name))
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


def _swing_up_specs(kind: str) -> list[ParamSpec]:
    g = SwingUpGains()
    return [ParamSpec(f, getattr(g, f), SwingUpGains.UNITS[f], SwingUpGains.DOCS[f],
                      "positive" if f in ("catch_angle", "release_angle") else "nonnegative")
            for f in SwingUpGains.UNITS] + lqr_specs(kind) + model_specs(kind)


def _swing_up_values(kind: str, parameter_set: str) -> dict[str, Any]:
    g = SwingUpGains()
    return {**{f: getattr(g, f) for f in SwingUpGains.UNITS}, **LQR_LAW.set_values(kind, "thesis")}


def swing_up_around(kind: str, v: Mapping[str, Any], balance: LQR) -> SwingUp:
    """The swing-up law of the flat parameter values ``v`` around the balancing law ``balance``
    (designed from ``v`` or rebuilt from stored gains: no design stack needed here)."""
    p = design_params_from(kind, v)
    cart = (p.Meq + p.Mp, p.Beq, p.force_per_amp / p.Ra, p.emf_per_velocity, p.Mp, p.Lp, p.g)
    return SwingUp(SwingUpGains(**{f: float(v[f]) for f in SwingUpGains.UNITS}), balance, cart,
                   float(v["sample_period"]), float(v["voltage_limit"]))


def _build_swing_up(kind: str, v: Mapping[str, Any], backend: str) -> SwingUp:
    balance = LQR(kind, lqr_design_from(kind, v, backend), float(v["voltage_limit"]),
                  output_filter_time_constant=float(v["output_filter_time_constant"]))
    return swing_up_around(kind, v, balance)


def _swing_up_from_gains(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> SwingUp:
    return swing_up_around(kind, values, lqr_from_gains(kind, values, gains))


# not in the thesis, single mass only: energy swing-up from hanging, balanced by the thesis's LQR
SWING_UP_LAW = LawEntry("SwingUp", {"single-mass": ("tuned",)}, _swing_up_specs, _swing_up_values, _build_swing_up,
                        classes=(SwingUp,), model_based=True,
                        designed=Designed(lqr_gain_specs, lqr_weight_parameters, lambda law: lqr_gains(law.balance),
                                          _swing_up_from_gains))
