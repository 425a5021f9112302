"""Every control law's parameters (names, units, defaults), its named parameter sets, and one
factory that builds a law from flat parameter values -- the same values a controller FMU holds.

Each law has a ``thesis`` set (the thesis's numbers, reference/thesis-data.md section 2) and,
where the thesis's numbers do not do the task on the thesis's own model (move the motor-driven
cart 0.05 m within 10 s, |angle| < 0.35 rad, within +-10 V), a ``tuned`` set that does
(``ipcosim.controllers.tuning`` says how it was found; docs/controllers.md says why it was needed).

=============  ===========================  =========================================
law            single mass                  double mass
=============  ===========================  =========================================
PID            thesis (fails: by design)    thesis (fails: by design)
CascadePID     tuned (no thesis set)        tuned (no thesis set)
LQR            thesis; discrete             thesis; discrete
HSMC           tuned; thesis (too slow)     thesis; tuned (robust: lab bench)
AdaptiveHSMC   tuned; thesis (too slow)     thesis
LQG            tuned; lab (not in thesis)   tuned; lab (not in thesis)
=============  ===========================  =========================================

The first set listed is the default: the FMU parameter defaults are its values, and the SSP
scenarios bind it (``parameter_sets`` feeds ``ipcosim.harness.scenario.ssp_gen``'s ``.ssv`` files).

Flat parameter names (``schema``): the law's gains as in ``ipcosim.controllers.laws``; ``sample_period``
[s]; ``voltage_limit`` [V]; for the model-based laws (LQR, LQG, HSMC, AdaptiveHSMC) the design model's
physical constants as ``model_<name>`` (``ipcosim.fmus.params`` names, defaults = the plant kind's default
preset): the controller's *belief* about the plant, independent of the plant component.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

from ipcosim.controllers.errors import ControllerParameterError, DesignError
from ipcosim.controllers.excitation import Excitation, ExcitationGains
from ipcosim.controllers.laws import (
    HSMC,
    LQG,
    LQR,
    PID,
    AdaptiveHSMC,
    AdaptiveSchedules,
    CascadeGains,
    CascadePID,
    DiscreteLaw,
    HSMCGains,
    LQGCoefficients,
    LQRCoefficients,
    PIDGains,
    Schedule,
    SubsystemModel,
    SwingUp,
    SwingUpGains,
    rest_state,
    zoh_lists,
)
from ipcosim.controllers.thesis import (
    THESIS_DOUBLE_MASS_OBSERVER_FACTOR,
    THESIS_DOUBLE_MASS_Q_DIAGONAL,
    THESIS_DOUBLE_MASS_R,
    THESIS_SINGLE_MASS_OBSERVER_POLES,
    THESIS_SINGLE_MASS_Q_DIAGONAL,
    THESIS_SINGLE_MASS_R,
)
from ipcosim.errors import closest
from ipcosim.fmus.linearize import LinearModel, linear_matrices
from ipcosim.fmus.params import (
    DEFAULT_PRESET,
    KINDS,
    PLANT_KINDS,
    PRESETS,
    ParameterError,
    PlantParams,
    make,
    parameter_info,
)
from ipcosim.fmus.physics import MEASURED

LAWS = ("PID", "CascadePID", "LQR", "HSMC", "AdaptiveHSMC", "LQG")
PLANT_SUFFIX = {"single-mass": "SingleMass", "double-mass": "DoubleMass"}

#: Parameter sets per law and plant kind; the first is the default (the one that does the task).
PARAMETER_SETS: dict[str, dict[str, tuple[str, ...]]] = {
    "PID": {"single-mass": ("thesis",), "double-mass": ("thesis",)},
    "CascadePID": {"single-mass": ("tuned",), "double-mass": ("tuned",)},
    # discrete: the thesis's weights, K from the discrete LQR at the sample period it runs at
    "LQR": {"single-mass": ("thesis", "discrete"), "double-mass": ("thesis", "discrete")},
    "HSMC": {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis", "tuned")},
    "AdaptiveHSMC": {"single-mass": ("tuned", "thesis"), "double-mass": ("thesis",)},
    # not in the thesis: discrete LQG with integral action (ipcosim.controllers.lqg), weights TUNED_LQG;
    # lab: the same design with the Coulomb friction compensation of LAB_LQG (for a plant with friction)
    "LQG": {"single-mass": ("tuned", "lab"), "double-mass": ("tuned", "lab")},
    # not in the thesis, single mass only: energy swing-up from hanging, balanced by the thesis's LQR
    "SwingUp": {"single-mass": ("tuned",)},
    # not a control law: the identification experiments' multisine and weak hold (ipcosim.controllers.excitation)
    "Excitation": {"single-mass": ("identify",), "double-mass": ("identify",)},
}

#: Physical constants that do not enter the design model (no inductance, no Coulomb friction, no limit).
_NOT_IN_DESIGN = {"La", "voltage_limit", "coulomb_velocity", "b", "b1", "b2"}


class CatalogError(ControllerParameterError):
    """Unknown law, plant kind, parameter set or parameter name."""


def model_name(kind: str, law: str) -> str:
    """FMU model name ``<Law><Plant>``, e.g. ``LQRSingleMass``."""
    return f"{law}{PLANT_SUFFIX[kind]}"


def default_preset(kind: str) -> str:
    """The plant preset a controller is designed for unless told otherwise."""
    return DEFAULT_PRESET[kind]


def default_set(kind: str, law: str) -> str:
    """The parameter set used when none is named."""
    return PARAMETER_SETS[law][kind][0]


# =================================================================== HSMC subsystem models

def subsystem_rows(kind: str) -> tuple[str, ...]:
    """Design-model state whose derivative each subsystem's ``f_i + b_i u`` gives (layer order)."""
    if kind == "single-mass":
        return ("pendulum_velocity", "cart_velocity")
    return ("pendulum_velocity", "passive_cart_velocity", "active_cart_velocity")


def subsystem_models(model: LinearModel) -> list[SubsystemModel]:
    """``f_i = A[row_i] . x``, ``b_i = B[row_i]`` from a design model (no inductance)."""
    return _subsystems(model.A, [row[0] for row in model.B], model.states)


def _subsystems(A, B, states) -> list[SubsystemModel]:  # noqa: ANN001 -- lists or arrays
    kind = "single-mass" if "cart_position" in states else "double-mass"
    out = []
    for row in subsystem_rows(kind):
        i = states.index(row)
        out.append(SubsystemModel(a=tuple(float(v) for v in A[i]), b=float(B[i])))
    return out


