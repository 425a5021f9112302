"""The hierarchical sliding-mode laws' numbers: the types of their gains, schedules and subsystem models, the
thesis's constants and gains by plant kind (App. A.5 / A.6, B.5 / B.6) and the tuned sets
(:mod:`ipcosim.controllers.laws.hsmc` is the law that uses them)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Mapping

from ipcosim.controllers.laws.base import LawParameterError
from ipcosim.fmus.kinds import get


@dataclass(frozen=True)
class SubsystemModel:
    """``x_(2i)' = f_i(x) + b_i u`` with ``f_i(x) = a . x`` linear in the state (design-model order)."""

    a: tuple[float, ...]
    b: float


@dataclass(frozen=True)
class HSMCGains:
    """Hierarchical sliding-mode law (thesis 3.2.3, 4.2.3 after Qian, Yi & Zhao 2008).

    Subsystems (error coordinates, positions minus the reference)::

        single: (th, th'), (xc - r, xc')
        double: (th, th'), (xc - r, xc'), (xa - r, xa')        xc passive, xa active (motor) cart

    ``s_i = c_i x_(2i-1) + x_(2i)``; layers ``S_1 = s_1``, ``S_i = lambda_(i-1) S_(i-1) + s_i``, and the
    single-mass top layer weights its own subsystem by ``top_weight`` (the thesis's lambda2 = 1):
    ``S_n = sum_r alpha_r s_r``. Reaching law ``S_n' = -k S_n - eta tanh(tanh_gain S_n) - KI int S_n``.
    """

    c: tuple[float, ...]
    lam: tuple[float, ...]
    k: float
    eta: float
    KI: float = 0.0
    top_weight: float = 1.0
    tanh_gain: float = 10.0
    derivative_time_constant: float = 0.002
    denominator_min: float = 1e-3

    def alphas(self) -> tuple[float, ...]:
        """Coefficients alpha_r of s_r in the top layer S_n."""
        n = len(self.c)
        alpha = [0.0] * n
        alpha[n - 1] = self.top_weight
        prod = 1.0
        for r in range(n - 2, -1, -1):  # alpha_r = lambda_r lambda_(r+1) ... lambda_(n-1)
            prod *= self.lam[r]
            alpha[r] = prod
        return tuple(alpha)


@dataclass(frozen=True)
class Schedule:
    """``value(t) = base + delta exp(-rate t)`` (thesis 3.2.4, 4.2.4)."""

    base: float
    delta: float = 0.0
    rate: float = 0.0

    def __call__(self, t: float) -> float:
        return self.base + self.delta * math.exp(-self.rate * t) if self.delta else self.base


@dataclass(frozen=True)
class AdaptiveSchedules:
    """Time schedules of the adaptive HSMC; ``None`` keeps the HSMC's constant."""

    k: Schedule | None = None
    eta: Schedule | None = None
    KI: Schedule | None = None
    c: tuple[Schedule | None, ...] = ()
    #: First-layer reaching gains (thesis App. A.6 KP1/deltaKP, KI1/deltaKI): the top layer's law gains
    #: ``alpha_1 (k1 S1 + KI1 int S1)``, so that the part of S_n carried by S1 reaches like S1' = -k1 S1 - KI1 int S1.
    k1: Schedule | None = None
    KI1: Schedule | None = None


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


def _a5_gains() -> HSMCGains:
    """App. A.5's surface and reaching-law constants."""
    t = THESIS_A5
    return HSMCGains(c=(0.93 * abs(t["a1"] + t["a2"] + t["a5"]), 0.19 * abs(t["a3"] + t["a4"] + t["a6"])),
                     lam=(-0.35,), top_weight=1.0, k=0.4, eta=0.0005, KI=240.0)


def _b5_gains() -> HSMCGains:
    """App. B.5's surface and reaching-law constants."""
    t = THESIS_B5
    s1 = sum(t[f"a{i}"] for i in range(1, 7))
    s2 = sum(t[f"a{i}"] for i in range(7, 13))
    s3 = sum(t[f"a{i}"] for i in range(13, 17))
    return HSMCGains(c=(0.1 * abs(s1), 0.7 * abs(s2) - 0.2, 0.2 * abs(s3)), lam=(-1.0, -50.0), k=8.0, eta=17.0,
                     KI=0.0)


def _a6_adaptive() -> tuple[HSMCGains, AdaptiveSchedules]:
    """App. A.6's schedules (docs/controllers.md: the inferred mapping of its names).

    c1 = 43.9911 + 3 e^-0.1t, c2 = 0.1766 + 10 e^-150t, k2 = K2 + dKP2 e^-KP2 t = 0.5 + 15 e^-0.1t,
    KI = 320 (1 - dKI2 e^-KI2 t) = 320 - 320 e^-0.3t, eta2 = 0.0005; the first layer's by the same
    forms: k1 = K1 + dKP e^-KP1 t = 14 e^-0.1t (no K1 in the listing), KI1 = 320 (1 - dKI e^-KI1 t).
    """
    g = replace(_a5_gains(), c=(43.9911, 0.1766), k=0.5, eta=0.0005, KI=320.0)
    return g, AdaptiveSchedules(k=Schedule(0.5, 15.0, 0.1), KI=Schedule(320.0, -320.0, 0.3),
                                c=(Schedule(43.9911, 3.0, 0.1), Schedule(0.1766, 10.0, 150.0)),
                                k1=Schedule(0.0, 14.0, 0.1), KI1=Schedule(320.0, -320.0, 4.0))


