"""The IP02 single-mass cart with a free pendulum (thesis ch. 3): its plant kind.

Its parameters, its equations (``ipcosim.fmus.physics`` states them and re-exports them) and their
momentum form ``[xc, p1, th, p2, i]``, which the integrator advances: there the motor current enters the
slow equations with a constant coefficient.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from ipcosim.fmus.kinds.common import (
    Cart,
    InternalForm,
    MotorParams,
    PlantKind,
    clip_voltage,
    karnopp,
    pendulum_cart_mass_matrix,
)
from ipcosim.fmus.kinds.common import param_field as _p


@dataclass(frozen=True)
class SingleMassParams(MotorParams):
    """IP02 single-mass cart with a free pendulum (thesis chapter 3)."""

    Mc: float = _p(0.961373, "kg", "cart mass (Meq = Mc + Jm N^2/rg^2 = 1.0945 kg)", "fit", positive=True)
    Mp: float = _p(0.2303, "kg", "pendulum mass", "fit", positive=True)
    Lp: float = _p(0.3371, "m", "full pendulum length (pivot to tip)", "fit", positive=True)
    Beq: float = _p(11.55, "N.s/m", "total viscous damping seen by the cart (rack, bearings, rotor)", "fit",
                    nonnegative=True)
    Bp: float = _p(0.0024, "N.m.s/rad", "viscous damping at the pendulum pivot", "fit", nonnegative=True)
    b: float = _p(0.0, "N", "Coulomb friction force on the cart", "assumed", nonnegative=True)

    @property
    def Meq(self) -> float:
        """Equivalent cart mass including reflected rotor inertia [kg]."""
        return self.Mc + self.reflected_inertia


def single_mass_applied_force(x: Sequence[float], p: SingleMassParams) -> float:
    """Force on the single-mass cart [N] besides Coulomb friction, with the pendulum's reaction at zero cart
    acceleration: the force the friction must balance for the cart to stick."""
    _, xd, th, thd, i = x
    ml = 0.5 * p.Mp * p.Lp
    s = math.sin(th)
    m12 = -ml * math.cos(th)
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    r1 = p.force_per_amp * i - ml * thd * thd * s - p.Beq * xd
    r2 = ml * p.g * s - p.Bp * thd
    return r1 - m12 * r2 / m22


def single_mass_rhs(x: Sequence[float], v: float, p: SingleMassParams) -> tuple[float, ...]:
    """Time derivative of the single-mass state ``[xc, xc', th, th', i]`` for voltage ``v`` [V]."""
    _, xd, th, thd, i = x
    vA = p.amplifier_gain * clip_voltage(v, p.voltage_limit)
    ml = 0.5 * p.Mp * p.Lp
    s, c = math.sin(th), math.cos(th)
    m11 = p.Meq + p.Mp
    m12 = -ml * c
    m22 = p.Mp * p.Lp * p.Lp / 3.0
    fric = karnopp(xd, single_mass_applied_force(x, p), p.b, p.coulomb_velocity) if p.b else 0.0
    r1 = p.force_per_amp * i - ml * thd * thd * s - p.Beq * xd - fric
    r2 = ml * p.g * s - p.Bp * thd
    det = m11 * m22 - m12 * m12
    xdd = (m22 * r1 - m12 * r2) / det
    thdd = (m11 * r2 - m12 * r1) / det
    di = (vA - p.Ra * i - p.emf_per_velocity * xd) / p.La
    return (xd, xdd, thd, thdd, di)


# --- Momentum form of the single-mass plant (used by the integrator) -----------------------
#
# In the state [xc, xc', th, th', i] the armature current reaches the accelerations through
# the angle-dependent inverse mass matrix, so the stiff current couples into the slow
# equations with a coefficient that varies with the angle. With the generalized momenta
#     p1 = (Meq + Mp) xc' - (Mp Lp/2) cos(th) th',   p2 = -(Mp Lp/2) cos(th) xc' + (Mp Lp^2/3) th'
# the current enters only p1' = (N Kt/rg) i - Beq xc' - fc(xc') with a constant coefficient
# (the centripetal term cancels), and the exponential integrator treats the stiff part exactly.

def _single_mass_matrix(th: float, p: SingleMassParams) -> tuple[float, float, float]:
    ml = 0.5 * p.Mp * p.Lp
    return p.Meq + p.Mp, -ml * math.cos(th), p.Mp * p.Lp * p.Lp / 3.0


def single_mass_to_momentum(x: Sequence[float], p: SingleMassParams) -> tuple[float, ...]:
    """``[xc, xc', th, th', i]`` -> ``[xc, p1, th, p2, i]``."""
    xc, xd, th, thd, i = x
    m11, m12, m22 = _single_mass_matrix(th, p)
    return (xc, m11 * xd + m12 * thd, th, m12 * xd + m22 * thd, i)


def single_mass_from_momentum(z: Sequence[float], p: SingleMassParams) -> tuple[float, ...]:
    """``[xc, p1, th, p2, i]`` -> ``[xc, xc', th, th', i]``."""
    xc, p1, th, p2, i = z
    m11, m12, m22 = _single_mass_matrix(th, p)
    det = m11 * m22 - m12 * m12
    return (xc, (m22 * p1 - m12 * p2) / det, th, (m11 * p2 - m12 * p1) / det, i)


def single_mass_momentum_rhs(z: Sequence[float], v: float, p: SingleMassParams) -> tuple[float, ...]:
    """Time derivative of the momentum-form state ``[xc, p1, th, p2, i]``."""
    _, xd, th, thd, i = single_mass_from_momentum(z, p)
    vA = p.amplifier_gain * clip_voltage(v, p.voltage_limit)
    ml = 0.5 * p.Mp * p.Lp
    s = math.sin(th)
    fric = karnopp(xd, single_mass_applied_force((0.0, xd, th, thd, i), p), p.b, p.coulomb_velocity) if p.b else 0.0
    dp1 = p.force_per_amp * i - p.Beq * xd - fric
    dp2 = ml * p.g * s - p.Bp * thd + ml * s * thd * xd
    di = (vA - p.Ra * i - p.emf_per_velocity * xd) / p.La
    return (xd, dp1, thd, dp2, di)


def single_mass_internal_rhs(p: SingleMassParams) -> Callable[..., tuple[float, ...]]:
    """``f(xc, p1, th, p2, i, vA)``: ``ipcosim.fmus.single_mass_momentum_rhs`` with the parameters folded
    into constants and the voltage already clipped (same arithmetic; checked equal in the tests)."""
    sin, cos = math.sin, math.cos
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
        fric = karnopp(xd, kf * i - ml * thd * thd * s - beq * xd - m12 * (mlg * s - bp * thd) / m22, b, cv) \
            if b else 0.0
        return (xd, kf * i - beq * xd - fric, thd, mlg * s - bp * thd + ml * s * thd * xd,
                (vA - ra * i - ke * xd) / la)
    return f


def single_mass_output_map(p: SingleMassParams) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """``ipcosim.fmus.single_mass_from_momentum`` with the parameters folded into constants
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