def design_subsystem_models(kind: str, values: Mapping[str, Any]) -> list[SubsystemModel]:
    """The subsystem models of the design model the flat ``model_*`` values describe (plain Python:
    the linearization of ``ipcosim.fmus.linearize.linear_matrices``, no numpy)."""
    A, B, states, _ = linear_matrices(_design_params(kind, values), inductance=False)
    return _subsystems(A, B, states)


# App. A.5 (single mass). These turn out to be the linearization of a cart + pendulum driven by a
# *force* with the double-mass passive cart's numbers (Mc 0.961 kg, medium pendulum 0.127 kg,
# Bc 0.002 N s/m): b1 = 4.488 rad/s^2/N and b2 = 1.008 m/s^2/N. Mapping (inferred from the values):
# th'' = a1 th + a5 th' + a2 xc' + b1 u;  xc'' = a3 th + a6 th' + a4 xc' + b2 u.
THESIS_A5 = dict(a1=47.8583476, a2=-0.008976130226, a3=0.9421754475, a4=-0.002016637257,
                 a5=-0.5471372821, a6=-0.01077135627, b1=4.48806511, b2=1.00831862)
# App. B.5 (double mass): th'' = a1 th + a2 th' + a3 xc + a4 xc' + a5 xa + a6 xa' + b1 u (b1 = 0);
# xc'' = a7 th + a8 th' + a9 xc + a10 xc' + a11 xa + a12 xa' + b2 u (b2 = 0);
# xa'' = a13 xc + a14 xc' + a15 xa + a16 xa' + b3 u. The App. B.3 model, entry by entry.
THESIS_B5 = dict(a1=47.85834769, a2=-0.5471372821, a3=-637.3052461, a4=-9.882719379, a5=637.305246,
                 a6=9.873743249, a7=0.942175447, a8=-0.0107713562, a9=-143.1812453, a10=-2.220317620,
                 a11=143.1812453, a12=2.21830098, a13=129.9026065, a14=2.012575593, a15=-129.9026065,
                 a16=-14.70083144, b1=0.0, b2=0.0, b3=1.57670963)


def thesis_coefficients(kind: str) -> dict[str, float]:
    """The thesis's named f_i, b_i constants (App. A.5 / B.5)."""
    return dict(THESIS_A5 if kind == "single-mass" else THESIS_B5)


def models_from_coefficients(kind: str, t: Mapping[str, float]) -> list[SubsystemModel]:
    """Subsystem models from the thesis-named constants, in design-model state order."""
    if kind == "single-mass":  # state [xc, xc', th, th']
        return [SubsystemModel((0.0, t["a2"], t["a1"], t["a5"]), t["b1"]),
                SubsystemModel((0.0, t["a4"], t["a3"], t["a6"]), t["b2"])]
    # state [xa, xa', xc, xc', th, th']
    return [SubsystemModel((t["a5"], t["a6"], t["a3"], t["a4"], t["a1"], t["a2"]), t["b1"]),
            SubsystemModel((t["a11"], t["a12"], t["a9"], t["a10"], t["a7"], t["a8"]), t["b2"]),
            SubsystemModel((t["a15"], t["a16"], t["a13"], t["a14"], 0.0, 0.0), t["b3"])]


def thesis_subsystem_models(kind: str) -> list[SubsystemModel]:
    """The thesis's f_i, b_i (App. A.5 / B.5) as subsystem models."""
    return models_from_coefficients(kind, thesis_coefficients(kind))


# ============================================================================ the numbers

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
    """App. A.6 / B.6 schedules (docs/controllers.md: the inferred mapping of the single-mass names)."""
    base = thesis_hsmc_gains(kind)
    if kind == "single-mass":
        # c1 = 43.9911 + 3 e^-0.1t, c2 = 0.1766 + 10 e^-150t, k2 = K2 + dKP2 e^-KP2 t = 0.5 + 15 e^-0.1t,
        # KI = 320 (1 - dKI2 e^-KI2 t) = 320 - 320 e^-0.3t, eta2 = 0.0005; the first layer's by the same
        # forms: k1 = K1 + dKP e^-KP1 t = 14 e^-0.1t (no K1 in the listing), KI1 = 320 (1 - dKI e^-KI1 t)
        g = replace(base, c=(43.9911, 0.1766), k=0.5, eta=0.0005, KI=320.0)
        return g, AdaptiveSchedules(k=Schedule(0.5, 15.0, 0.1), KI=Schedule(320.0, -320.0, 0.3),
                                    c=(Schedule(43.9911, 3.0, 0.1), Schedule(0.1766, 10.0, 150.0)),
                                    k1=Schedule(0.0, 14.0, 0.1), KI1=Schedule(320.0, -320.0, 4.0))
    # k3 = 9 + 11.5 e^-t, eta3 = 17 + 1.1 e^-2t, c2 = 0.6506 - 0.5 e^-3t, KI = 0
    c = list(base.c)
    c[1] = 0.7 * abs(sum(THESIS_B5[f"a{i}"] for i in range(7, 13)))  # B.6: 0.6506, without the -0.2
    g = replace(base, c=tuple(c), k=9.0, eta=17.0, KI=0.0)
    return g, AdaptiveSchedules(k=Schedule(9.0, 11.5, 1.0), eta=Schedule(17.0, 1.1, 2.0),
                                c=(None, Schedule(c[1], -0.5, 3.0), None))


