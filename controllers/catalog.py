"""Named parameter sets of every law and a factory: ``make_law(law, kind, parameter_set)``.

Each law has a ``thesis`` set (the thesis's numbers, reference/thesis-data.md section 2) and,
where the thesis's numbers do not do the task on the thesis's own model (move the motor-driven
cart 0.05 m within 10 s, |angle| < 0.35 rad, within +-10 V), a ``tuned`` set that does
(``controllers.tuning`` says how it was found; docs/controllers.md says why it was needed).

=============  ===========================  =========================================
law            single mass                  double mass
=============  ===========================  =========================================
PID            thesis (fails: by design)    thesis (fails: by design)
CascadePID     tuned (no thesis set)        tuned (no thesis set)
LQR            thesis                       thesis
HSMC           thesis (too slow), tuned     thesis
AdaptiveHSMC   thesis (too slow), tuned     thesis
=============  ===========================  =========================================
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any


from fmus.linearize import LinearModel
from fmus.params import DEFAULT_PRESET, PlantParams, kind_of, preset

from .design import (THESIS_DOUBLE_MASS_OBSERVER_FACTOR, THESIS_DOUBLE_MASS_Q, THESIS_DOUBLE_MASS_R,
                     THESIS_SINGLE_MASS_OBSERVER_POLES, THESIS_SINGLE_MASS_R, design_lqr, design_model,
                     thesis_single_mass_Q)
from .laws import (LQR, PID, AdaptiveHSMC, AdaptiveSchedules, CascadeGains, CascadePID, DiscreteLaw, HSMC,
                   HSMCGains, LawParameterError, PIDGains, Schedule, SubsystemModel)

LAWS = ("PID", "CascadePID", "LQR", "HSMC", "AdaptiveHSMC")
PLANT_SUFFIX = {"single-mass": "SingleMass", "double-mass": "DoubleMass"}
KIND_OF_SUFFIX = {v: k for k, v in PLANT_SUFFIX.items()}

#: Parameter sets per law and plant kind; the first is the default (the one that does the task).
PARAMETER_SETS: dict[str, dict[str, tuple[str, ...]]] = {
    "PID": {"single-mass": ("thesis",), "double-mass": ("thesis",)},
    "CascadePID": {"single-mass": ("tuned",), "double-mass": ("tuned",)},
    "LQR": {"single-mass": ("thesis",), "double-mass": ("thesis",)},
    "HSMC": {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis",)},
    "AdaptiveHSMC": {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis",)},
}

#: Where the HSMC's subsystem models f_i, b_i come from.
COEFFICIENT_SOURCES = ("linearization", "thesis")


def model_name(law: str, kind: str) -> str:
    """FMU model name ``<Law><Plant>``, e.g. ``LQRSingleMass``."""
    return f"{law}{PLANT_SUFFIX[kind]}"


def default_preset(kind: str) -> str:
    """The plant preset a controller is designed for unless told otherwise."""
    return DEFAULT_PRESET[kind]


def default_set(law: str, kind: str) -> str:
    """The parameter set used when none is named."""
    return PARAMETER_SETS[law][kind][0]


# --- HSMC subsystem models -----------------------------------------------------------------------------

def subsystem_rows(kind: str) -> tuple[str, ...]:
    """Design-model state whose derivative each subsystem's ``f_i + b_i u`` gives (layer order)."""
    if kind == "single-mass":
        return ("pendulum_velocity", "cart_velocity")
    return ("pendulum_velocity", "passive_cart_velocity", "active_cart_velocity")


def subsystem_models(model: LinearModel) -> list[SubsystemModel]:
    """``f_i = A[row_i] . x``, ``b_i = B[row_i]`` from a design model (no inductance)."""
    kind = "single-mass" if "cart_position" in model.states else "double-mass"
    out = []
    for row in subsystem_rows(kind):
        i = model.states.index(row)
        out.append(SubsystemModel(a=tuple(float(v) for v in model.A[i]), b=float(model.B[i, 0])))
    return out


