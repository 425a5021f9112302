"""Nonlinear IP02 plant dynamics, pure Python (no FMI import).

One source of truth for the plant FMUs, the virtual rig, the controller design and
the analysis tools. Equations (thesis 3.1, 3.8, 3.14, 3.18, 4.6, 4.15; theta is the
pendulum angle, counter-clockwise positive from upright):

Single mass, state ``x = [xc, xc_dot, theta, theta_dot, i]``::

    La i'  = vA - Ra i - (N Kb / rg) xc'
    (Meq + Mp) xc'' - (Mp Lp/2) cos(th) th'' + (Mp Lp/2) th'^2 sin(th) + Beq xc' + fc(xc')
                    = (N Kt / rg) i
    (Mp Lp^2/3) th'' - (Mp Lp/2) cos(th) xc'' + Bp th' - Mp g (Lp/2) sin(th) = 0

Double mass, state ``x = [xa, xa_dot, xc, xc_dot, theta, theta_dot, i]``::

    La i'  = vA - Ra i - (N Kb / rg) xa'
    Ma_eq xa'' + Ba xa' - Bf xc' + K (xa - xc) + fa(xa') = (N Kt / rg) i
    (Mc + Mp) xc'' - (Mp Lp/2) cos(th) th'' + (Mp Lp/2) th'^2 sin(th) - Bf xa' + (Bf + Bc) xc'
                    - K (xa - xc) + fc(xc') = 0
    (Mp Lp^2/3) th'' - (Mp Lp/2) cos(th) xc'' + Bp th' - Mp g (Lp/2) sin(th) = 0

``vA`` is the commanded voltage clipped to ``+-voltage_limit`` (the D/A range) times ``amplifier_gain`` (the amplifier).

Coulomb friction is stick-slip, after D. Karnopp, "Computer simulation of stick-slip friction in
mechanical dynamic systems", ASME J. Dyn. Syst. Meas. Control 107(1), 100-103 (1985)
(:func:`karnopp`): outside a small velocity band ``|v| < coulomb_velocity`` the force is the
kinetic ``b sign(v)``; inside it the cart sticks: the friction balances the *applied* force (every
other force on the cart, with the coupled pendulum's reaction, :func:`single_mass_applied_force`,
:func:`double_mass_applied_forces`) up to the breakaway force ``b`` (static = kinetic level), so the
cart's acceleration is zero. The band replaces the zero-velocity instant a fixed-step integrator
never hits; ``ipcosim.fmus.plant.constrain`` then holds a stuck cart exactly still at the end of
each step. A cart pushed with less than ``b`` does not move. Every friction term is exactly zero
(and the arithmetic that of the frictionless model) for the thesis's default b = 0.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

from ipcosim.fmus.params import DoubleMassParams, PlantParams, SingleMassParams

SINGLE_STATES = ("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity", "motor_current")
DOUBLE_STATES = ("active_cart_position", "active_cart_velocity", "passive_cart_position",
                 "passive_cart_velocity", "pendulum_angle", "pendulum_velocity", "motor_current")
STATE_UNITS = {"cart_position": "m", "cart_velocity": "m/s", "active_cart_position": "m",
               "active_cart_velocity": "m/s", "passive_cart_position": "m", "passive_cart_velocity": "m/s",
               "pendulum_angle": "rad", "pendulum_velocity": "rad/s", "motor_current": "A"}

#: Measured outputs (what the rig's encoders give), per plant kind.
MEASURED = {"single-mass": ("cart_position", "pendulum_angle"),
            "double-mass": ("active_cart_position", "passive_cart_position", "pendulum_angle")}
#: Index of the motor-driven cart's position in the state, per plant kind.
MOTOR_CART = {"single-mass": 0, "double-mass": 0}


def state_names(kind: str) -> tuple[str, ...]:
    """Names of the state variables of plant ``kind`` in state-vector order."""
    return SINGLE_STATES if kind == "single-mass" else DOUBLE_STATES


def clip_voltage(v: float, limit: float) -> float:
    """The D/A converter's range: the command clipped to +-limit (the amplifier then multiplies it by
    ``amplifier_gain``)."""
    return limit if v > limit else (-limit if v < -limit else v)


def karnopp(v: float, applied: float, b: float, band: float) -> float:
    """Karnopp's stick-slip Coulomb force [N] on a cart at velocity ``v`` [m/s] under ``applied`` force [N].

    Kinetic ``b sign(v)`` for ``|v| >= band``; inside the band the force that cancels ``applied``,
    saturated at the breakaway force ``b`` (Karnopp 1985, module docstring).
    """
    if -band < v < band:
        return b if applied > b else (-b if applied < -b else applied)
    return b if v > 0.0 else -b


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


def rhs_for(params: PlantParams) -> Callable[[Sequence[float], float, PlantParams], tuple[float, ...]]:
    """The right-hand side function matching the parameter set's plant kind."""
    return double_mass_rhs if isinstance(params, DoubleMassParams) else single_mass_rhs


def quasi_static_current(x_mech: Sequence[float], v: float, params: PlantParams) -> float:
    """Armature current with the inductance neglected (La -> 0): (vA - emf * motor cart velocity) / Ra."""
    vA = params.amplifier_gain * clip_voltage(v, params.voltage_limit)
    return (vA - params.emf_per_velocity * x_mech[1]) / params.Ra


def rhs_no_inductance(x_mech: Sequence[float], v: float, params: PlantParams) -> tuple[float, ...]:
    """Mechanical right-hand side with the current eliminated (thesis App. A.2/B.3 models)."""
    i = quasi_static_current(x_mech, v, params)
    return rhs_for(params)((*x_mech, i), v, params)[:-1]


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
