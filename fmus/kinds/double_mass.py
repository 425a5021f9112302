"""The IP02 active cart coupled by a spring and damper to a passive cart carrying the pendulum
(thesis ch. 4): its plant kind.

Its parameters and its equations (``ipcosim.fmus.physics`` states them and re-exports them); the integrator
advances the plain state (the current drives only the active cart, whose mass matrix is constant).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from ipcosim.fmus.kinds.common import Cart, MotorParams, PlantKind, clip_voltage, karnopp, pendulum_cart_mass_matrix
from ipcosim.fmus.kinds.common import param_field as _p


@dataclass(frozen=True)
class DoubleMassParams(MotorParams):
    """IP02 active cart (motor) coupled by a spring and damper to a passive cart carrying the
    pendulum (thesis chapter 4)."""

    Ma: float = _p(0.961423, "kg", "active cart mass (Ma_eq = Ma + Jm N^2/rg^2 = 1.09455 kg)", "fit",
                   positive=True)
    Mc: float = _p(0.96125, "kg", "passive cart mass", "fit", positive=True)
    Mp: float = _p(0.12717, "kg", "pendulum mass (medium pendulum)", "fit", positive=True)
    Lp: float = _p(0.337, "m", "full pendulum length (pivot to tip)", "fit", positive=True)
    Ba: float = _p(8.347, "N.s/m", "viscous damping on the active cart (incl. rotor damping)", "fit",
                   nonnegative=True)
    Bc: float = _p(0.00201, "N.s/m", "viscous damping on the passive cart", "fit", nonnegative=True)
    Bf: float = _p(2.2029, "N.s/m", "damper between the carts", "fit", nonnegative=True)
    K: float = _p(142.185, "N/m", "spring stiffness between the carts", "fit", nonnegative=True)
    Bp: float = _p(0.0024, "N.m.s/rad", "viscous damping at the pendulum pivot", "fit", nonnegative=True)
    b1: float = _p(0.0, "N", "Coulomb friction force on the active cart", "assumed", nonnegative=True)
    b2: float = _p(0.0, "N", "Coulomb friction force on the passive cart", "assumed", nonnegative=True)

    @property
    def Ma_eq(self) -> float:
        """Equivalent active-cart mass including reflected rotor inertia [kg]."""
        return self.Ma + self.reflected_inertia



def double_mass_internal_rhs(p: DoubleMassParams) -> Callable[..., tuple[float, ...]]:
    """``f(xa, xa', xc, xc', th, th', i, vA)``: ``ipcosim.fmus.double_mass_rhs`` with the parameters folded
    into constants and the voltage already clipped (same arithmetic; checked equal in the tests)."""
    sin, cos = math.sin, math.cos
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
        s = sin(th)
        m12 = -ml * cos(th)
        r2 = mlg * s - Bp * thd
        fa = karnopp(xad, kf * i - Ba * xad + Bf * xcd - spring, b1, cv) if b1 else 0.0
        fc = karnopp(xcd, Bf * xad - bfc * xcd + spring - ml * thd * thd * s - m12 * r2 / m22, b2, cv) \
            if b2 else 0.0
        xadd = (kf * i - Ba * xad + Bf * xcd - spring - fa) / Ma_eq
        r1 = Bf * xad - bfc * xcd + spring - ml * thd * thd * s - fc
        det = m11 * m22 - m12 * m12
        return (xad, xadd, xcd, (m22 * r1 - m12 * r2) / det, thd, (m11 * r2 - m12 * r1) / det,
                (vA - ra * i - ke * xad) / la)
    return f


def double_mass_rhs(x: Sequence[float], v: float, p: DoubleMassParams) -> tuple[float, ...]:
    """Time derivative of the double-mass state ``[xa, xa', xc, xc', th, th', i]`` for voltage ``v`` [V]."""
    xa, xad, xc, xcd, th, thd, i = x
    vA = p.amplifier_gain * clip_voltage(v, p.voltage_limit)
    spring = p.K * (xa - xc)
    fa = fc = 0.0
    if p.b1 or p.b2:
        applied_a, applied_c = double_mass_applied_forces(x, p)
        fa = karnopp(xad, applied_a, p.b1, p.coulomb_velocity) if p.b1 else 0.0
        fc = karnopp(xcd, applied_c, p.b2, p.coulomb_velocity) if p.b2 else 0.0
    xadd = (p.force_per_amp * i - p.Ba * xad + p.Bf * xcd - spring - fa) / p.Ma_eq
    ml = 0.5 * p.Mp * p.Lp
    s, c = math.sin(th), math.cos(th)
    m11 = p.Mc + p.Mp
    m12 = -ml * c
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    r1 = p.Bf * xad - (p.Bf + p.Bc) * xcd + spring - ml * thd * thd * s - fc
    r2 = ml * p.g * s - p.Bp * thd
    det = m11 * m22 - m12 * m12
    xcdd = (m22 * r1 - m12 * r2) / det
    thdd = (m11 * r2 - m12 * r1) / det
    di = (vA - p.Ra * i - p.emf_per_velocity * xad) / p.La
    return (xad, xadd, xcd, xcdd, thd, thdd, di)


def double_mass_applied_forces(x: Sequence[float], p: DoubleMassParams) -> tuple[float, float]:
    """Forces [N] on the active and on the passive cart besides Coulomb friction (the passive cart's with the
    pendulum's reaction at zero cart acceleration): what each cart's friction must balance for it to stick."""
    xa, xad, xc, xcd, th, thd, i = x
    spring = p.K * (xa - xc)
    ml = 0.5 * p.Mp * p.Lp
    s = math.sin(th)
    m12 = -ml * math.cos(th)
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    r1 = p.Bf * xad - (p.Bf + p.Bc) * xcd + spring - ml * thd * thd * s
    r2 = ml * p.g * s - p.Bp * thd
    return p.force_per_amp * i - p.Ba * xad + p.Bf * xcd - spring, r1 - m12 * r2 / m22


def double_mass_pendulum_mass_matrix(th: float, p: DoubleMassParams) -> tuple[float, float, float]:
    """``(m11, m12, m22)``: the mass matrix of the passive cart and the pendulum at angle ``th`` (the taps)."""
    return pendulum_cart_mass_matrix(p.Mc, th, p)


KIND = PlantKind(
    name="double-mass", suffix="DoubleMass", description="double-mass (spring-coupled) carts", params=DoubleMassParams,
    presets={
        "thesis-ch4": ({}, "double mass, medium pendulum: reproduces thesis eq. 4.23 and App. B.3"),
        # b2 FITTED (not measured): docs/plant.md, thesis-ch4-friction, says how
        "thesis-ch4-friction": ({"b2": 0.1047},
                                "thesis-ch4 plus a passive-cart Coulomb force b2 = 0.1047 N, FITTED so that the "
                                "thesis's double-mass HSMC leaves the thesis's 5.575 mm steady-state error (20 s)"),
    },
    states=("active_cart_position", "active_cart_velocity", "passive_cart_position", "passive_cart_velocity",
            "pendulum_angle", "pendulum_velocity", "motor_current"),
    measured=("active_cart_position", "passive_cart_position", "pendulum_angle"),
    carts=(Cart("active_cart_position", "active_cart_velocity", "b1", mass="Ma_eq", damping="Ba"),
           Cart("passive_cart_position", "passive_cart_velocity", "b2", damping="Bc")),
    rhs=double_mass_rhs,
    applied_forces=double_mass_applied_forces,
    folded_rhs=double_mass_internal_rhs,
    pendulum_mass_matrix=double_mass_pendulum_mass_matrix,
    kernels={"double_mass_rhs": double_mass_rhs},
    identified=("Ma", "Mc", "K", "Ba", "Bf", "b1", "b2", "Kt"),
)