#: Tuned sets: single mass ``python -m ipcosim.controllers.tuning`` (rounded to 3 significant digits); double mass
#: the robust search of docs/controllers.md (``ipcosim tune --max-peak-sensitivity 6 --min-delay-margin 0.003
#: --min-phase-margin 30 --spread 0.1``, rounded to 4 digits): a slow, robust feedback, and a reference model
#: that sets how fast the cart follows the step.
TUNED_CASCADE: dict[str, CascadeGains] = {
    "single-mass": CascadeGains(Kp_th=79.2, Kd_th=12.9, Kp_x=10.9, Kd_x=6.74, Ki_x=6.37),
    "double-mass": CascadeGains(Kp_th=61.07, Kd_th=25.25, Ki_th=4.295, Kp_x=4.252, Kd_x=11.12, Ki_x=0.1017,
                                Kv_m=30.91, derivative_time_constant=0.00598, reference_time_constant=0.4258),
}
TUNED_HSMC: dict[str, HSMCGains] = {
    # derivative filter 10 ms (not 2 ms): with 4096-count encoders the faster filter lets the
    # quantization noise through the high reaching gain (the voltage chatters, the cart never settles)
    "single-mass": replace(thesis_hsmc_gains("single-mass"), c=(5.63, 2.46), k=76.7, KI=1540.0,
                           derivative_time_constant=0.01),
    # the robust objective of ``ipcosim tune`` on double-mass-hsmc-lab (docs/controllers.md gives the command):
    # every loop of the +-10 % spread with peak |S| <= 2.5 and a delay margin >= 3 ms, worst-run cost (the
    # thesis set: 0.4 ms, its reaching term eta tanh(10 S) with eta = 17 a gain of 170). Designed on the thesis's
    # subsystem constants, like the thesis set.
    "double-mass": replace(thesis_hsmc_gains("double-mass"), c=(3.16, 1.90, 7.52), lam=(-0.336, -17.4), k=5.25,
                           eta=1.87, KI=10.1, derivative_time_constant=0.0069),
}
#: Tuned HSMC sets designed on the thesis's subsystem constants (``use_thesis_coefficients``).
TUNED_HSMC_ON_THESIS_COEFFICIENTS = ("double-mass",)
TUNED_ADAPTIVE: dict[str, tuple[HSMCGains, AdaptiveSchedules]] = {
    # k(t) = 76.7 - 60 e^-t, c2(t) = 2.46 - e^-3t: a gentle start (no saturation, no overshoot), full
    # gains after ~1 s (a search over the thesis's schedule forms on top of the tuned HSMC)
    "single-mass": (TUNED_HSMC["single-mass"], AdaptiveSchedules(k=Schedule(76.7, -60.0, 1.0),
                                                                 c=(None, Schedule(2.46, -1.0, 3.0)))),
}

#: LQG weights (``ipcosim.controllers.lqg``; docs/controllers.md, "LQG", says how they were chosen): the
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


# ============================================================================ the schema

#: The longest controller sample period accepted [s]: the pendulum's unstable pole (6.6 rad/s on
#: the single mass, ``ipcosim linearize``) grows 700-fold in 1 s.
MAX_SAMPLE_PERIOD = 1.0


@dataclass(frozen=True)
class ParamSpec:
    """One flat law parameter: FMU variable name, default, unit, description and constraint."""

    name: str
    default: float | bool
    unit: str | None
    description: str
    constraint: str = "finite"     # finite | positive | nonnegative | period | bool

    def check(self, value: Any) -> str | None:
        """``None`` if ``value`` is acceptable, else the reason."""
        if self.constraint == "bool":
            return None
        v = float(value)
        if not math.isfinite(v):
            return "not a finite number"
        if self.constraint in ("positive", "period") and v <= 0:
            return "must be > 0"
        if self.constraint == "period" and v > MAX_SAMPLE_PERIOD:
            return (f"must be at most {MAX_SAMPLE_PERIOD:g} s (the upright pendulum diverges e-fold in about "
                    f"0.15 s; no sampled law holds it at {v:g} s)")
        if self.constraint == "nonnegative" and v < 0:
            return "must be >= 0"
        return None


def _unit_div(num: dict[str, int], den: dict[str, int]) -> str:
    exps = dict(num)
    for b, e in den.items():
        exps[b] = exps.get(b, 0) - e
    pos = [f"{b}{e if e != 1 else ''}" for b, e in exps.items() if e > 0]
    neg = [f"{b}{-e if e != -1 else ''}" for b, e in exps.items() if e < 0]
    return (".".join(pos) or "1") + ("/" + ".".join(neg) if neg else "")


_STATE_DIM = {"position": {"m": 1}, "velocity": {"m": 1, "s": -1}, "angle": {"rad": 1},
              "angvel": {"rad": 1, "s": -1}}


def _state_dim(state: str) -> dict[str, int]:
    if state == "pendulum_angle":
        return _STATE_DIM["angle"]
    if state == "pendulum_velocity":
        return _STATE_DIM["angvel"]
    return _STATE_DIM["position" if state.endswith("position") else "velocity"]


def design_states(kind: str) -> tuple[str, ...]:
    """States of the design model (``ipcosim.fmus.physics`` order without the motor current)."""
    from ipcosim.fmus.physics import state_names  # noqa: PLC0415
    return state_names(kind)[:-1]


def _model_specs(kind: str) -> list[ParamSpec]:
    defaults = dict(PRESETS[DEFAULT_PRESET[kind]][1])
    out = []
    for info in parameter_info(PLANT_KINDS[kind]):
        if info["name"] in _NOT_IN_DESIGN:
            continue
        meta = {f.name: f.metadata for f in PLANT_KINDS[kind].__dataclass_fields__.values()}[info["name"]]
        constraint = "positive" if meta.get("positive") else ("nonnegative" if meta.get("nonnegative") else "finite")
        out.append(ParamSpec(f"model_{info['name']}", float(defaults.get(info["name"], info["default"])),
                             info["unit"], f"design model: {info['doc']}", constraint))
    return out


def _common_specs() -> list[ParamSpec]:
    return [ParamSpec("sample_period", 1e-3, "s", "controller sample period: the output is updated at k*sample_period "
                                                  "and held in between", "period"),
            ParamSpec("voltage_limit", 10.0, "V", "output limit (the Q4 card's +-10 V analog output range)",
                      "positive")]