def single_mass_pendulum_mass_matrix(th: float, p: SingleMassParams) -> tuple[float, float, float]:
    """``(m11, m12, m22)``: the mass matrix of the cart and the pendulum at angle ``th`` (the taps)."""
    return pendulum_cart_mass_matrix(p.Meq, th, p)


KIND = PlantKind(
    name="single-mass", suffix="SingleMass", description="single-mass cart", params=SingleMassParams,
    presets={
        "thesis-ch3": ({}, "single mass, the thesis's MIXED set: the long pendulum's mass (0.2303 kg) on the medium "
                           "pendulum's length (0.3371 m), no real pendulum; kept because it reproduces thesis eq. 3.24 "
                           "and its poles (the thesis's ch. 3 model)"),
        "thesis-appendix-a": ({"Lp": 0.6413},
                              "single mass, long pendulum (0.2303 kg, 0.6413 m), physically consistent: reproduces "
                              "the App. A.2 4-state A, B (the model the thesis designed its LQR on)"),
        "ip02-medium": ({"Mp": 0.12717, "Lp": 0.337},
                        "single mass, medium pendulum (0.12717 kg, 0.337 m: the double-mass fit), physically "
                        "consistent"),
    },
    states=("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity", "motor_current"),
    measured=("cart_position", "pendulum_angle"),
    carts=(Cart("cart_position", "cart_velocity", "b", damping="Beq"),),
    rhs=single_mass_rhs,
    applied_forces=lambda x, p: (single_mass_applied_force(x, p),),
    folded_rhs=single_mass_internal_rhs,
    pendulum_mass_matrix=single_mass_pendulum_mass_matrix,
    internal=InternalForm(single_mass_to_momentum, single_mass_momentum_rhs, single_mass_output_map),
    kernels={"single_mass_rhs": single_mass_rhs, "single_mass_momentum_rhs": single_mass_momentum_rhs},
    identified=("Mc", "Beq", "Bp", "b", "Kt"),
)