# App. A.5 (single mass). NOTE: these are the linearization of a cart + pendulum driven by a *force*
# with the double-mass passive cart's numbers (Mc 0.961 kg, medium pendulum 0.127 kg, Bc 0.002):
# b1 = 4.488 rad/s^2/N and b2 = 1.008 m/s^2/N are 1/(mass-matrix determinant) terms of that model.
# Mapping inferred from the values: th'' = a1 th + a5 th' + a2 xc' + b1 u; xc'' = a3 th + a6 th' + a4 xc' + b2 u.
THESIS_A5 = dict(a1=47.8583476, a2=-0.008976130226, b1=4.48806511, a3=0.9421754475, a4=-0.002016637257,
                 b2=1.00831862, a5=-0.5471372821, a6=-0.01077135627)
# App. B.5 (double mass): th'' = a1 th + a2 th' + a3 xc + a4 xc' + a5 xa + a6 xa' (b1 = 0);
# xc'' = a7 th + a8 th' + a9 xc + a10 xc' + a11 xa + a12 xa' (b2 = 0);
# xa'' = a13 xc + a14 xc' + a15 xa + a16 xa' + b3 u. Identical to the App. B.3 model.
THESIS_B5 = dict(a1=47.85834769, a2=-0.5471372821, a3=-637.3052461, a4=-9.882719379, a5=637.305246,
                 a6=9.873743249, b1=0.0, a7=0.942175447, a8=-0.0107713562, a9=-143.1812453, a10=-2.220317620,
                 a11=143.1812453, a12=2.21830098, b2=0.0, a13=129.9026065, a14=2.012575593, a15=-129.9026065,
                 a16=-14.70083144, b3=1.57670963)


def thesis_subsystem_models(kind: str) -> list[SubsystemModel]:
    """The thesis's f_i, b_i constants (App. A.5 / B.5) in design-model state order."""
    if kind == "single-mass":
        t = THESIS_A5  # order [xc, xc', th, th']
        return [SubsystemModel((0.0, t["a2"], t["a1"], t["a5"]), t["b1"]),
                SubsystemModel((0.0, t["a4"], t["a3"], t["a6"]), t["b2"])]
    t = THESIS_B5  # order [xa, xa', xc, xc', th, th']
    return [SubsystemModel((t["a5"], t["a6"], t["a3"], t["a4"], t["a1"], t["a2"]), t["b1"]),
            SubsystemModel((t["a11"], t["a12"], t["a9"], t["a10"], t["a7"], t["a8"]), t["b2"]),
            SubsystemModel((t["a15"], t["a16"], t["a13"], t["a14"], 0.0, 0.0), t["b3"])]


def thesis_hsmc_gains(kind: str) -> HSMCGains:
    """App. A.5 / B.5 surface and reaching-law constants."""
    if kind == "single-mass":
        t = THESIS_A5
        return HSMCGains(c=(0.93 * abs(t["a1"] + t["a2"] + t["a5"]), 0.19 * abs(t["a3"] + t["a4"] + t["a6"])),
                         lam=(-0.35,), top_weight=1.0, k=0.4, eta=0.0005, KI=240.0)
    t = THESIS_B5
    s1 = sum(t[f"a{i}"] for i in range(1, 7))
    s2 = sum(t[f"a{i}"] for i in range(7, 13))
    s3 = sum(t[f"a{i}"] for i in range(13, 17))
    return HSMCGains(c=(0.1 * abs(s1), 0.7 * abs(s2) - 0.2, 0.2 * abs(s3)), lam=(-1.0, -50.0), k=8.0, eta=17.0,
                     KI=0.0)