def _hsmc_specs(kind: str, law: str) -> list[ParamSpec]:
    n = 2 if kind == "single-mass" else 3
    subsystem = (("pendulum", "cart") if n == 2 else ("pendulum", "passive cart", "active cart"))
    specs = [ParamSpec(f"c{i + 1}", 1.0, "1/s", f"slope of the {subsystem[i]} sliding surface "
                                               f"s{i + 1} = c{i + 1} position + velocity", "positive")
             for i in range(n)]
    if kind == "single-mass":
        specs += [ParamSpec("lambda1", -0.35, "m/rad", "layer weight: S2 = lambda1 S1 + lambda2 s2"),
                  ParamSpec("lambda2", 1.0, "1", "weight of the cart surface in S2 = lambda1 S1 + lambda2 s2")]
        top = {"m": 1, "s": -1}
    else:
        specs += [ParamSpec("lambda1", -1.0, "m/rad", "layer weight: S2 = lambda1 S1 + s2"),
                  ParamSpec("lambda2", -50.0, "1", "layer weight: S3 = lambda2 S2 + s3")]
        top = {"m": 1, "s": -1}
    specs += [ParamSpec("k", 1.0, "1/s", "reaching law: proportional gain (S' = -k S - eta tanh(g S) - KI int S)",
                        "nonnegative"),
              ParamSpec("eta", 0.0, _unit_div({**top, "s": -2}, {}), "reaching law: switching gain", "nonnegative"),
              ParamSpec("KI", 0.0, "1/s2", "reaching law: integral gain", "nonnegative"),
              ParamSpec("tanh_gain", 10.0, _unit_div({}, top), "reaching law: slope g of tanh(g S) "
                                                               "(the thesis's 10)", "positive"),
              ParamSpec("derivative_time_constant", 0.002, "s", "velocity estimates: time constant of the "
                                                                "filtered differences", "nonnegative"),
              ParamSpec("denominator_min", 1e-3, "1", "smallest |sum alpha_r b_r| accepted (the hierarchy divides "
                                                      "by it)", "positive"),
              ParamSpec("use_thesis_coefficients", False, None, "subsystem models f_i, b_i: false = from the "
                                                                "design model's linearization; true = the a*/b* "
                                                                "parameters (the thesis's constants)", "bool")]
    rows = subsystem_rows(kind)
    thesis = thesis_coefficients(kind)
    # unit of each thesis constant: d(row)/dt per state, u in volts for b (force in newtons for App. A.5)
    coef_state = _coefficient_states(kind)
    for name, value in thesis.items():
        if name.startswith("b"):
            row = rows[int(name[1:]) - 1]
            per = {"N": 1} if kind == "single-mass" else {"V": 1}
            unit = _unit_div(_deriv_dim(row), per)
            doc = (f"thesis App. A.5 input gain of subsystem {name[1:]} (per newton of cart force)" if
                   kind == "single-mass" else f"thesis App. B.5 input gain of subsystem {name[1:]}")
        else:
            row, state = coef_state[name]
            unit = _unit_div(_deriv_dim(row), _state_dim(state))
            doc = f"thesis App. {'A' if kind == 'single-mass' else 'B'}.5 constant: d({row})/dt per {state}"
        specs.append(ParamSpec(name, value, unit, doc))
    if law == "AdaptiveHSMC":
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


def _coefficient_states(kind: str) -> dict[str, tuple[str, str]]:
    if kind == "single-mass":
        return {"a1": ("pendulum_velocity", "pendulum_angle"), "a2": ("pendulum_velocity", "cart_velocity"),
                "a5": ("pendulum_velocity", "pendulum_velocity"), "a3": ("cart_velocity", "pendulum_angle"),
                "a4": ("cart_velocity", "cart_velocity"), "a6": ("cart_velocity", "pendulum_velocity")}
    order = ("pendulum_angle", "pendulum_velocity", "passive_cart_position", "passive_cart_velocity",
             "active_cart_position", "active_cart_velocity")
    out = {}
    for i, st in enumerate(order):
        out[f"a{i + 1}"] = ("pendulum_velocity", st)
        out[f"a{i + 7}"] = ("passive_cart_velocity", st)
    for i, st in enumerate(order[2:]):
        out[f"a{i + 13}"] = ("active_cart_velocity", st)
    return out


