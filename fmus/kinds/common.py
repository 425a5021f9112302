"""What every plant kind's module builds on: the registry entry (:class:`PlantKind`), the motor, gearbox
and amplifier parameters every IP02 plant shares (:class:`MotorParams`), and the D/A range and the stick-slip
friction of ``ipcosim.fmus.physics``.

Pure Python, standard library only; imports no kind (the kinds import it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from operator import attrgetter
from typing import Any, Callable, Mapping, Sequence


@dataclass(frozen=True)
class Cart:
    """One cart of a plant: its position and velocity states, its Coulomb-friction parameter, for a cart
    that does not carry the pendulum the parameter of its equivalent mass (what a force on it accelerates),
    and the parameter of the viscous damping between it and the track (``""``: none declared)."""

    position: str
    velocity: str
    coulomb: str
    mass: str = ""
    damping: str = ""


@dataclass(frozen=True)
class InternalForm:
    """A state the integrator advances instead of the plant's own (the single mass's momenta).

    ``to_internal(x, p)`` maps the plant state to it, ``rhs(z, v, p)`` is its time derivative (the
    physics' form: the integrator's Jacobian is taken on it), ``output_map(p)`` returns the map back
    to the plant state with the parameters folded into constants.
    """

    to_internal: Callable[..., Sequence[Any]]
    rhs: Callable[..., tuple[Any, ...]]
    output_map: Callable[[Any], Callable[[Sequence[Any]], Sequence[Any]]]


@dataclass(frozen=True)
class PlantKind:
    """One plant kind, as its module declares it.

    Attributes
    ----------
    name : str
        The kind's name (``single-mass``), the word of scenario names.
    suffix : str
        The FMU model names' suffix: the plant ``IP02<suffix>``, its adapter ``IP02HIL<suffix>``, a law's
        ``<Law><suffix>``.
    description : str
        A few words for scenario descriptions (``single-mass cart``).
    params : type
        Its parameter dataclass (``ipcosim.fmus.params``); one class per kind.
    presets : mapping
        Named parameter presets: name -> (overrides of the class defaults, one-line description); the
        first is the default (the plant FMU's parameter defaults).
    states : tuple of str
        State names in state-vector order, the motor current last.
    measured : tuple of str
        The encoder-measured outputs, in the order the laws receive them.
    carts : tuple of Cart
        The carts, the motor-driven one first, the one carrying the pendulum last.
    rhs : callable
        ``rhs(x, v, p)``: the time derivative of the state for the commanded voltage ``v`` [V].
    applied_forces : callable
        ``applied_forces(x, p)``: per cart, the force [N] besides Coulomb friction that its friction must
        balance for it to stick (``carts`` order).
    folded_rhs : callable
        ``folded_rhs(p)``: ``f(*z, vA)``, the integrator's right-hand side with the parameters folded into
        constants and the voltage clipped and amplified (on ``internal``'s state when there is one).
    pendulum_mass_matrix : callable
        ``pendulum_mass_matrix(th, p)``: ``(m11, m12, m22)``, the mass matrix of the cart carrying the pendulum
        and the pendulum at angle ``th`` (the taps' velocity jumps).
    internal : InternalForm or None
        The state the integrator advances, None: the plant state itself.
    kernels : mapping
        Stand-alone native kernels: C function name -> physics function ``(x, v, p)``.
    identified : tuple of str
        The parameters an identification estimates by default (``ipcosim.harness.studies.identify``).
    """

    name: str
    suffix: str
    description: str
    params: type
    presets: Mapping[str, tuple[dict[str, float], str]]
    states: tuple[str, ...]
    measured: tuple[str, ...]
    carts: tuple[Cart, ...]
    rhs: Callable[..., tuple[Any, ...]]
    applied_forces: Callable[..., tuple[Any, ...]]
    folded_rhs: Callable[[Any], Callable[..., tuple[Any, ...]]]
    pendulum_mass_matrix: Callable[[Any, Any], tuple[Any, Any, Any]]
    internal: InternalForm | None = None
    kernels: Mapping[str, Callable[..., tuple[Any, ...]]] = field(default_factory=dict)
    identified: tuple[str, ...] = ()

    @property
    def model(self) -> str:
        """Model name of the plant FMU (``IP02SingleMass``)."""
        return f"IP02{self.suffix}"

    @property
    def hil_model(self) -> str:
        """Model name of the plant's HIL adapter FMU (``IP02HILSingleMass``)."""
        return f"IP02HIL{self.suffix}"

    @property
    def default_preset(self) -> str:
        """The default preset's name (the first of ``presets``)."""
        return next(iter(self.presets))

    @cached_property
    def cart_indices(self) -> tuple[tuple[int, int], ...]:
        """(position, velocity) state indices of each cart."""
        return tuple((self.states.index(c.position), self.states.index(c.velocity)) for c in self.carts)

    @cached_property
    def pendulum_cart_reading(self) -> int:
        """Index in ``measured`` of the position of the cart carrying the pendulum."""
        return self.measured.index(self.carts[-1].position)

    @cached_property
    def coulomb_forces(self) -> Callable[[Any], tuple[float, ...]]:
        """``coulomb_forces(p)``: the Coulomb (breakaway) force of each cart [N] in parameter set ``p``."""
        get = attrgetter(*(c.coulomb for c in self.carts))
        return get if len(self.carts) > 1 else lambda p: (get(p),)


def _p(default: float, unit: str, doc: str, source: str, positive: bool = False,
       nonnegative: bool = False) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc, "source": source,
                                            "positive": positive, "nonnegative": nonnegative})


#: A parameter field with its unit, description and source (what the kinds' parameter classes are made of).
param_field = _p


@dataclass(frozen=True)
class MotorParams:
    """Parameters shared by both plants: DC motor, gearbox, pinion, amplifier, gravity."""

    Ra: float = _p(2.6, "Ohm", "armature resistance", "IP02", positive=True)
    La: float = _p(1.8e-4, "H", "armature inductance", "IP02", positive=True)
    Kt: float = _p(7.68e-3, "N.m/A", "motor torque constant", "IP02", positive=True)
    Kb: float = _p(7.68e-3, "V.s/rad", "motor back-EMF constant", "IP02", positive=True)
    Jm: float = _p(3.9e-7, "kg.m2", "rotor moment of inertia", "IP02", nonnegative=True)
    N: float = _p(3.71, "1", "planetary gearbox ratio", "IP02", positive=True)
    rg: float = _p(6.35e-3, "m", "motor pinion radius", "IP02", positive=True)
    g: float = _p(9.81, "m/s2", "gravitational acceleration", "thesis", positive=True)
    voltage_limit: float = _p(10.0, "V", "amplifier/DAC output range: input is clipped to +-voltage_limit",
                              "Q4 data sheet", positive=True)
    coulomb_velocity: float = _p(1e-3, "m/s",
                                 "stick band of the stick-slip Coulomb friction: |v| below it sticks (Karnopp)",
                                 "assumed", positive=True)
    amplifier_gain: float = _p(1.0, "1", "power amplifier's voltage gain: the motor sees amplifier_gain times the "
                                    "clipped command", "IP02 (UPM amplifier, gain 1)", positive=True)

    @property
    def reflected_inertia(self) -> float:
        """Rotor inertia seen at the cart, Jm N^2 / rg^2 [kg]."""
        return self.Jm * self.N ** 2 / self.rg ** 2

    @property
    def force_per_amp(self) -> float:
        """Cart force per armature amp, N Kt / rg [N/A]."""
        return self.N * self.Kt / self.rg

    @property
    def emf_per_velocity(self) -> float:
        """Back-EMF per cart velocity, N Kb / rg [V.s/m]."""
        return self.N * self.Kb / self.rg


def clip_voltage(v: float, limit: float) -> float:
    """The D/A converter's range: the command clipped to +-limit (the amplifier then multiplies it by
    ``amplifier_gain``)."""
    return limit if v > limit else (-limit if v < -limit else v)


def pendulum_cart_mass_matrix(cart_mass: float, th: float, p: Any) -> tuple[float, float, float]:
    """``(m11, m12, m22)``: the mass matrix of a cart of equivalent mass ``cart_mass`` carrying the IP02's
    pendulum (``p.Mp``, ``p.Lp``, a uniform rod pivoted at its end) upright at angle ``th`` (the taps)."""
    ml = 0.5 * p.Mp * p.Lp
    m11 = cart_mass + p.Mp
    return m11, -ml * math.cos(th), p.Mp * p.Lp * p.Lp / 3.0


def karnopp(v: float, applied: float, b: float, band: float) -> float:
    """Karnopp's stick-slip Coulomb force [N] on a cart at velocity ``v`` [m/s] under ``applied`` force [N].

    Kinetic ``b sign(v)`` for ``|v| >= band``; inside the band the force that cancels ``applied``,
    saturated at the breakaway force ``b`` (Karnopp 1985, module docstring).
    """
    if -band < v < band:
        return b if applied > b else (-b if applied < -b else applied)
    return b if v > 0.0 else -b