def thesis_adaptive(kind: str) -> tuple[HSMCGains, AdaptiveSchedules]:
    """App. A.6 / B.6 schedules (see docs/controllers.md for the inferred mapping of the single-mass names)."""
    base = thesis_hsmc_gains(kind)
    if kind == "single-mass":
        # c1 = 43.9911 (+3 e^-0.1t), c2 = 0.1766 + 10 e^-150t, k2 = K2 + dKP2 e^-KP2 t = 0.5 + 15 e^-0.1t,
        # KI = 320 (1 - dKI2 e^-KI2 t) = 320 - 320 e^-0.3t, eta2 = 0.0005
        g = replace(base, c=(43.9911, 0.1766), k=0.5, eta=0.0005, KI=320.0)
        return g, AdaptiveSchedules(k=Schedule(0.5, 15.0, 0.1), KI=Schedule(320.0, -320.0, 0.3),
                                    c=(Schedule(43.9911, 3.0, 0.1), Schedule(0.1766, 10.0, 150.0)))
    # k3 = 9 + 11.5 e^-t, eta3 = 17 + 1.1 e^-2t, c2 = 0.6506 - 0.5 e^-3t, KI = 0
    c = list(base.c)
    c[1] = 0.7 * abs(sum(THESIS_B5[f"a{i}"] for i in range(7, 13)))  # B.6: 0.6506, without the -0.2
    g = replace(base, c=tuple(c), k=9.0, eta=17.0, KI=0.0)
    return g, AdaptiveSchedules(k=Schedule(9.0, 11.5, 1.0), eta=Schedule(17.0, 1.1, 2.0),
                                c=(None, Schedule(c[1], -0.5, 3.0), None))


# --- tuned sets (controllers.tuning; see docs/controllers.md) -------------------------------------------

TUNED_CASCADE: dict[str, CascadeGains] = {
    "single-mass": CascadeGains(Kp_th=101.0, Kd_th=20.8, Kp_x=12.0, Kd_x=8.05, Ki_x=8.01),
    "double-mass": CascadeGains(Kp_th=21.2, Kd_th=2.96, Kp_x=1.3, Kd_x=6.33, Ki_x=0.524, Kv_m=3.29),
}
TUNED_HSMC: dict[str, HSMCGains] = {
    "single-mass": replace(thesis_hsmc_gains("single-mass"), c=(4.57, 2.71), lam=(-0.23,), k=12.7, KI=34.2),
}
TUNED_ADAPTIVE: dict[str, tuple[HSMCGains, AdaptiveSchedules]] = {
    # KI(t) = KI (1 - e^-3t): the integral is held back while the cart is still far from the reference
    "single-mass": (TUNED_HSMC["single-mass"], AdaptiveSchedules(KI=Schedule(34.2, -34.2, 3.0))),
}


# --- the factory ----------------------------------------------------------------------------------------

def _check_set(law: str, kind: str, parameter_set: str | None) -> str:
    if law not in PARAMETER_SETS:
        raise LawParameterError("law", f"unknown control law {law!r}; expected one of {', '.join(LAWS)}")
    if kind not in PLANT_SUFFIX:
        raise LawParameterError("kind", f"unknown plant kind {kind!r}")
    sets = PARAMETER_SETS[law][kind]
    name = parameter_set or sets[0]
    if name not in sets:
        raise LawParameterError("parameter_set", f"{model_name(law, kind)} has no parameter set {name!r}; "
                                                 f"available: {', '.join(sets)}")
    return name


def lqr_design_for(kind: str, params: PlantParams, sample_period: float = 1e-3, backend: str = "control"):
    """The thesis's LQR design (weights and observer poles of App. A.2 / B.3) on ``params``."""
    model = design_model(params)
    if kind == "single-mass":
        return design_lqr(model, thesis_single_mass_Q(), THESIS_SINGLE_MASS_R,
                          observer_poles=THESIS_SINGLE_MASS_OBSERVER_POLES, sample_period=sample_period,
                          backend=backend)
    return design_lqr(model, THESIS_DOUBLE_MASS_Q, THESIS_DOUBLE_MASS_R,
                      observer_pole_factor=THESIS_DOUBLE_MASS_OBSERVER_FACTOR, sample_period=sample_period,
                      backend=backend)