def _lqr_specs(kind: str) -> list[ParamSpec]:
    states = design_states(kind)
    specs = []
    for s in states:
        dim = _state_dim(s)
        specs.append(ParamSpec(f"Q_{s}", 0.0, _unit_div({}, {b: 2 * e for b, e in dim.items()}),
                               f"LQR state weight on {s} (diagonal of Q)", "nonnegative"))
    specs.append(ParamSpec("R", 1.0, "1/V2", "LQR input weight", "positive"))
    specs.append(ParamSpec("discrete_design", False, None, "K from the discrete LQR on the zero-order-hold model "
                                                           "at sample_period (true) or the continuous LQR used at "
                                                           "the sample instants (false, the thesis's)", "bool"))
    specs.append(ParamSpec("observer_pole_factor", 0.0, "1", "observer poles = factor * eig(A - B K) if > 0 "
                                                              "(thesis double mass: 10); 0 = use observer_pole_*",
                           "nonnegative"))
    for i in range(len(states) // 2):
        specs += [ParamSpec(f"observer_pole_{i + 1}_re", -100.0 * (i + 1), "rad/s",
                            f"observer pole pair {i + 1}: real part (used when observer_pole_factor = 0)"),
                  ParamSpec(f"observer_pole_{i + 1}_im", 0.0, "rad/s",
                            f"observer pole pair {i + 1}: imaginary part >= 0 (re +- j im; 0 = a double real pole)",
                            "nonnegative")]
    specs.append(ParamSpec("output_filter_time_constant", 0.0, "s", "each measurement passes 1/(tau s + 1)^2 "
                                                                     "before the observer if > 0 (thesis double "
                                                                     "mass: 0.0008)", "nonnegative"))
    return specs


def _lqg_specs(kind: str) -> list[ParamSpec]:
    from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT  # noqa: PLC0415

    specs = [ParamSpec(f"Q_{s}", 0.0, _unit_div({}, {b: 2 * e for b, e in _state_dim(s).items()}),
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
LQG_FRICTION = {"single-mass": ("friction_b",), "double-mass": ("friction_b1", "friction_b2")}


def _lab_lqg(kind: str) -> dict[str, float]:
    """The values of the LQG's ``lab`` set beyond the design (``LAB_LQG`` and the lab bench's Coulomb forces)."""
    from ipcosim.fmus.instruments import REALISM  # noqa: PLC0415

    lab = REALISM["lab"][kind]
    return {**{n: float(lab[n[len("friction_"):]]) for n in LQG_FRICTION[kind]}, **LAB_LQG[kind]}  # type: ignore[index]


def _lqg_friction_specs(kind: str) -> list[ParamSpec]:
    """The LQG parameters that act at run time only (no redesign): friction compensation, integrator dead band."""
    carts = ("cart",) if kind == "single-mass" else ("active cart", "passive cart")
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


def _pid_specs() -> list[ParamSpec]:
    g = PIDGains()
    return [ParamSpec(f, getattr(g, f), PIDGains.UNITS[f], PIDGains.DOCS[f],
                      "nonnegative" if f == "derivative_time_constant" else "finite")
            for f in ("Kp", "Ki", "Kd", "derivative_time_constant")]


def _swing_up_specs() -> list[ParamSpec]:
    g = SwingUpGains()
    return [ParamSpec(f, getattr(g, f), SwingUpGains.UNITS[f], SwingUpGains.DOCS[f],
                      "positive" if f in ("catch_angle", "release_angle") else "nonnegative")
            for f in SwingUpGains.UNITS]


def _excitation_specs() -> list[ParamSpec]:
    g = ExcitationGains()
    return [ParamSpec(f, getattr(g, f), ExcitationGains.UNITS[f], ExcitationGains.DOCS[f],
                      "positive" if f in ("band_low", "band_high", "period") else "nonnegative")
            for f in ExcitationGains.UNITS]


def _cascade_specs() -> list[ParamSpec]:
    g = CascadeGains()
    pos = {"theta_ref_limit": "positive", "derivative_time_constant": "nonnegative",
           "reference_time_constant": "nonnegative"}
    return [ParamSpec(f, getattr(g, f), CascadeGains.UNITS[f], CascadeGains.DOCS[f], pos.get(f, "finite"))
            for f in CascadeGains.UNITS]


def schema(kind: str, law: str) -> list[ParamSpec]:
    """Every parameter of ``law`` on ``kind``, with the default set's values as defaults."""
    _check(kind, law)
    specs = _common_specs()
    if law == "PID":
        specs += _pid_specs()
    elif law == "CascadePID":
        specs += _cascade_specs()
    elif law == "LQR":
        specs += _lqr_specs(kind) + _model_specs(kind)
    elif law == "SwingUp":
        specs += _swing_up_specs() + _lqr_specs(kind) + _model_specs(kind)
    elif law == "Excitation":
        specs += _excitation_specs()
    elif law == "LQG":
        specs += _lqg_specs(kind) + _model_specs(kind)
    else:
        specs += _hsmc_specs(kind, law) + _model_specs(kind)
    values = set_values(kind, law, default_set(kind, law))
    return [replace(s, default=values.get(s.name, s.default)) for s in specs]


def _check(kind: str, law: str) -> None:
    if law not in PARAMETER_SETS:
        raise CatalogError("law", f"unknown control law {law!r}; {closest(law, PARAMETER_SETS)}")
    if kind not in PLANT_SUFFIX:
        raise CatalogError("kind", f"unknown plant kind {kind!r}; {closest(kind, KINDS)}")
    if kind not in PARAMETER_SETS[law]:
        raise CatalogError("kind", f"control law {law} is not available for the {kind} plant")


def _hsmc_values(kind: str, g: HSMCGains, use_thesis: bool) -> dict[str, Any]:
    v: dict[str, Any] = {f"c{i + 1}": float(c) for i, c in enumerate(g.c)}
    v["lambda1"] = float(g.lam[0])
    v["lambda2"] = float(g.top_weight if kind == "single-mass" else g.lam[1])
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


def set_values(kind: str, law: str, parameter_set: str) -> dict[str, Any]:
    """The values a named parameter set gives (only the parameters it fixes)."""
    _check(kind, law)
    sets = PARAMETER_SETS[law][kind]
    if parameter_set not in sets:
        raise CatalogError("parameter_set", f"{model_name(kind, law)} has no parameter set {parameter_set!r}; "
                                            f"{closest(parameter_set, sets)}")
    if law == "PID":
        g = PIDGains()
        return {"Kp": g.Kp, "Ki": g.Ki, "Kd": g.Kd, "derivative_time_constant": g.derivative_time_constant}
    if law == "CascadePID":
        g = TUNED_CASCADE[kind]
        return {f: getattr(g, f) for f in CascadeGains.UNITS}
    if law == "SwingUp":
        g = SwingUpGains()
        return {**{f: getattr(g, f) for f in SwingUpGains.UNITS}, **set_values(kind, "LQR", "thesis")}
    if law == "Excitation":
        g = ExcitationGains()
        return {f: getattr(g, f) for f in ExcitationGains.UNITS}
    if law == "LQG":
        t = TUNED_LQG[kind]
        v: dict[str, Any] = {f"Q_{s}": float(q) for s, q in zip(design_states(kind), t["Q"])}
        v.update({k: float(t[k]) for k in ("Q_integral", "R", "process_noise", "acceleration_noise")})
        return {**v, **(_lab_lqg(kind) if parameter_set == "lab" else {})}
    if law == "LQR":
        states = design_states(kind)
        if kind == "single-mass":
            Q, R, factor = THESIS_SINGLE_MASS_Q_DIAGONAL, THESIS_SINGLE_MASS_R, 0.0
            poles, tau = THESIS_SINGLE_MASS_OBSERVER_POLES, 0.0
        else:
            Q, R, factor = THESIS_DOUBLE_MASS_Q_DIAGONAL, THESIS_DOUBLE_MASS_R, THESIS_DOUBLE_MASS_OBSERVER_FACTOR
            poles, tau = None, 0.0008
        v = {f"Q_{s}": float(Q[i]) for i, s in enumerate(states)}
        v.update(R=float(R), observer_pole_factor=factor, output_filter_time_constant=tau,
                 discrete_design=parameter_set == "discrete")
        if poles is not None:
            upper = [p for p in poles if p.imag >= 0]
            for i, p in enumerate(upper, 1):
                v[f"observer_pole_{i}_re"] = float(p.real)
                v[f"observer_pole_{i}_im"] = float(p.imag)
        return v
    if law == "HSMC":
        if parameter_set == "thesis":
            return _hsmc_values(kind, thesis_hsmc_gains(kind), True)
        return _hsmc_values(kind, TUNED_HSMC[kind], kind in TUNED_HSMC_ON_THESIS_COEFFICIENTS)
    g, s = thesis_adaptive(kind) if parameter_set == "thesis" else TUNED_ADAPTIVE[kind]
    v = _hsmc_values(kind, g, parameter_set == "thesis")
    v.update(_schedule_values(g, s))
    return v


def parameter_sets(kind: str, law: str) -> dict[str, dict[str, Any]]:
    """``{set name: {FMU parameter: value}}`` of ``law`` on plant ``kind``.

    Used by ``ipcosim.harness.scenario.ssp_gen``.
    """
    return {name: set_values(kind, law, name) for name in PARAMETER_SETS[law][kind]}


def defaults(kind: str, law: str) -> dict[str, Any]:
    """``{name: default}`` of every parameter (``schema``)."""
    return {s.name: s.default for s in schema(kind, law)}


# ============================================================================ the factory

def _design_params(kind: str, values: Mapping[str, Any]) -> PlantParams:
    phys = {k[len("model_"):]: float(v) for k, v in values.items() if k.startswith("model_")}
    try:
        return make(kind, **phys)
    except ParameterError as exc:
        msg = str(exc)
        for name in phys:
            if msg.startswith(f"parameter {name} "):
                raise ControllerParameterError(f"model_{name}", msg.replace(f"parameter {name} ",
                                                                            f"parameter model_{name} ", 1)) from None
        raise ControllerParameterError("model", msg) from None


def design_params_from(kind: str, values: Mapping[str, Any]) -> PlantParams:
    """The design model's plant parameters from flat ``model_*`` values (others default)."""
    return _design_params(kind, values)


def lqr_design_from(kind: str, v: Mapping[str, Any], backend: str = "control"):
    """The LQR design the flat values describe (``ipcosim.controllers.design.design_lqr``; numpy, scipy
    and, for ``backend="control"``, python-control are imported here)."""
    import numpy as np  # noqa: PLC0415 -- the design stack, imported only to design

    from ipcosim.controllers.design import design_lqr, design_model  # noqa: PLC0415

    states = design_states(kind)
    model = design_model(_design_params(kind, v))
    Q = np.diag([float(v[f"Q_{s}"]) for s in states])
    factor = float(v["observer_pole_factor"])
    poles = None
    if factor <= 0:
        poles = []
        for i in range(len(states) // 2):
            re, im = float(v[f"observer_pole_{i + 1}_re"]), float(v[f"observer_pole_{i + 1}_im"])
            poles += [complex(re, im), complex(re, -im)]
    try:
        return design_lqr(model, Q, [[float(v["R"])]], observer_poles=poles,
                          observer_pole_factor=factor if factor > 0 else None,
                          sample_period=float(v["sample_period"]), backend=backend,
                          discrete=bool(v["discrete_design"]))
    except DesignError as exc:
        raise DesignError(_fmu_name(exc.parameter, kind), _fmu_message(exc, kind)) from None


# ============================================================ LQR gains without the design stack

def lqr_gain_specs(kind: str) -> list[ParamSpec]:
    """The LQR's gains as flat parameters: ``K_<state>`` and ``N`` (``u = -K x^ + N r``) and the
    current-estimator gain ``M_<state>_<output>`` (``x^ = x- + M (y - C x-)``), design-model order.

    A controller FMU ships them designed for its default parameters; setting them replaces the
    design (one set of names for the gains of every flavour of the FMU).
    """
    states, outputs = design_states(kind), MEASURED[kind]
    specs = [ParamSpec(f"K_{s}", 0.0, _unit_div({"V": 1}, _state_dim(s)),
                       f"LQR gain on the estimated {s} (u = -K x^ + N r)") for s in states]
    specs.append(ParamSpec("N", 0.0, "V/m", "reference gain N = -1/(C1 (A - B K)^-1 B)"))
    return specs + _estimator_gain_specs(states, outputs)


def _estimator_gain_specs(states: tuple[str, ...], outputs: tuple[str, ...]) -> list[ParamSpec]:
    return [ParamSpec(f"M_{s}_{o}", 0.0, _unit_div(_state_dim(s), _state_dim(o)),
                      f"current-estimator gain from the {o} innovation to the estimated {s}")
            for s in states for o in outputs]


def _estimator_gains(c: Any) -> dict[str, float]:
    return {f"M_{s}_{o}": m for s, row in zip(c.states, c.M) for o, m in zip(c.outputs, row)}


def _sampled_model(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> dict[str, Any]:
    """The coefficient fields every estimator law shares, in plain Python: states, outputs, the
    zero-order-hold model (``linear_matrices`` of the ``model_*`` values and a plain-Python matrix
    exponential), the measured rows C and the estimator gain M taken from ``gains``."""
    A, B, states, outputs = linear_matrices(_design_params(kind, values), inductance=False)
    T = float(values["sample_period"])
    Ad, Bd = zoh_lists(A, B, T)
    return dict(states=states, outputs=outputs, sample_period=T, Ad=tuple(map(tuple, Ad)), Bd=tuple(Bd),
                M=tuple(tuple(float(gains[f"M_{s}_{o}"]) for o in outputs) for s in states),
                C=tuple(tuple(1.0 if s == o else 0.0 for s in states) for o in outputs))


#: LQR parameters that only the design stack turns into gains (weights, observer poles).
def lqr_weight_parameters(kind: str) -> tuple[str, ...]:
    """Names of the LQR parameters that enter only through the design (``Q_*``, ``R``, ``observer_*``)."""
    return tuple(s.name for s in _lqr_specs(kind) if s.name != "output_filter_time_constant")


def lqr_design_parameters(kind: str) -> tuple[str, ...]:
    """Every LQR parameter the gains depend on: weights, observer poles, ``model_*``, ``sample_period``."""
    return design_parameters(kind, "LQR")


def lqr_gains(law: LQR) -> dict[str, float]:
    """``{K_<state>, N, M_<state>_<output>: value}`` of an LQR law (``lqr_gain_specs`` names)."""
    c = law.coefficients
    out = {f"K_{s}": k for s, k in zip(c.states, c.K)}
    out["N"] = c.N
    out.update(_estimator_gains(c))
    return out


def lqr_from_gains(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> LQR:
    """An LQR law from flat values and given gains, in plain Python (no numpy, scipy or python-control).

    The zero-order-hold model ``Ad, Bd`` comes from the ``model_*`` values and ``sample_period``
    (``ipcosim.fmus.linearize.linear_matrices`` and a plain-Python matrix exponential); ``K``, ``N``
    and ``M`` are taken as given.
    """
    m = _sampled_model(kind, values, gains)
    coef = LQRCoefficients(K=tuple(float(gains[f"K_{s}"]) for s in m["states"]), N=float(gains["N"]), **m)
    return LQR(kind, coef, float(values["voltage_limit"]),
               output_filter_time_constant=float(values["output_filter_time_constant"]))


# ============================================================ LQG

def lqg_design_from(kind: str, v: Mapping[str, Any], backend: str = "control"):
    """The LQG design the flat values describe (``ipcosim.controllers.lqg.design_lqg``; the design stack
    is imported here)."""
    import numpy as np  # noqa: PLC0415 -- the design stack, imported only to design

    from ipcosim.controllers.design import design_model  # noqa: PLC0415
    from ipcosim.controllers.lqg import design_lqg  # noqa: PLC0415

    Q = np.diag([float(v[f"Q_{s}"]) for s in design_states(kind)])
    try:
        return design_lqg(design_model(_design_params(kind, v)), Q, float(v["Q_integral"]), float(v["R"]),
                          sample_period=float(v["sample_period"]), process_noise=float(v["process_noise"]),
                          acceleration_noise=float(v["acceleration_noise"]),
                          resolutions=[float(v[f"resolution_{o}"]) for o in MEASURED[kind]], backend=backend)
    except DesignError as exc:
        raise DesignError(_fmu_name(exc.parameter, kind), _fmu_message(exc, kind)) from None


def lqg_gain_specs(kind: str) -> list[ParamSpec]:
    """The LQG's gains as flat parameters: ``K_<state>``, ``K_voltage``, ``K_integral`` and the Kalman
    current-estimator gain ``M_<state>_<output>`` (``ipcosim.controllers.laws.LQGCoefficients``)."""
    states = design_states(kind)
    law = "u = -K (x^ - x_r r) - K_voltage v - K_integral q"
    specs = [ParamSpec(f"K_{s}", 0.0, _unit_div({"V": 1}, _state_dim(s)), f"LQG gain on the estimated {s} ({law})")
             for s in states]
    specs += [ParamSpec("K_voltage", 0.0, "1", f"LQG gain on the voltage v being applied, computed a sample "
                                              f"earlier ({law})"),
              ParamSpec("K_integral", 0.0, "V/m.s", f"LQG gain on the integral q of the motor-cart position "
                                                   f"error ({law})")]
    return specs + _estimator_gain_specs(states, MEASURED[kind])


def lqg_gains(law: LQG) -> dict[str, float]:
    """``{K_<state>, K_voltage, K_integral, M_<state>_<output>: value}`` of an LQG law."""
    c = law.coefficients
    out = {f"K_{s}": k for s, k in zip(c.states, c.K)}
    out.update(K_voltage=c.K_voltage, K_integral=c.K_integral, **_estimator_gains(c))
    return out


def lqg_from_gains(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> LQG:
    """An LQG law from flat values and given gains, in plain Python (as ``lqr_from_gains``)."""
    m = _sampled_model(kind, values, gains)
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
    p = _design_params(kind, values)
    A, B, states, _ = linear_matrices(p, inductance=False)
    T = float(values["sample_period"])
    per_newton = p.Ra / p.force_per_amp
    carts = [i for i, s in enumerate(states) if s.endswith("cart_velocity")]
    forces = [[b * per_newton for b in B]]
    leads = [[0.0] * len(states)]
    if kind == "double-mass":
        ia = states.index("active_cart_position")
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


# ============================================================ every law with designed gains

#: Laws whose gains the design stack computes, shipped designed for the defaults and parameters of
#: their FMU (the swing-up hands over to an LQR).
DESIGNED_LAWS = ("LQR", "SwingUp", "LQG")


def gain_specs(kind: str, law: str) -> list[ParamSpec]:
    """The gain parameters of a law of ``DESIGNED_LAWS``."""
    return lqg_gain_specs(kind) if law == "LQG" else lqr_gain_specs(kind)


def weight_parameters(kind: str, law: str) -> tuple[str, ...]:
    """The parameters of a designed law that enter only through the design (weights, poles, noises)."""
    if law == "LQG":
        return tuple(s.name for s in _lqg_specs(kind) if s.name not in lqg_runtime_parameters(kind))
    return lqr_weight_parameters(kind)


def design_parameters(kind: str, law: str) -> tuple[str, ...]:
    """Every parameter a designed law's gains depend on: weights, ``model_*``, ``sample_period``."""
    return (*weight_parameters(kind, law), *(s.name for s in _model_specs(kind)), "sample_period")


def designed_gains(law: DiscreteLaw) -> dict[str, float]:
    """The gains (``gain_specs`` names) of a designed law object (a swing-up: its balancing LQR's)."""
    return lqg_gains(law) if isinstance(law, LQG) else lqr_gains(getattr(law, "balance", law))


def law_from_gains(kind: str, law: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> DiscreteLaw:
    """A designed law from flat values and given gains, without the design stack."""
    if law == "LQG":
        return lqg_from_gains(kind, values, gains)
    lqr = lqr_from_gains(kind, values, gains)
    return swing_up_around(kind, values, lqr) if law == "SwingUp" else lqr


def _fmu_name(parameter: str, kind: str) -> str:
    return {"Q": "Q", "R": "R", "observer_poles": "observer_pole_*", "model": "model_*"}.get(parameter, parameter)


def _fmu_message(exc: DesignError, kind: str) -> str:
    where = {"Q": "parameters Q_*", "R": "parameter R", "observer_poles": "parameters observer_pole_*",
             "observer_pole_factor": "parameter observer_pole_factor", "model": "parameters model_*",
             "sample_period": "parameter sample_period"}.get(exc.parameter, f"parameter {exc.parameter}")
    return f"{where}: {exc}"


def build_law(kind: str, law: str, values: Mapping[str, Any] | None = None, backend: str = "control") -> DiscreteLaw:
    """A law from flat parameter values (missing ones take their defaults).

    Parameters
    ----------
    law : str
        One of ``LAWS``.
    kind : {'single-mass', 'double-mass'}
        Plant kind.
    values : mapping, optional
        ``{parameter: value}`` (``schema`` names).
    backend : {'control', 'scipy'}
        Design back end of the LQR (the FMUs use ``scipy``).

    Raises
    ------
    ControllerParameterError
        Naming the parameter (``parameter`` attribute and the message).
    """
    v = _checked_values(kind, law, values)
    T, vlim = float(v["sample_period"]), float(v["voltage_limit"])
    if law == "PID":
        g = PIDGains(**{f: float(v[f]) for f in ("Kp", "Ki", "Kd", "derivative_time_constant")})
        return PID(kind, g, T, vlim)
    if law == "CascadePID":
        return CascadePID(kind, CascadeGains(**{f: float(v[f]) for f in CascadeGains.UNITS}), T, vlim)
    if law == "LQR":
        design = lqr_design_from(kind, v, backend)
        return LQR(kind, design, vlim, output_filter_time_constant=float(v["output_filter_time_constant"]))
    if law == "Excitation":
        return Excitation(kind, ExcitationGains(**{f: float(v[f]) for f in ExcitationGains.UNITS}), T, vlim)
    if law == "LQG":
        return _lqg_law(kind, LQGCoefficients.from_design(lqg_design_from(kind, v, backend)), v)
    if law == "SwingUp":
        balance = LQR(kind, lqr_design_from(kind, v, backend), vlim,
                      output_filter_time_constant=float(v["output_filter_time_constant"]))
        return swing_up_around(kind, v, balance)
    return _sliding_mode(kind, law, v, T, vlim)


def _checked_values(kind: str, law: str, values: Mapping[str, Any] | None) -> dict[str, Any]:
    """Every parameter of the law: the given values over the defaults, each checked against its schema."""
    spec = {s.name: s for s in schema(kind, law)}
    v = {name: s.default for name, s in spec.items()}
    for name, value in (values or {}).items():
        if name not in spec:
            raise CatalogError(name, f"{model_name(kind, law)} has no parameter {name!r}; {closest(name, spec)}")
        v[name] = value
    for name, s in spec.items():
        reason = s.check(v[name])
        if reason:
            unit = f" {s.unit}" if s.unit and s.unit != "1" else ""
            raise ControllerParameterError(name, f"parameter {name} = {v[name]}{unit}: {reason}")
    return v


def _sliding_mode(kind: str, law: str, v: Mapping[str, Any], T: float, vlim: float) -> DiscreteLaw:
    """The HSMC or adaptive HSMC law of the checked values ``v``: gains, subsystem models (the
    thesis's coefficients or designed), and for the adaptive law its gain schedules."""
    n = 2 if kind == "single-mass" else 3
    c = tuple(float(v[f"c{i + 1}"]) for i in range(n))
    if kind == "single-mass":
        lam, top = (float(v["lambda1"]),), float(v["lambda2"])
    else:
        lam, top = (float(v["lambda1"]), float(v["lambda2"])), 1.0
    g = HSMCGains(c=c, lam=lam, top_weight=top, k=float(v["k"]), eta=float(v["eta"]), KI=float(v["KI"]),
                  tanh_gain=float(v["tanh_gain"]), derivative_time_constant=float(v["derivative_time_constant"]),
                  denominator_min=float(v["denominator_min"]))
    if bool(v["use_thesis_coefficients"]):
        models = models_from_coefficients(kind, {k: float(v[k]) for k in thesis_coefficients(kind)})
    else:
        models = design_subsystem_models(kind, v)
    if law == "HSMC":
        return _through_motor(HSMC(kind, g, models, T, vlim), kind, v)

    def sched(name: str) -> Schedule | None:
        return Schedule(float(v[name]), float(v[f"{name}_delta"]), float(v[f"{name}_rate"]))

    def lower(name: str) -> Schedule | None:  # first-layer gains: absent unless set
        return sched(name) if float(v[name]) or float(v[f"{name}_delta"]) else None

    schedules = AdaptiveSchedules(k=sched("k"), eta=sched("eta"), KI=sched("KI"),
                                  c=tuple(sched(f"c{i + 1}") for i in range(n)), k1=lower("k1"), KI1=lower("KI1"))
    return _through_motor(AdaptiveHSMC(kind, g, models, schedules, T, vlim), kind, v)


def swing_up_around(kind: str, v: Mapping[str, Any], balance: LQR) -> SwingUp:
    """The swing-up law of the flat parameter values ``v`` around the balancing law ``balance``
    (designed from ``v`` or rebuilt from stored gains: no design stack needed here)."""
    p = _design_params(kind, v)
    cart = (p.Meq + p.Mp, p.Beq, p.force_per_amp / p.Ra, p.emf_per_velocity, p.Mp, p.Lp, p.g)
    return SwingUp(SwingUpGains(**{f: float(v[f]) for f in SwingUpGains.UNITS}), balance, cart,
                   float(v["sample_period"]), float(v["voltage_limit"]))


def _through_motor(law: HSMC, kind: str, v: Mapping[str, Any]) -> HSMC:
    """The App. A.5 constants model a force-driven cart: their law's output is a force, applied through
    the design model's motor (``HSMC.drive_through_motor``). The other models are voltage models."""
    if kind == "single-mass" and bool(v["use_thesis_coefficients"]):
        p = _design_params(kind, v)
        law.drive_through_motor(p.force_per_amp / p.Ra, p.emf_per_velocity)
    return law


def make_law(kind: str, law: str, parameter_set: str | None = None, design_params: PlantParams | None = None,
             sample_period: float = 1e-3, voltage_limit: float = 10.0, backend: str = "control",
             **overrides: Any) -> DiscreteLaw:
    """A law from a named parameter set (default: the first of ``PARAMETER_SETS``).

    Parameters
    ----------
    kind, law : str
        Plant kind and law.
    parameter_set : str, optional
        ``thesis`` or ``tuned``.
    design_params : PlantParams, optional
        Plant parameters the model-based laws are designed for (default: the kind's default preset).
    sample_period, voltage_limit : float
        [s], [V].
    backend : str
        LQR design back end.
    **overrides
        Further flat parameter values (``schema`` names), e.g. ``use_thesis_coefficients=True``.
    """
    _check(kind, law)
    values: dict[str, Any] = dict(set_values(kind, law, parameter_set or default_set(kind, law)))
    values.update(sample_period=sample_period, voltage_limit=voltage_limit)
    if design_params is not None and law in ("LQR", "HSMC", "AdaptiveHSMC", "SwingUp", "LQG"):
        names = {s.name for s in schema(kind, law)}
        for k2, val in vars(design_params).items():
            if f"model_{k2}" in names:
                values[f"model_{k2}"] = val
    values.update(overrides)
    return build_law(kind, law, values, backend)


def lqr_design_for(kind: str, params: PlantParams, sample_period: float = 1e-3, backend: str = "control"):
    """The thesis's LQR design (App. A.2 / B.3 weights and observer poles) on ``params``."""
    values = dict(set_values(kind, "LQR", "thesis"))
    values.update({f"model_{k}": v for k, v in vars(params).items() if k not in _NOT_IN_DESIGN},
                  sample_period=sample_period)
    full = {s.name: s.default for s in schema(kind, "LQR")}
    full.update(values)
    return lqr_design_from(kind, full, backend)


__all__ = ["LAWS", "KINDS", "PARAMETER_SETS", "ParamSpec", "schema", "set_values", "parameter_sets", "defaults",
           "build_law", "make_law", "model_name", "default_set", "default_preset", "subsystem_models",
           "thesis_subsystem_models", "thesis_hsmc_gains", "thesis_adaptive", "lqr_design_for",
           "design_params_from", "lqr_gain_specs", "lqr_design_parameters", "lqr_weight_parameters", "lqr_gains",
           "lqr_from_gains", "swing_up_around", "DESIGNED_LAWS", "gain_specs", "weight_parameters",
           "design_parameters", "designed_gains", "law_from_gains", "lqg_design_from", "TUNED_LQG", "LAB_LQG",
           "TUNED_CASCADE", "TUNED_HSMC", "TUNED_ADAPTIVE", "CatalogError"]