def _b6_adaptive() -> tuple[HSMCGains, AdaptiveSchedules]:
    """App. B.6's schedules: k3 = 9 + 11.5 e^-t, eta3 = 17 + 1.1 e^-2t, c2 = 0.6506 - 0.5 e^-3t, KI = 0."""
    base = _b5_gains()
    c = list(base.c)
    c[1] = 0.7 * abs(sum(THESIS_B5[f"a{i}"] for i in range(7, 13)))  # B.6: 0.6506, without the -0.2
    g = replace(base, c=tuple(c), k=9.0, eta=17.0, KI=0.0)
    return g, AdaptiveSchedules(k=Schedule(9.0, 11.5, 1.0), eta=Schedule(17.0, 1.1, 2.0),
                                c=(None, Schedule(c[1], -0.5, 3.0), None))


@dataclass(frozen=True)
class ThesisHSMC:
    """What the thesis gives the HSMC on one plant kind.

    Attributes
    ----------
    appendix : str
        The thesis appendix of its constants (``A``: App. A.5 / A.6).
    coefficients : mapping
        Its named subsystem constants ``a*``, ``b*``.
    layout : tuple of tuple of str
        Per subsystem (layer order): the constant multiplying each design-model state (``""``: none, 0),
        then the name of its input gain.
    force_model : bool
        The constants model a cart driven by a force [N] (the law then drives it through the motor), not
        by the motor voltage.
    gains : callable
        ``gains()``: the thesis's HSMC gains.
    adaptive : callable
        ``adaptive()``: the thesis's adaptive HSMC gains and schedules.
    """

    appendix: str
    coefficients: Mapping[str, float]
    layout: tuple[tuple[str, ...], ...]
    force_model: bool
    gains: Callable[[], HSMCGains]
    adaptive: Callable[[], tuple[HSMCGains, AdaptiveSchedules]]


#: The thesis's HSMC by plant kind (the kinds the HSMC laws support).
THESIS_HSMC: dict[str, ThesisHSMC] = {
    # state [xc, xc', th, th']
    "single-mass": ThesisHSMC("A", THESIS_A5, (("", "a2", "a1", "a5", "b1"), ("", "a4", "a3", "a6", "b2")),
                              True, _a5_gains, _a6_adaptive),
    # state [xa, xa', xc, xc', th, th']
    "double-mass": ThesisHSMC("B", THESIS_B5, (("a5", "a6", "a3", "a4", "a1", "a2", "b1"),
                                               ("a11", "a12", "a9", "a10", "a7", "a8", "b2"),
                                               ("a15", "a16", "a13", "a14", "", "", "b3")),
                              False, _b5_gains, _b6_adaptive),
}


def thesis_hsmc(kind: str) -> ThesisHSMC:
    """The thesis's HSMC on plant kind ``kind``.

    Raises
    ------
    LawParameterError
        Naming the kind, when the thesis gives the HSMC no constants for it.
    """
    name = get(kind).name  # an unknown kind: the registry's error
    try:
        return THESIS_HSMC[name]
    except KeyError:
        raise LawParameterError("kind", f"the HSMC has no thesis constants for plant kind {kind!r} (it has "
                                        f"them for {', '.join(THESIS_HSMC)})") from None


def thesis_coefficients(kind: str) -> dict[str, float]:
    """The thesis's named f_i, b_i constants (App. A.5 / B.5)."""
    return dict(thesis_hsmc(kind).coefficients)


def models_from_coefficients(kind: str, t: Mapping[str, float]) -> list[SubsystemModel]:
    """Subsystem models from the thesis-named constants, in design-model state order."""
    return [SubsystemModel(tuple(t[n] if n else 0.0 for n in row[:-1]), t[row[-1]])
            for row in thesis_hsmc(kind).layout]


def thesis_subsystem_models(kind: str) -> list[SubsystemModel]:
    """The thesis's f_i, b_i (App. A.5 / B.5) as subsystem models."""
    return models_from_coefficients(kind, thesis_coefficients(kind))


# ============================================================================ the numbers

def thesis_hsmc_gains(kind: str) -> HSMCGains:
    """App. A.5 / B.5 surface and reaching-law constants."""
    return thesis_hsmc(kind).gains()


def thesis_adaptive(kind: str) -> tuple[HSMCGains, AdaptiveSchedules]:
    """App. A.6 / B.6 schedules (docs/controllers.md: the inferred mapping of the single-mass names)."""
    return thesis_hsmc(kind).adaptive()


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
