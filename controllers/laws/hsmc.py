"""The hierarchical sliding-mode laws (thesis 3.2.3 / 4.2.3) and their adaptive variant with scheduled gains
(3.2.4 / 4.2.4): the laws, their subsystem models (the thesis's App. A.5 / B.5 constants or the design model's
linearization), their parameters and sets, their linear models and their registry entries. Their numbers (gain
types, the thesis's constants, the tuned sets) are :mod:`ipcosim.controllers.laws.hsmc_numbers`."""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from ipcosim.controllers.laws.base import (
    DiscreteLaw,
    FilteredDerivative,
    LawEntry,
    LawParameterError,
    ParamSpec,
    check_finite,
    check_nonneg,
    check_positive,
    design_params_from,
    design_states,
    dot,
    model_specs,
    state_dim,
    unit_div,
)
from ipcosim.controllers.laws.hsmc_numbers import (  # noqa: F401 -- the law's numbers, importable from here too
    THESIS_A5,
    THESIS_B5,
    THESIS_HSMC,
    TUNED_ADAPTIVE,
    TUNED_HSMC,
    TUNED_HSMC_ON_THESIS_COEFFICIENTS,
    AdaptiveSchedules,
    HSMCGains,
    Schedule,
    SubsystemModel,
    ThesisHSMC,
    models_from_coefficients,
    thesis_adaptive,
    thesis_coefficients,
    thesis_hsmc,
    thesis_hsmc_gains,
    thesis_subsystem_models,
)
from ipcosim.controllers.linear import Builder, Lin, lsum
from ipcosim.fmus.kinds import get, plant_kind
from ipcosim.fmus.linearize import LinearModel, linear_matrices


