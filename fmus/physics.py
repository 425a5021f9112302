"""Nonlinear IP02 plant dynamics, pure Python (no FMI import).

One source of truth for the plant FMUs, the virtual rig, the controller design and
the analysis tools. Each plant kind's equations are written in its own module
(``ipcosim.fmus.kinds.single_mass``, ``ipcosim.fmus.kinds.double_mass``) and re-exported here; the tables
and functions by kind (``MEASURED``, :func:`state_names`, :func:`rhs_for`) read the kind registry.

Equations (thesis 3.1, 3.8, 3.14, 3.18, 4.6, 4.15; theta is the pendulum angle, counter-clockwise
positive from upright):

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

from typing import TYPE_CHECKING, Callable, Sequence

from ipcosim.fmus import kinds
from ipcosim.fmus.kinds.common import clip_voltage, karnopp
from ipcosim.fmus.kinds.double_mass import double_mass_applied_forces, double_mass_rhs
from ipcosim.fmus.kinds.single_mass import (
    single_mass_applied_force,
    single_mass_from_momentum,
    single_mass_momentum_rhs,
    single_mass_rhs,
    single_mass_to_momentum,
)

if TYPE_CHECKING:
    from ipcosim.fmus.params import PlantParams

__all__ = ["clip_voltage", "karnopp", "double_mass_applied_forces", "double_mass_rhs", "single_mass_applied_force",
           "single_mass_from_momentum", "single_mass_momentum_rhs", "single_mass_rhs", "single_mass_to_momentum"]

STATE_UNITS = {"cart_position": "m", "cart_velocity": "m/s", "active_cart_position": "m",
               "active_cart_velocity": "m/s", "passive_cart_position": "m", "passive_cart_velocity": "m/s",
               "pendulum_angle": "rad", "pendulum_velocity": "rad/s", "motor_current": "A"}

#: Measured outputs (what the rig's encoders give), per plant kind (``ipcosim.fmus.kinds``).
MEASURED = kinds.ByKind(lambda k: k.measured)
#: Index of the motor-driven cart's position in the state, per plant kind.
MOTOR_CART = kinds.ByKind(lambda k: k.cart_indices[0][0])


def state_names(kind: str) -> tuple[str, ...]:
    """Names of the state variables of plant ``kind`` in state-vector order."""
    return kinds.get(kind).states


def rhs_for(params: PlantParams) -> Callable[[Sequence[float], float, PlantParams], tuple[float, ...]]:
    """The right-hand side function matching the parameter set's plant kind."""
    return kinds.of_params(params).rhs


def quasi_static_current(x_mech: Sequence[float], v: float, params: PlantParams) -> float:
    """Armature current with the inductance neglected (La -> 0): (vA - emf * motor cart velocity) / Ra."""
    vA = params.amplifier_gain * clip_voltage(v, params.voltage_limit)
    return (vA - params.emf_per_velocity * x_mech[1]) / params.Ra


def rhs_no_inductance(x_mech: Sequence[float], v: float, params: PlantParams) -> tuple[float, ...]:
    """Mechanical right-hand side with the current eliminated (thesis App. A.2/B.3 models)."""
    i = quasi_static_current(x_mech, v, params)
    return rhs_for(params)((*x_mech, i), v, params)[:-1]


