"""The LQG: discrete LQG with integral action and a one-sample computation delay (Kalman filter, design in
``ipcosim.controllers.lqg_design``), with Coulomb friction compensation; its parameters and sets, its gains as
parameters, its linear model and its registry entry."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from operator import mul
from typing import Any, Mapping, Sequence

from ipcosim.controllers.errors import DesignError
from ipcosim.controllers.laws.base import (
    CurrentEstimatorLaw,
    Designed,
    LawEntry,
    LawParameterError,
    ParamSpec,
    check_nonneg,
    check_positive,
    design_params_from,
    design_states,
    estimator_gain_specs,
    estimator_gains,
    fmu_message,
    fmu_name,
    model_specs,
    rest_state,
    right_inverse,
    sampled_model,
    state_dim,
    unit_div,
    zoh_lists,
)
from ipcosim.controllers.linear import Builder, Lin, lsum
from ipcosim.controllers.thesis import (
    THESIS_DOUBLE_MASS_Q_DIAGONAL,
    THESIS_SINGLE_MASS_Q_DIAGONAL,
    THESIS_SINGLE_MASS_R,
)
from ipcosim.fmus.expm import as_matrix
from ipcosim.fmus.kinds import ByKind, get
from ipcosim.fmus.linearize import linear_matrices
from ipcosim.fmus.physics import MEASURED


@dataclass(frozen=True)
class LQGCoefficients:
    """Everything the LQG law computes with, as plain floats (design-model state order).

    ``K`` (n), ``K_voltage``, ``K_integral``: the feedback ``u = -K (x^ - x_r r) - K_voltage v -
    K_integral q`` (``ipcosim.controllers.lqg_design``); ``M`` (n x p): the Kalman current-estimator gain;
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
        """The coefficients of an ``ipcosim.controllers.lqg_design.LQGDesign``."""
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
    """Discrete LQG with integral action and a one-sample computation delay (``ipcosim.controllers.lqg_design``).

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
        tau = check_nonneg("reference_time_constant", reference_time_constant)
        self.reference_pole = math.exp(-self.sample_period / tau) if tau > 0 else 0.0
        self.friction = tuple(check_nonneg("friction", b) for b in friction)
        if self.friction and len(self.friction) != len(coefficients.friction_states):
            raise LawParameterError("friction", f"need {len(coefficients.friction_states)} Coulomb forces (one per "
                                                f"cart of the friction model), got {len(self.friction)}")
        self.friction_velocity = check_positive("friction_velocity", friction_velocity)
        self.integrator_dead_band = check_nonneg("integrator_dead_band", integrator_dead_band)
        self.friction_breakaway_gain = check_nonneg("friction_breakaway_gain", friction_breakaway_gain)
        self.dither_amplitude = check_nonneg("dither_amplitude", dither_amplitude)
        self._Cpinv = right_inverse(coefficients.C)
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


# ============================================================================ parameters and sets

#: LQG weights (``ipcosim.controllers.lqg_design``; docs/controllers.md, "LQG", says how they were chosen): the
#: thesis's state weights (the double mass's passive-cart position weighted 40 instead of 19), Q_integral on
#: the integral of the motor-cart error, R on the voltage, and the Kalman filter's input-disturbance standard
#: deviation process_noise [V] and acceleration disturbance acceleration_noise [m/s^2]. The double mass's
#: acceleration_noise of 16 (3 before) widens the loop's gain range at the pendulum encoder, whose upper end a
#: short pendulum or a stiff spring crossed at about 4 Hz (docs/controllers.md, "Robustness at the pendulum
#: encoder").
TUNED_LQG: dict[str, dict[str, Any]] = {
    "single-mass": {"Q": THESIS_SINGLE_MASS_Q_DIAGONAL, "Q_integral": 3.0e7, "R": 180 * THESIS_SINGLE_MASS_R,
                    "process_noise": 0.3, "acceleration_noise": 0.0},
    "double-mass": {"Q": tuple(40.0 if i == 2 else q for i, q in enumerate(THESIS_DOUBLE_MASS_Q_DIAGONAL)),
                    "Q_integral": 1.0e4, "R": 0.4, "process_noise": 1.0, "acceleration_noise": 16.0},
}


#: The LQG's ``lab`` set: TUNED_LQG's design with the Coulomb friction compensation (``laws.coulomb_estimate``)
#: of the lab bench's fitted forces (``fmus.instruments.REALISM["lab"]``, as ``friction_<b>``): its threshold
#: friction_velocity [m/s] and the breakaway gain at rest (``friction_breakaway_gain``), chosen on the lab bench's
#: robustness runs (docs/controllers.md, "Coulomb friction compensation"); the single mass's dither_amplitude [V]
#: keeps its cart from sticking near rest (docs/controllers.md, "Dither").
LAB_LQG: dict[str, dict[str, float]] = {
    "single-mass": {"friction_velocity": 5e-4, "friction_breakaway_gain": 0.0, "dither_amplitude": 0.4},
    "double-mass": {"friction_velocity": 2e-3, "friction_breakaway_gain": 1.0},
}

#: The double mass's ``lab-soft`` set: the ``lab`` set with the voltage weight R 20 times the ``tuned`` one's.
#: The softer regulator kicks the motor cart less at each pendulum count edge, and the friction cycle it
#: leaves on the lab bench with every spread is smaller (docs/controllers.md, "Shrinking the cycle").
LAB_SOFT_LQG: dict[str, dict[str, float]] = {"double-mass": {"R": 8.0}}


def _lqg_specs(kind: str) -> list[ParamSpec]:
    from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT  # noqa: PLC0415

    specs = [ParamSpec(f"Q_{s}", 0.0, unit_div({}, {b: 2 * e for b, e in state_dim(s).items()}),
                       f"LQG state weight on {s} (diagonal of Q, on x - x_r r)", "nonnegative")
             for s in design_states(kind)]
    specs += [ParamSpec("Q_integral", 1.0, "1/m2.s2", "LQG weight on the integral of the motor-cart position error "
                                                      "(> 0: the integrator must be weighted to be stabilized)",
                        "positive"),
              ParamSpec("R", 1.0, "1/V2", "LQG input weight", "positive"),
              ParamSpec("process_noise", 1.0, "V", "Kalman filter: standard deviation of the voltage-equivalent "
                                                   "input disturbance (held over a sample)", "positive"),
              ParamSpec("reference_time_constant", 1.0, "s", "the law follows the reference through "
                                                              "1/(tau s + 1), started at the measured motor-cart "
                                                              "position (0 = the reference as given)", "nonnegative"),
              ParamSpec("acceleration_noise", 0.0, "m/s2", "Kalman filter: standard deviation of an acceleration "
                                                           "disturbance on every body (rad/s2 on the pendulum), held "
                                                           "over a sample", "nonnegative")]
    for o in MEASURED[kind]:
        res = PENDULUM_RAD_PER_COUNT if o == "pendulum_angle" else CART_M_PER_COUNT
        specs.append(ParamSpec(f"resolution_{o}", res, "rad" if o == "pendulum_angle" else "m",
                               f"Kalman filter: encoder resolution of the {o}; noise variance resolution^2/12",
                               "positive"))
    return specs + _lqg_friction_specs(kind)


#: The LQG's Coulomb friction compensation, one force per cart (the plant's names b; b1, b2 after "friction_").
LQG_FRICTION = ByKind(lambda k: tuple(f"friction_{cart.coulomb}" for cart in k.carts))


def _lab_lqg(kind: str) -> dict[str, float]:
    """The values of the LQG's ``lab`` set beyond the design (``LAB_LQG`` and the lab bench's Coulomb forces)."""
    from ipcosim.fmus.instruments import REALISM  # noqa: PLC0415

    lab = REALISM["lab"][kind]
    return {**{n: float(lab[n[len("friction_"):]]) for n in LQG_FRICTION[kind]}, **LAB_LQG[kind]}  # type: ignore[index]


def _lqg_friction_specs(kind: str) -> list[ParamSpec]:
    """The LQG parameters that act at run time only (no redesign): friction compensation, integrator dead band."""
    carts = [cart.position.removesuffix("_position").replace("_", " ") for cart in get(kind).carts]
    specs = [ParamSpec(name, 0.0, "N", f"Coulomb force the law compensates on the {cart} (0 = no compensation; "
                                       "the lab set: the lab bench's fitted value)", "nonnegative")
             for name, cart in zip(LQG_FRICTION[kind], carts)]
    return specs + [ParamSpec("friction_velocity", 2e-3, "m/s", "friction compensation: none below this estimated "
                                                                "cart speed, full above twice it, linear between",
                              "positive"),
                    ParamSpec("friction_breakaway_gain", 0.0, "1", "friction compensation of a cart near rest: "
                                                                   "this times the net force the loop's "
                                                                   "frictionless model puts on it, up to its Coulomb "
                                                                   "force (0 = none)", "nonnegative"),
                    ParamSpec("integrator_dead_band", 0.0, "m", "the integral ignores this much of the motor-cart "
                                                                "position error (0 = none)", "nonnegative"),
                    ParamSpec("dither_amplitude", 0.0, "V", "square wave at half the sample rate added to the "
                                                            "voltage, so a cart near rest does not stick (0 = none)",
                              "nonnegative")]


#: LQG parameters that act at run time, not through the design.
def lqg_runtime_parameters(kind: str) -> tuple[str, ...]:
    """The LQG parameters a changed value of which needs no redesign."""
    return ("reference_time_constant", *(s.name for s in _lqg_friction_specs(kind)))


def _lqg_values(kind: str, parameter_set: str) -> dict[str, Any]:
    t = TUNED_LQG[kind]
    v: dict[str, Any] = {f"Q_{s}": float(q) for s, q in zip(design_states(kind), t["Q"])}
    v.update({k: float(t[k]) for k in ("Q_integral", "R", "process_noise", "acceleration_noise")})
    if parameter_set in ("lab", "lab-soft"):
        v.update(_lab_lqg(kind))
    return {**v, **(LAB_SOFT_LQG[kind] if parameter_set == "lab-soft" else {})}


def lqg_weight_parameters(kind: str) -> tuple[str, ...]:
    """The LQG parameters that enter only through the design (weights, noises, resolutions)."""
    return tuple(s.name for s in _lqg_specs(kind) if s.name not in lqg_runtime_parameters(kind))


# ============================================================================ design and gains

def lqg_design_from(kind: str, v: Mapping[str, Any], backend: str = "control"):
    """The LQG design the flat values describe (``ipcosim.controllers.lqg_design.design_lqg``; the design stack
    is imported here)."""
    import numpy as np  # noqa: PLC0415 -- the design stack, imported only to design

    from ipcosim.controllers.design import design_model  # noqa: PLC0415
    from ipcosim.controllers.lqg_design import design_lqg  # noqa: PLC0415

    Q = np.diag([float(v[f"Q_{s}"]) for s in design_states(kind)])
    try:
        return design_lqg(design_model(design_params_from(kind, v)), Q, float(v["Q_integral"]), float(v["R"]),
                          sample_period=float(v["sample_period"]), process_noise=float(v["process_noise"]),
                          acceleration_noise=float(v["acceleration_noise"]),
                          resolutions=[float(v[f"resolution_{o}"]) for o in MEASURED[kind]], backend=backend)
    except DesignError as exc:
        raise DesignError(fmu_name(exc.parameter, kind), fmu_message(exc, kind)) from None


def lqg_gain_specs(kind: str) -> list[ParamSpec]:
    """The LQG's gains as flat parameters: ``K_<state>``, ``K_voltage``, ``K_integral`` and the Kalman
    current-estimator gain ``M_<state>_<output>`` (``ipcosim.controllers.laws.LQGCoefficients``)."""
    states = design_states(kind)
    law = "u = -K (x^ - x_r r) - K_voltage v - K_integral q"
    specs = [ParamSpec(f"K_{s}", 0.0, unit_div({"V": 1}, state_dim(s)), f"LQG gain on the estimated {s} ({law})")
             for s in states]
    specs += [ParamSpec("K_voltage", 0.0, "1", f"LQG gain on the voltage v being applied, computed a sample "
                                              f"earlier ({law})"),
              ParamSpec("K_integral", 0.0, "V/m.s", f"LQG gain on the integral q of the motor-cart position "
                                                   f"error ({law})")]
    return specs + estimator_gain_specs(states, MEASURED[kind])


def lqg_gains(law: LQG) -> dict[str, float]:
    """``{K_<state>, K_voltage, K_integral, M_<state>_<output>: value}`` of an LQG law."""
    c = law.coefficients
    out = {f"K_{s}": k for s, k in zip(c.states, c.K)}
    out.update(K_voltage=c.K_voltage, K_integral=c.K_integral, **estimator_gains(c))
    return out


def lqg_from_gains(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> LQG:
    """An LQG law from flat values and given gains, in plain Python (as ``lqr_from_gains``)."""
    m = sampled_model(kind, values, gains)
    coef = LQGCoefficients(K=tuple(float(gains[f"K_{s}"]) for s in m["states"]), K_voltage=float(gains["K_voltage"]),
                           K_integral=float(gains["K_integral"]), reference_states=rest_state(m["states"]), **m)
    return _lqg_law(kind, coef, values)


def coulomb_model(kind: str, values: Mapping[str, Any]) -> dict[str, Any]:
    """The Coulomb friction model of the LQG (``LQGCoefficients.friction_*``, ``volts_per_newton``) for the
    ``model_*`` values and ``sample_period``, in plain Python.

    A force on the motor cart acts as the voltage ``force / (force_per_amp / Ra)`` does (the design model has
    no inductance). The active cart's position enters the passive cart's and the pendulum's equations only
    through the spring force ``K (x_a - x_p)``, so a force of 1 N on the passive cart acts there as the column
    ``A[:, x_a] / K`` (without the active cart's own row), and the loop holds it with the motor cart leading
    by ``1 / K`` per newton.
    """
    p = design_params_from(kind, values)
    A, B, states, _ = linear_matrices(p, inductance=False)
    T = float(values["sample_period"])
    per_newton = p.Ra / p.force_per_amp
    carts = [i for i, s in enumerate(states) if s.endswith("cart_velocity")]
    forces = [[b * per_newton for b in B]]
    leads = [[0.0] * len(states)]
    if len(get(kind).carts) > 1:  # the pendulum's cart, coupled to the motor's by the spring K
        ia = states.index(get(kind).carts[0].position)
        forces.append([0.0 if i == carts[0] else row[ia] / p.K for i, row in enumerate(A)])
        leads.append([1.0 / p.K if i == ia else 0.0 for i in range(len(states))])
    columns = tuple(tuple(zoh_lists(A, f, T)[1]) for f in forces)
    return dict(friction_states=tuple(carts), friction_columns=columns, friction_leads=tuple(map(tuple, leads)),
                volts_per_newton=per_newton)


def _lqg_law(kind: str, coef: LQGCoefficients, values: Mapping[str, Any]) -> LQG:
    """The LQG law of ``coef`` with its friction model and the run-time parameters of ``values``."""
    return LQG(kind, replace(coef, **coulomb_model(kind, values)), float(values["voltage_limit"]),
               float(values["reference_time_constant"]), [float(values[n]) for n in LQG_FRICTION[kind]],
               float(values["friction_velocity"]), float(values["integrator_dead_band"]),
               float(values["friction_breakaway_gain"]), float(values["dither_amplitude"]))


def _build_lqg(kind: str, v: Mapping[str, Any], backend: str) -> LQG:
    return _lqg_law(kind, LQGCoefficients.from_design(lqg_design_from(kind, v, backend)), v)


# ============================================================================ linear model

def linear_lqg(law: LQG, b: Builder) -> tuple[Lin, list[str]]:
    d, T = law.coefficients, law.sample_period
    p, n = len(law.measured), len(d.states)
    ys = [b.input(j) for j in range(p)]
    xp, applied, integral = [b.state() for _ in range(n)], b.state(), b.state()
    innov = [ys[j] - lsum([xp[i] * d.C[j][i] for i in range(n)]) for j in range(p)]
    xh = [xp[i] + lsum([innov[j] * d.M[i][j] for j in range(p)]) for i in range(n)]
    free = [lsum([xh[j] * d.Ad[i][j] for j in range(n)]) + applied * d.Bd[i] for i in range(n)]
    g = law.friction_breakaway_gain
    forces = [((free[i] - xh[i]) * (g / col[i]), col, lead)  # the breakaway term's slope g at rest
              for i, f, col, lead in zip(d.friction_states, law.friction, d.friction_columns, d.friction_leads)
              if g and f > 0]
    u = lsum([xh[i] * -d.K[i] for i in range(n)]) - applied * d.K_voltage - integral * d.K_integral
    u = lsum([u] + [f * (d.volts_per_newton + sum(k * g for k, g in zip(d.K, lead))) for f, _, lead in forces])
    for i in range(n):
        b.feed(xp[i], lsum([free[i]] + [f * -col[i] for f, col, _ in forces]))
    b.feed(applied, u)
    b.feed(integral, integral - ys[0] * T)
    notes = ["output: the voltage computed a sample earlier (one-sample computation delay)",
             "reference lag left out (the reference is 0)"]
    if any(law.friction):
        notes.append(f"Coulomb friction compensation of a sliding cart left out (zero below "
                     f"{law.friction_velocity:g} m/s: no small-signal slope)"
                     + (f"; its breakaway term at rest kept (slope {g:g} on the demand)" if forces else ""))
    if law.integrator_dead_band:
        notes.append(f"integrator dead band of {law.integrator_dead_band:g} m left out")
    if law.dither_amplitude:
        notes.append(f"dither of {law.dither_amplitude:g} V at half the sample rate left out (an input, not feedback)")
    return applied, notes


# not in the thesis: discrete LQG with integral action (ipcosim.controllers.lqg_design), weights TUNED_LQG;
# lab: the same design with the Coulomb friction compensation of LAB_LQG (for a plant with friction);
# lab-soft: the lab set with the voltage weight of LAB_SOFT_LQG
LQG_LAW = LawEntry("LQG", {"single-mass": ("tuned", "lab"), "double-mass": ("tuned", "lab", "lab-soft")},
                   lambda kind: _lqg_specs(kind) + model_specs(kind), _lqg_values, _build_lqg, classes=(LQG,),
                   model_based=True, designed=Designed(lqg_gain_specs, lqg_weight_parameters, lqg_gains,
                                                       lqg_from_gains), linear=linear_lqg)
