"""The plant as a hybrid system for a variable-step solver (the native plants' model exchange).

A fixed-step integrator never lands on the instant a cart's velocity crosses zero, so the
co-simulation plant (``ipcosim.fmus.plant``) approximates Coulomb friction with Karnopp's band
``|v| < coulomb_velocity`` (``ipcosim.fmus.physics.karnopp``) and applies stiction and the end stops
after each step (``plant.constrain``). A solver with event location needs neither: each cart has a
*mode*, a discrete state that only changes at events,

* ``+1`` / ``-1``: sliding forwards / backwards, kinetic friction ``b * mode``;
* ``0``: at rest, held by static friction (within the breakaway force ``b``) or by an end stop (any
  force pushing outwards); its velocity is 0 and the holding force equals the applied force
  (``physics.single_mass_applied_force``, ``double_mass_applied_forces``), so it does not accelerate.

Two event indicators per cart say when its mode must change (:func:`cart_indicators`): a sliding
cart's velocity in its direction of motion (reaching 0: it stops or reverses) and its distance to the
end stop; a resting cart's margin of the applied force to what holds it. At an event,
:func:`settle_cart` stops a cart at an end stop (inelastic, as ``instruments.stop_carts``) and
chooses its new mode from the force at rest. The right-hand side is the frictionless physics
(``physics.rhs_for``) with each cart's friction force added through the mass matrix
(:func:`derivatives`). With no Coulomb friction and no end stops every indicator is constant and the
model is ``physics.rhs_for`` itself.

Plain arithmetic and comparisons on floats: the native generator traces these functions into C.
"""
from __future__ import annotations

import copy
from typing import Any, Sequence

from ipcosim.fmus import kinds
from ipcosim.fmus.params import PlantParams, plant_kind_of
from ipcosim.fmus.physics import rhs_for
from ipcosim.fmus.plant import CARTS, coulomb_forces

#: The mode of a cart before the first event: taken from its velocity and the force on it (:func:`settle_cart`).
UNKNOWN = 2.0
#: The Coulomb friction parameter of each cart, ``CARTS`` order (the plant kind's, ``ipcosim.fmus.kinds``).
COULOMB_FIELDS = kinds.ByKind(lambda k: tuple(cart.coulomb for cart in k.carts))


def frictionless(p: PlantParams) -> PlantParams:
    """A copy of ``p`` without Coulomb friction (every breakaway force 0)."""
    q = copy.copy(p)
    for name in COULOMB_FIELDS[plant_kind_of(p)]:
        object.__setattr__(q, name, 0.0)
    return q


def applied_forces(kind: str, x: Sequence[Any], p: PlantParams) -> tuple[Any, ...]:
    """Force on each cart besides Coulomb friction [N] (``CARTS`` order), as ``ipcosim.fmus.physics``
    defines it: what its friction (or an end stop) must balance for it to stay at rest."""
    return kinds.get(kind).applied_forces(x, p)


def cart_force(mode: Any, applied: Any, b: Any) -> Any:
    """The force that friction and the end stop exert on a cart [N], opposing its motion: kinetic
    ``b * mode`` while sliding, the applied force itself at rest (mode 0)."""
    return applied if mode == 0.0 else b * mode


def friction_response(kind: str, x: Sequence[Any], p: PlantParams, forces: Sequence[Any]) -> list[Any]:
    """Change of the state derivative by the carts' friction ``forces`` [N] (each opposing the motion):
    through the inverse mass matrix of ``physics.single_mass_rhs`` / ``double_mass_rhs``, where each
    enters as ``-f`` in its cart's force balance."""
    plant = kinds.get(kind)
    names = plant.states
    out: list[Any] = [0.0] * len(names)
    *others, carrier = plant.carts  # the cart carrying the pendulum is the last
    for cart, f in zip(others, forces):
        out[names.index(cart.velocity)] = -f / getattr(p, cart.mass)
    m11, m12, m22 = plant.pendulum_mass_matrix(x[names.index("pendulum_angle")], p)
    det = m11 * m22 - m12 * m12
    f = forces[-1]
    out[names.index(carrier.velocity)] = -(m22 * f) / det
    out[names.index("pendulum_velocity")] = m12 * f / det
    return out


def derivatives(x: Sequence[Any], v: Any, p: PlantParams, modes: Sequence[Any]) -> list[Any]:
    """Time derivative of the state ``x`` (``physics.state_names`` order) for voltage ``v`` [V] with the
    carts in ``modes``: a resting cart neither moves nor accelerates."""
    kind = plant_kind_of(p)
    free = rhs_for(p)(x, v, frictionless(p))  # type: ignore[arg-type]
    forces = [cart_force(m, a, b) for m, a, b in zip(modes, applied_forces(kind, x, p), coulomb_forces(p))]
    out = [d + r for d, r in zip(free, friction_response(kind, x, p, forces))]
    for (ip, iv), m in zip(CARTS[kind], modes):
        out[ip] = 0.0 if m == 0.0 else out[ip]
        out[iv] = 0.0 if m == 0.0 else out[iv]
    return out