def make_law(law: str, kind: str, parameter_set: str | None = None, design_params: PlantParams | None = None,
             sample_period: float = 1e-3, voltage_limit: float = 10.0, coefficients: str = "linearization",
             **options: Any) -> DiscreteLaw:
    """Build a control law from a named parameter set.

    Parameters
    ----------
    law : str
        One of ``LAWS``.
    kind : {'single-mass', 'double-mass'}
        Plant kind.
    parameter_set : str, optional
        ``thesis`` or ``tuned`` (``PARAMETER_SETS``); default: the first listed.
    design_params : PlantParams, optional
        Plant parameters the model-based laws (LQR, HSMC) are designed for; default: the
        kind's default preset (``thesis-ch3`` / ``thesis-ch4``).
    sample_period, voltage_limit : float
        [s], [V].
    coefficients : {'linearization', 'thesis'}
        HSMC / AdaptiveHSMC: subsystem models from the design model's linearization or the
        thesis's App. A.5/B.5 constants.
    **options
        ``output_filter_time_constant`` (LQR), ``derivative_time_constant`` (PID, CascadePID, HSMC).
    """
    name = _check_set(law, kind, parameter_set)
    if design_params is None:
        design_params = preset(default_preset(kind))
    elif kind_of(design_params) != kind:
        raise LawParameterError("design_params", f"design parameters are for a {kind_of(design_params)} plant, "
                                                 f"the law for a {kind} plant")
    if coefficients not in COEFFICIENT_SOURCES:
        raise LawParameterError("coefficients", f"coefficients = {coefficients!r}; expected one of "
                                                f"{', '.join(COEFFICIENT_SOURCES)}")
    tau = options.pop("derivative_time_constant", None)
    if law == "PID":
        gains = PIDGains() if tau is None else replace(PIDGains(), derivative_time_constant=tau)
        _no_options(law, options)
        return PID(kind, gains, sample_period, voltage_limit)
    if law == "CascadePID":
        gains = TUNED_CASCADE[kind] if tau is None else replace(TUNED_CASCADE[kind], derivative_time_constant=tau)
        _no_options(law, options)
        return CascadePID(kind, gains, sample_period, voltage_limit)
    if law == "LQR":
        tau_f = options.pop("output_filter_time_constant", 0.0008 if kind == "double-mass" else 0.0)
        _no_options(law, options)
        design = lqr_design_for(kind, design_params, sample_period)
        return LQR(kind, design, voltage_limit, output_filter_time_constant=tau_f)
    _no_options(law, options)
    models = (subsystem_models(design_model(design_params)) if coefficients == "linearization"
              else thesis_subsystem_models(kind))
    if law == "HSMC":
        gains = thesis_hsmc_gains(kind) if name == "thesis" else TUNED_HSMC[kind]
        if tau is not None:
            gains = replace(gains, derivative_time_constant=tau)
        return HSMC(kind, gains, models, sample_period, voltage_limit)
    gains, schedules = thesis_adaptive(kind) if name == "thesis" else TUNED_ADAPTIVE[kind]
    if tau is not None:
        gains = replace(gains, derivative_time_constant=tau)
    return AdaptiveHSMC(kind, gains, models, schedules, sample_period, voltage_limit)


def _no_options(law: str, options: dict) -> None:
    if options:
        raise LawParameterError(next(iter(options)), f"{law} has no option {', '.join(options)}")


__all__ = ["LAWS", "PARAMETER_SETS", "make_law", "model_name", "default_set", "default_preset",
           "subsystem_models", "thesis_subsystem_models", "thesis_hsmc_gains", "thesis_adaptive",
           "lqr_design_for", "TUNED_CASCADE", "TUNED_HSMC", "TUNED_ADAPTIVE"]
