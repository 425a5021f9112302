"""A third plant kind, for the registry's test: the IP02 cart with its pendulum hanging (a gantry crane).

The single-mass cart and pendulum with the angle measured counter-clockwise from hanging straight down:
pendulum centre of mass at ``(xc + l sin th, -l cos th)``, ``l = Lp/2``; Lagrange's equations give::

    La i'  = vA - Ra i - (N Kb / rg) xc'
    (Meq + Mp) xc'' + (Mp l) cos(th) th'' - (Mp l) th'^2 sin(th) + Beq xc' + fc(xc') = (N Kt / rg) i
    (Mp Lp^2/3) th'' + (Mp l) cos(th) xc'' + Bp th' + Mp g l sin(th) = 0

(the upright single mass's equations with ``th`` replaced by ``th + pi``). Written from these equations
alone; it imports only what every kind builds on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from ipcosim.fmus.kinds.common import Cart, MotorParams, PlantKind, clip_voltage, karnopp
from ipcosim.fmus.kinds.common import param_field as _p


@dataclass(frozen=True)
class CraneParams(MotorParams):
    """IP02 cart with the pendulum hanging below it."""

    Mc: float = _p(0.961373, "kg", "cart mass", "IP02 single mass", positive=True)
    Mp: float = _p(0.2303, "kg", "pendulum mass", "IP02 single mass", positive=True)
    Lp: float = _p(0.3371, "m", "full pendulum length (pivot to tip)", "IP02 single mass", positive=True)
    Beq: float = _p(11.55, "N.s/m", "viscous damping seen by the cart", "IP02 single mass", nonnegative=True)
    Bp: float = _p(0.0024, "N.m.s/rad", "viscous damping at the pivot", "IP02 single mass", nonnegative=True)
    b: float = _p(0.0, "N", "Coulomb friction force on the cart", "assumed", nonnegative=True)

    @property
    def Meq(self) -> float:
        """Equivalent cart mass including reflected rotor inertia [kg]."""
        return self.Mc + self.reflected_inertia


def crane_mass_matrix(th: float, p: CraneParams) -> tuple[float, float, float]:
    """``(m11, m12, m22)`` of the cart and the hanging pendulum at angle ``th``."""
    return p.Meq + p.Mp, 0.5 * p.Mp * p.Lp * math.cos(th), p.Mp * p.Lp * p.Lp / 3.0


def _forces(x: Sequence[float], p: CraneParams) -> tuple[float, float]:
    """The generalized forces on the cart and on the pendulum, Coulomb friction left out."""
    _, xd, th, thd, i = x
    ml = 0.5 * p.Mp * p.Lp
    return (p.force_per_amp * i + ml * thd * thd * math.sin(th) - p.Beq * xd,
            -ml * p.g * math.sin(th) - p.Bp * thd)


def crane_applied_forces(x: Sequence[float], p: CraneParams) -> tuple[float]:
    """The force on the cart [N] its friction balances when it sticks (zero cart acceleration)."""
    m11, m12, m22 = crane_mass_matrix(x[2], p)
    r1, r2 = _forces(x, p)
    return (r1 - m12 * r2 / m22,)


def crane_motion(x: Sequence[float], vA: float, p: CraneParams) -> tuple[float, ...]:
    """The state derivative for the amplified motor voltage ``vA`` [V]."""
    _, xd, th, thd, i = x
    m11, m12, m22 = crane_mass_matrix(th, p)
    r1, r2 = _forces(x, p)
    r1 -= karnopp(xd, crane_applied_forces(x, p)[0], p.b, p.coulomb_velocity) if p.b else 0.0
    det = m11 * m22 - m12 * m12
    return (xd, (m22 * r1 - m12 * r2) / det, thd, (m11 * r2 - m12 * r1) / det,
            (vA - p.Ra * i - p.emf_per_velocity * xd) / p.La)


def crane_rhs(x: Sequence[float], v: float, p: CraneParams) -> tuple[float, ...]:
    """The state derivative of ``[xc, xc', th, th', i]`` for the commanded voltage ``v`` [V]."""
    return crane_motion(x, p.amplifier_gain * clip_voltage(v, p.voltage_limit), p)


def crane_folded_rhs(p: CraneParams) -> Callable[..., tuple[float, ...]]:
    """``f(xc, xc', th, th', i, vA)`` for the integrator."""
    return lambda *z: crane_motion(z[:-1], z[-1], p)


KIND = PlantKind(
    name="crane", suffix="Crane", description="cart with a hanging pendulum (gantry crane)", params=CraneParams,
    presets={"crane-long": ({"Lp": 0.6413}, "long pendulum hanging"), "crane-medium": ({}, "medium pendulum")},
    states=("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity", "motor_current"),
    measured=("cart_position", "pendulum_angle"),
    carts=(Cart("cart_position", "cart_velocity", "b"),),
    rhs=crane_rhs, applied_forces=crane_applied_forces, folded_rhs=crane_folded_rhs,
    pendulum_mass_matrix=crane_mass_matrix, kernels={"crane_rhs": crane_rhs},
)