def stop_side(pos: Any, end_stop: Any) -> float:
    """``+1`` / ``-1`` for a cart at or beyond the end stop ``+end_stop`` / ``-end_stop``, else 0
    (0 = no end stops)."""
    if end_stop > 0.0 and pos >= end_stop:
        return 1.0
    if end_stop > 0.0 and pos <= -end_stop:
        return -1.0
    return 0.0


def holds(applied: Any, b: Any, side: Any) -> bool:
    """Whether a cart at rest stays there under ``applied`` [N]: static friction below ``b`` holds it
    either way, an end stop (``side``) any force pushing outwards. At the breakaway force itself the cart
    slides: a solver locates the event where the margin (:func:`cart_indicators`) has reached zero."""
    if side > 0.0:
        return applied > -b
    if side < 0.0:
        return applied < b
    return b > 0.0 and -b < applied < b


def cart_indicators(pos: Any, vel: Any, mode: Any, applied: Any, b: Any, end_stop: Any) -> tuple[Any, Any]:
    """The cart's two event indicators (an event where one changes sign): a sliding cart's velocity along
    its mode (only with Coulomb friction; a frictionless cart reverses without an event) and its distance to
    the end stops; a resting cart's margin of ``applied`` to what holds it (1.0: nothing to watch)."""
    if mode == 0.0:
        side = stop_side(pos, end_stop)
        margin = applied + b if side > 0.0 else (b - applied if side < 0.0 else b - abs(applied))
        return margin, 1.0
    sliding = vel * mode if b > 0.0 else 1.0
    return sliding, (end_stop - abs(pos) if end_stop > 0.0 else 1.0)


def clamp_cart(pos: Any, vel: Any, end_stop: Any) -> tuple[Any, Any]:
    """(position, velocity) after the end stops: a cart beyond one is put on it and its outward velocity is
    lost (inelastic, as ``ipcosim.fmus.instruments.stop_carts``)."""
    side = stop_side(pos, end_stop)
    if side == 0.0:
        return pos, vel
    return side * end_stop, (0.0 if vel * side > 0.0 else vel)


def settle_cart(vel: Any, mode: Any, applied: Any, b: Any, side: Any) -> tuple[Any, Any]:
    """(velocity, mode) of a cart at an event: a sliding cart whose velocity has reached zero along its mode
    comes to rest; a cart at rest stays there if it :func:`holds`, else slides the way ``applied`` (the force
    on it at rest) pushes. A cart of mode :data:`UNKNOWN` (before the first event) takes its mode from its
    velocity, or from the force when it is still."""
    if mode == 0.0 or (mode * mode == 1.0 and b > 0.0 and vel * mode <= 0.0):
        vel = 0.0  # at rest (a solver's rounding aside), or come to rest
    if vel != 0.0:
        return vel, (1.0 if vel > 0.0 else -1.0)
    if holds(applied, b, side):
        return 0.0, 0.0
    return 0.0, (1.0 if applied > 0.0 else -1.0)


def settle(x: Sequence[Any], p: PlantParams, modes: Sequence[Any], end_stop: Any) -> tuple[list[Any], list[Any]]:
    """(state, modes) after one pass of the event iteration: each cart in turn against the end stops
    (:func:`clamp_cart`), then its mode from the force on it at rest (:func:`settle_cart`). Repeated until
    nothing changes (the host's event iteration); at rest, a second pass changes nothing."""
    kind = plant_kind_of(p)
    out, new_modes = list(x), []
    for k, ((ip, iv), b, m) in enumerate(zip(CARTS[kind], coulomb_forces(p), modes)):
        out[ip], out[iv] = clamp_cart(out[ip], out[iv], end_stop)
        rest = list(out)
        rest[iv] = 0.0
        out[iv], mode = settle_cart(out[iv], m, applied_forces(kind, rest, p)[k], b, stop_side(out[ip], end_stop))
        new_modes.append(mode)
    return out, new_modes


def indicators(x: Sequence[Any], p: PlantParams, modes: Sequence[Any], end_stop: Any) -> list[Any]:
    """Every event indicator, two per cart (``CARTS`` order; :func:`cart_indicators`)."""
    kind = plant_kind_of(p)
    applied = applied_forces(kind, x, p)
    out: list[Any] = []
    for k, ((ip, iv), b, m) in enumerate(zip(CARTS[kind], coulomb_forces(p), modes)):
        out.extend(cart_indicators(x[ip], x[iv], m, applied[k], b, end_stop))
    return out