class HSMC(DiscreteLaw):
    """Hierarchical sliding-mode controller (two layers single mass, three double mass).

    The law is the unique input that makes the top layer follow the reaching law exactly on
    the subsystem models ``x_(2i)' = f_i + b_i u``::

        S_n' = sum_r alpha_r (c_r x_(2r) + f_r) + (sum_r alpha_r b_r) u
        u = -[sum_r alpha_r (c_r x_(2r) + f_r) + k S_n + eta tanh(g S_n) + KI int S_n] / sum_r alpha_r b_r

    which is Qian, Yi & Zhao's ``u = (sum_r alpha_r b_r u_eq,r + u_sw) / sum_r alpha_r b_r`` with
    ``b_r u_eq,r = -(c_r x_(2r) + f_r)``. The denominator ``sum_r alpha_r b_r`` must stay away from 0:
    a set of gains for which ``|sum alpha_r b_r| < denominator_min`` is rejected. The integral of
    S_n is frozen while the output saturates in the direction the integral pushes.

    Parameters
    ----------
    kind : str
        Plant kind.
    gains : HSMCGains
        Surface and reaching-law constants.
    models : sequence of SubsystemModel
        ``f_i, b_i`` of each subsystem, in the design-model state order (``subsystem_models``).
    """

    def __init__(self, kind: str, gains: HSMCGains, models: Sequence[SubsystemModel],
                 sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        n_layers = len(subsystem_rows(kind))
        self.n_layers = n_layers
        n_states = 2 * n_layers
        if len(gains.c) != n_layers:
            raise LawParameterError("c", f"HSMC on the {kind} plant needs {n_layers} surface slopes c, got "
                                         f"{len(gains.c)}")
        if len(gains.lam) != n_layers - 1:
            raise LawParameterError("lambda", f"HSMC on the {kind} plant needs {n_layers - 1} layer weights "
                                              f"lambda, got {len(gains.lam)}")
        if len(models) != n_layers:
            raise LawParameterError("model", f"HSMC needs {n_layers} subsystem models, got {len(models)}")
        for i, ci in enumerate(gains.c, 1):
            check_positive(f"c{i}", ci)
        for i, li in enumerate(gains.lam, 1):
            check_finite(f"lambda{i}", li)
        for name in ("k", "eta", "KI"):
            check_nonneg(name, getattr(gains, name))
        check_finite("top_weight", gains.top_weight)
        check_positive("tanh_gain", gains.tanh_gain)
        check_nonneg("derivative_time_constant", gains.derivative_time_constant)
        check_positive("denominator_min", gains.denominator_min)
        for i, m in enumerate(models, 1):
            if len(m.a) != n_states:
                raise LawParameterError(f"a{i}", f"subsystem {i} model needs {n_states} coefficients, got {len(m.a)}")
            for j, aj in enumerate(m.a, 1):
                check_finite(f"a{i}_{j}", aj)
            check_finite(f"b{i}", m.b)
        self.gains = gains
        self.models = tuple(models)
        # Constants of the top layer, as plain floats for the per-sample arithmetic:
        # S_n = sum alpha_r (c_r pos_r + vel_r),  S_n' = sum alpha_r c_r vel_r + w . x + den u,
        # with w = alpha A and den = alpha . b.
        alpha = gains.alphas()
        self._den = self._check_denominator(gains, dot(alpha, [float(m.b) for m in models]))
        self._alpha = tuple(float(a) for a in alpha)
        self._w = tuple(dot(alpha, [float(m.a[j]) for m in models]) for j in range(n_states))
        self._c = tuple(float(ci) for ci in gains.c)
        tau = gains.derivative_time_constant
        self._d = [FilteredDerivative(self.sample_period, tau) for _ in range(n_layers)]
        self._reads, self._order = subsystem_readings(kind)
        self.reset()

    @staticmethod
    def _check_denominator(gains: HSMCGains, den: float) -> float:
        if not math.isfinite(den) or abs(den) < gains.denominator_min:
            raise LawParameterError("lambda", f"parameters lambda1, lambda2: the HSMC denominator sum(alpha_r b_r) "
                                              f"= {den:.6g} is below denominator_min = {gains.denominator_min:g}: the "
                                              "top sliding layer cannot be moved by the input (change the layer "
                                              "weights or the model's b_i)")
        return den

    def reset(self) -> None:
        super().reset()
        self.integral = 0.0
        self.S = 0.0
        for d in self._d:
            d.reset()

    #: Output = force_gain * (law's u) + emf_gain * (motor-cart velocity): 1 and 0 when the subsystem
    #: models are voltage models; ``drive_through_motor`` sets them for force models.
    force_gain = 1.0
    emf_gain = 0.0

    def drive_through_motor(self, force_per_volt: float, emf_per_velocity: float) -> "HSMC":
        """Treat the law's ``u`` as a force [N] and apply the voltage that makes the motor produce it.

        The cart force of the DC motor (inductance neglected) is ``F = Kf (V - Ke v)`` with
        ``Kf = N Kt/(Ra rg)`` [N/V] and ``Ke = N Kb/rg`` [V s/m], ``v`` the motor-cart velocity, so
        ``V = F/Kf + Ke v``. Needed when the subsystem models ``f_i + b_i u`` describe a force-driven
        cart (the thesis's App. A.5 constants); returns the law.
        """
        self.force_gain = 1.0 / check_positive("force_per_volt", force_per_volt)
        self.emf_gain = check_nonneg("emf_per_velocity", emf_per_velocity)
        return self

    def _state(self, y: Sequence[float], r: float) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """Design-model state estimate in error coordinates (ipcosim.fmus.physics order without the current),
        and the (positions, velocities) of the subsystems: pendulum, pendulum cart, (motor cart)."""
        pos = tuple(float(y[j]) - r if cart else float(y[j]) for j, cart in self._reads)
        vel = tuple(d.update(float(y[j])) for d, (j, _) in zip(self._d, self._reads))
        return tuple((vel if v else pos)[i] for i, v in self._order), pos, vel

    def _lower_layer_terms(self, c: tuple[float, ...], pos: tuple[float, ...], vel: tuple[float, ...]) -> float:
        """Reaching terms of the first layer added to the top layer's (0 for HSMC; see AdaptiveHSMC)."""
        return 0.0

    def current_gains(self) -> tuple[tuple[float, ...], float, float, float]:
        """(c, k, eta, KI) in effect at the law's time (constant for HSMC)."""
        g = self.gains
        return self._c, g.k, g.eta, g.KI

    def _compute(self, y: Sequence[float], r: float) -> float:
        x, pos, vel = self._state(y, r)
        c, k, eta, KI = self.current_gains()
        S = num = 0.0
        for a, ci, p, v in zip(self._alpha, c, pos, vel):
            S += a * (ci * p + v)
            num += a * ci * v
        for w, xi in zip(self._w, x):
            num += w * xi
        num += self._lower_layer_terms(c, pos, vel)
        den = self._den
        integral = self.integral + S * self.sample_period
        u_rest = -(num + k * S + eta * math.tanh(self.gains.tanh_gain * S)) / den
        if self.emf_gain or self.force_gain != 1.0:  # a force model: the voltage that gives the force
            den = den / self.force_gain
            u_rest = u_rest * self.force_gain + self.emf_gain * vel[-1]
        u = u_rest - KI * integral / den
        if abs(u) <= self.voltage_limit or (u > 0) != (-KI * S / den > 0):
            self.integral = integral
        else:
            u = u_rest - KI * self.integral / den
        self.S = S
        return u


class AdaptiveHSMC(HSMC):
    """HSMC whose gains follow time schedules ``p(t) = p0 + dp exp(-rate t)`` (thesis 3.2.4, 4.2.4).

    t is the law's own time ``ticks * sample_period`` (since its start or last reset). High reaching
    gain early (fast rise), lower later (less overshoot); integral gain small early, full later.
    """

    def __init__(self, kind: str, gains: HSMCGains, models: Sequence[SubsystemModel],
                 schedules: AdaptiveSchedules, sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        super().__init__(kind, gains, models, sample_period, voltage_limit)
        for name in ("k", "eta", "KI", "k1", "KI1"):
            sch = getattr(schedules, name)
            if sch is not None:
                for part in ("base", "delta", "rate"):
                    check_finite(f"{name}_{part}", getattr(sch, part))
                check_nonneg(f"{name}_rate", sch.rate)
                if min(sch.base, sch.base + sch.delta) < 0:
                    raise LawParameterError(f"{name}_delta", f"parameter {name}_delta = {sch.delta}: the schedule "
                                                             f"{name}(t) = {sch.base} + {sch.delta} exp(-{sch.rate} t) "
                                                             "goes negative")
        if schedules.c and len(schedules.c) != self.n_layers:
            raise LawParameterError("c", f"need {self.n_layers} c schedules (or none), got {len(schedules.c)}")
        for i, sch in enumerate(schedules.c, 1):
            if sch is not None:
                for part in ("base", "delta", "rate"):
                    check_finite(f"c{i}_{part}", getattr(sch, part))
                check_nonneg(f"c{i}_rate", sch.rate)
                if min(sch.base, sch.base + sch.delta) <= 0:
                    raise LawParameterError(f"c{i}_delta", f"parameter c{i}_delta = {sch.delta}: the schedule "
                                                           f"c{i}(t) = {sch.base} + {sch.delta} exp(-{sch.rate} t) "
                                                           "must stay > 0")
        self.schedules = schedules

    def reset(self) -> None:
        super().reset()
        self.integral1 = 0.0

    def _lower_layer_terms(self, c: tuple[float, ...], pos: tuple[float, ...], vel: tuple[float, ...]) -> float:
        sc = self.schedules
        if sc.k1 is None and sc.KI1 is None:
            return 0.0
        t = self.time
        S1 = c[0] * pos[0] + vel[0]
        self.integral1 += S1 * self.sample_period
        k1 = sc.k1(t) if sc.k1 is not None else 0.0
        KI1 = sc.KI1(t) if sc.KI1 is not None else 0.0
        return self._alpha[0] * (k1 * S1 + KI1 * self.integral1)

    def current_gains(self) -> tuple[tuple[float, ...], float, float, float]:
        t = self.time
        g, sc = self.gains, self.schedules
        c = tuple(s(t) if s is not None else ci for s, ci in zip(sc.c or (None,) * len(self._c), self._c))
        k = sc.k(t) if sc.k is not None else g.k
        eta = sc.eta(t) if sc.eta is not None else g.eta
        KI = sc.KI(t) if sc.KI is not None else g.KI
        return c, k, eta, KI


# ============================================================================ subsystem models

def subsystem_rows(kind: str) -> tuple[str, ...]:
    """Design-model state whose derivative each subsystem's ``f_i + b_i u`` gives (layer order)."""
    return ("pendulum_velocity", *(cart.velocity for cart in reversed(get(kind).carts)))


def subsystem_positions(kind: str) -> tuple[str, ...]:
    """Design-model state of each subsystem's position (layer order): the pendulum's angle, then the carts
    from the one carrying the pendulum to the motor's."""
    return ("pendulum_angle", *(cart.position for cart in reversed(get(kind).carts)))


def subsystem_readings(kind: str) -> tuple[tuple[tuple[int, bool], ...], tuple[tuple[int, bool], ...]]:
    """Where the law finds each subsystem in the kind's measured signals, and each design-model state.

    Returns
    -------
    reads : tuple of (int, bool)
        Per layer: the index of its position in the measured signals, and whether it is a cart's (taken
        relative to the reference).
    order : tuple of (int, bool)
        Per design-model state: its layer, and whether it is that layer's velocity (else its position).
    """
    measured, positions, rows = get(kind).measured, subsystem_positions(kind), subsystem_rows(kind)
    reads = tuple((measured.index(p), p != "pendulum_angle") for p in positions)
    order = tuple((rows.index(s), True) if s in rows else (positions.index(s), False) for s in design_states(kind))
    return reads, order


def subsystem_models(model: LinearModel) -> list[SubsystemModel]:
    """``f_i = A[row_i] . x``, ``b_i = B[row_i]`` from a design model (no inductance)."""
    return _subsystems(model.A, [row[0] for row in model.B], model.states)


def _subsystems(A, B, states) -> list[SubsystemModel]:  # noqa: ANN001 -- lists or arrays
    out = []
    for row in subsystem_rows(plant_kind(connectors=states) or ""):
        i = states.index(row)
        out.append(SubsystemModel(a=tuple(float(v) for v in A[i]), b=float(B[i])))
    return out


def design_subsystem_models(kind: str, values: Mapping[str, Any]) -> list[SubsystemModel]:
    """The subsystem models of the design model the flat ``model_*`` values describe (plain Python:
    the linearization of ``ipcosim.fmus.linearize.linear_matrices``, no numpy)."""
    A, B, states, _ = linear_matrices(design_params_from(kind, values), inductance=False)
    return _subsystems(A, B, states)


# ============================================================================ parameters and sets

def _hsmc_specs(kind: str) -> list[ParamSpec]:
    n = len(subsystem_rows(kind))
    subsystem = (("pendulum", "cart") if n == 2 else ("pendulum", "passive cart", "active cart"))
    specs = [ParamSpec(f"c{i + 1}", 1.0, "1/s", f"slope of the {subsystem[i]} sliding surface "
                                               f"s{i + 1} = c{i + 1} position + velocity", "positive")
             for i in range(n)]
    thesis = thesis_hsmc(kind)
    lam = thesis.gains().lam
    if n == 2:  # one cart: the second parameter weights the cart's own surface in the top layer
        specs += [ParamSpec("lambda1", lam[0], "m/rad", "layer weight: S2 = lambda1 S1 + lambda2 s2"),
                  ParamSpec("lambda2", 1.0, "1", "weight of the cart surface in S2 = lambda1 S1 + lambda2 s2")]
    else:
        specs += [ParamSpec("lambda1", lam[0], "m/rad", "layer weight: S2 = lambda1 S1 + s2"),
                  *(ParamSpec(f"lambda{i}", lam[i - 1], "1", f"layer weight: S{i + 1} = lambda{i} S{i} + s{i + 1}")
                    for i in range(2, n))]
    top = {"m": 1, "s": -1}
    specs += [ParamSpec("k", 1.0, "1/s", "reaching law: proportional gain (S' = -k S - eta tanh(g S) - KI int S)",
                        "nonnegative"),
              ParamSpec("eta", 0.0, unit_div({**top, "s": -2}, {}), "reaching law: switching gain", "nonnegative"),
              ParamSpec("KI", 0.0, "1/s2", "reaching law: integral gain", "nonnegative"),
              ParamSpec("tanh_gain", 10.0, unit_div({}, top), "reaching law: slope g of tanh(g S) "
                                                               "(the thesis's 10)", "positive"),
              ParamSpec("derivative_time_constant", 0.002, "s", "velocity estimates: time constant of the "
                                                                "filtered differences", "nonnegative"),
              ParamSpec("denominator_min", 1e-3, "1", "smallest |sum alpha_r b_r| accepted (the hierarchy divides "
                                                      "by it)", "positive"),
              ParamSpec("use_thesis_coefficients", False, None, "subsystem models f_i, b_i: false = from the "
                                                                "design model's linearization; true = the a*/b* "
                                                                "parameters (the thesis's constants)", "bool")]
    return specs + _coefficient_specs(kind, thesis)


def _coefficient_specs(kind: str, thesis: ThesisHSMC) -> list[ParamSpec]:
    """The thesis's constants as parameters; unit: d(row)/dt per state, per volt of ``u`` for b (per newton of
    cart force for a force model)."""
    app, rows, specs = thesis.appendix, subsystem_rows(kind), []
    coef_state = _coefficient_states(kind, thesis)
    for name, value in thesis.coefficients.items():
        if name.startswith("b"):
            row = rows[int(name[1:]) - 1]
            unit = unit_div(_deriv_dim(row), {"N": 1} if thesis.force_model else {"V": 1})
            doc = f"thesis App. {app}.5 input gain of subsystem {name[1:]}" + \
                (" (per newton of cart force)" if thesis.force_model else "")
        else:
            row, state = coef_state[name]
            unit = unit_div(_deriv_dim(row), state_dim(state))
            doc = f"thesis App. {app}.5 constant: d({row})/dt per {state}"
        specs.append(ParamSpec(name, value, unit, doc))
    return specs


def _adaptive_specs(kind: str) -> list[ParamSpec]:
    """The HSMC's parameters, the first-layer gains and a schedule of every gain."""
    n = len(subsystem_rows(kind))
    specs = _hsmc_specs(kind)
    specs += [ParamSpec("k1", 0.0, "1/s", "first-layer reaching gain: the top layer's law adds "
                                          "lambda1 (k1 S1 + KI1 int S1) (thesis App. A.6 deltaKP, KP1)",
                        "nonnegative"),
              ParamSpec("KI1", 0.0, "1/s2", "first-layer integral gain (thesis App. A.6 KI1, deltaKI)",
                        "nonnegative")]
    for base in ["k", "eta", "KI", "k1", "KI1"] + [f"c{i + 1}" for i in range(n)]:
        unit = next(s.unit for s in specs if s.name == base)
        specs += [ParamSpec(f"{base}_delta", 0.0, unit, f"schedule {base}(t) = {base} + {base}_delta "
                                                        f"exp(-{base}_rate t): initial excess"),
                  ParamSpec(f"{base}_rate", 0.0, "1/s", f"schedule of {base}: decay rate", "nonnegative")]
    return specs


def _deriv_dim(row: str) -> dict[str, int]:
    return {"rad": 1, "s": -2} if row == "pendulum_velocity" else {"m": 1, "s": -2}


def _coefficient_states(kind: str, thesis: ThesisHSMC) -> dict[str, tuple[str, str]]:
    """Thesis constant ``a*`` -> (the state whose derivative it gives, the state it multiplies)."""
    rows, states = subsystem_rows(kind), design_states(kind)
    return {name: (row, state) for row, layout in zip(rows, thesis.layout)
            for state, name in zip(states, layout) if name}


def _hsmc_values(kind: str, g: HSMCGains, use_thesis: bool) -> dict[str, Any]:
    v: dict[str, Any] = {f"c{i + 1}": float(c) for i, c in enumerate(g.c)}
    v.update({f"lambda{i + 1}": float(lam) for i, lam in enumerate(g.lam)})
    if len(g.lam) == 1:  # one cart: lambda2 weights the cart's surface in the top layer
        v["lambda2"] = float(g.top_weight)
    v.update(k=g.k, eta=g.eta, KI=g.KI, derivative_time_constant=g.derivative_time_constant,
             use_thesis_coefficients=use_thesis)
    return v


def _schedule_values(g: HSMCGains, s: AdaptiveSchedules) -> dict[str, float]:
    v: dict[str, float] = {}
    for name in ("k", "eta", "KI", "k1", "KI1"):
        sch = getattr(s, name)
        v[name] = sch.base if sch else getattr(g, name, 0.0)
        v[f"{name}_delta"] = sch.delta if sch else 0.0
        v[f"{name}_rate"] = sch.rate if sch else 0.0
    scs = s.c or (None,) * len(g.c)
    for i, (sch, c) in enumerate(zip(scs, g.c), 1):
        v[f"c{i}"] = sch.base if sch else c
        v[f"c{i}_delta"] = sch.delta if sch else 0.0
        v[f"c{i}_rate"] = sch.rate if sch else 0.0
    return v


def _hsmc_set(kind: str, parameter_set: str) -> dict[str, Any]:
    if parameter_set == "thesis":
        return _hsmc_values(kind, thesis_hsmc_gains(kind), True)
    return _hsmc_values(kind, TUNED_HSMC[kind], kind in TUNED_HSMC_ON_THESIS_COEFFICIENTS)


def _adaptive_set(kind: str, parameter_set: str) -> dict[str, Any]:
    g, s = thesis_adaptive(kind) if parameter_set == "thesis" else TUNED_ADAPTIVE[kind]
    v = _hsmc_values(kind, g, parameter_set == "thesis")
    v.update(_schedule_values(g, s))
    return v


# ============================================================================ the factory

def _gains_and_models(kind: str, v: Mapping[str, Any]) -> tuple[HSMCGains, list[SubsystemModel]]:
    """The HSMC gains of the checked values ``v`` and the subsystem models (the thesis's coefficients or
    designed)."""
    n = len(subsystem_rows(kind))
    c = tuple(float(v[f"c{i + 1}"]) for i in range(n))
    if n == 2:  # one cart: lambda2 weights the cart's surface in the top layer
        lam, top = (float(v["lambda1"]),), float(v["lambda2"])
    else:
        lam, top = tuple(float(v[f"lambda{i}"]) for i in range(1, n)), 1.0
    g = HSMCGains(c=c, lam=lam, top_weight=top, k=float(v["k"]), eta=float(v["eta"]), KI=float(v["KI"]),
                  tanh_gain=float(v["tanh_gain"]), derivative_time_constant=float(v["derivative_time_constant"]),
                  denominator_min=float(v["denominator_min"]))
    if bool(v["use_thesis_coefficients"]):
        models = models_from_coefficients(kind, {k: float(v[k]) for k in thesis_coefficients(kind)})
    else:
        models = design_subsystem_models(kind, v)
    return g, models


def _build_hsmc(kind: str, v: Mapping[str, Any], backend: str) -> HSMC:
    g, models = _gains_and_models(kind, v)
    return _through_motor(HSMC(kind, g, models, float(v["sample_period"]), float(v["voltage_limit"])), kind, v)


def _build_adaptive(kind: str, v: Mapping[str, Any], backend: str) -> AdaptiveHSMC:
    """The adaptive HSMC law of the checked values ``v``: the HSMC's gains and models and its gain schedules."""
    g, models = _gains_and_models(kind, v)
    n = len(g.c)

    def sched(name: str) -> Schedule | None:
        return Schedule(float(v[name]), float(v[f"{name}_delta"]), float(v[f"{name}_rate"]))

    def lower(name: str) -> Schedule | None:  # first-layer gains: absent unless set
        return sched(name) if float(v[name]) or float(v[f"{name}_delta"]) else None

    schedules = AdaptiveSchedules(k=sched("k"), eta=sched("eta"), KI=sched("KI"),
                                  c=tuple(sched(f"c{i + 1}") for i in range(n)), k1=lower("k1"), KI1=lower("KI1"))
    law = AdaptiveHSMC(kind, g, models, schedules, float(v["sample_period"]), float(v["voltage_limit"]))
    return _through_motor(law, kind, v)


def _through_motor(law: HSMC, kind: str, v: Mapping[str, Any]) -> HSMC:
    """The App. A.5 constants model a force-driven cart: their law's output is a force, applied through
    the design model's motor (``HSMC.drive_through_motor``). The other models are voltage models."""
    if bool(v["use_thesis_coefficients"]) and thesis_hsmc(kind).force_model:
        p = design_params_from(kind, v)
        law.drive_through_motor(p.force_per_amp / p.Ra, p.emf_per_velocity)
    return law


# ============================================================================ linear models

def linear_hsmc(law: HSMC, b: Builder) -> tuple[Lin, list[str]]:
    """The HSMC's linear model: its gains, ``eta tanh(g S)`` linearized as ``eta g S``."""
    c, k, eta, KI = law.current_gains()
    return _linear_sliding_mode(law, b, (c, k, eta, KI, 0.0, 0.0), [])


def linear_adaptive_hsmc(law: AdaptiveHSMC, b: Builder) -> tuple[Lin, list[str]]:
    """The adaptive HSMC's linear model: its schedules frozen at their final values (t -> infinity)."""
    g, sc = law.gains, law.schedules
    c = tuple(s.base if s is not None else ci for s, ci in zip(sc.c or (None,) * len(law._c), law._c))
    k, eta, KI = ((getattr(sc, n).base if getattr(sc, n) is not None else getattr(g, n)) for n in ("k", "eta", "KI"))
    k1, KI1 = (getattr(sc, n).base if getattr(sc, n) is not None else 0.0 for n in ("k1", "KI1"))
    return _linear_sliding_mode(law, b, (c, k, eta, KI, k1, KI1),
                                ["schedules frozen at their final values (t -> infinity)"])


def _linear_sliding_mode(law: HSMC, b: Builder, gains: tuple[Any, ...], extra: list[str]) -> tuple[Lin, list[str]]:
    """The sliding-mode law with the gains ``(c, k, eta, KI, k1, KI1)`` as a linear expression of the inputs."""
    g, T, tau = law.gains, law.sample_period, law.gains.derivative_time_constant
    c, k, eta, KI, k1, KI1 = gains
    notes = [f"eta tanh(g S) linearized as eta g S (g = {g.tanh_gain:g})", *extra]
    pos = tuple(b.input(j) for j, _ in law._reads)
    vel = tuple(b.derivative(p, T, tau) for p in pos)
    x = tuple((vel if v else pos)[i] for i, v in law._order)
    S = lsum([(p * ci + v) * a for a, ci, p, v in zip(law._alpha, c, pos, vel)])
    num = lsum([v * (a * ci) for a, ci, v in zip(law._alpha, c, vel)]) + lsum([xi * w for w, xi in zip(law._w, x)])
    total = num + S * (k + eta * g.tanh_gain)
    if KI:
        total = total + b.integral(S, T) * KI
    S1 = pos[0] * c[0] + vel[0]
    if k1:
        total = total + S1 * (law._alpha[0] * k1)
    if KI1:
        total = total + b.integral(S1, T) * (law._alpha[0] * KI1)
    u = total * (-law.force_gain / law._den) + vel[-1] * law.emf_gain
    if law.emf_gain or law.force_gain != 1.0:
        notes.append("law output is a force, applied through the motor model")
    return u, notes


HSMC_LAW = LawEntry("HSMC", {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis", "tuned")},
                    lambda kind: _hsmc_specs(kind) + model_specs(kind), _hsmc_set, _build_hsmc, classes=(HSMC,),
                    model_based=True, linear=linear_hsmc)
ADAPTIVE_HSMC_LAW = LawEntry("AdaptiveHSMC", {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis",)},
                             lambda kind: _adaptive_specs(kind) + model_specs(kind), _adaptive_set, _build_adaptive,
                             classes=(AdaptiveHSMC,), model_based=True, linear=linear_adaptive_hsmc)
