"""The LQR: state feedback on a discrete current estimator (the thesis's design, App. A.2 / B.3), its
parameters and sets, its design from the flat values, its gains as parameters (so its FMU runs without the
design stack), its linear model and its registry entry."""
from __future__ import annotations

from dataclasses import dataclass
from operator import mul
from typing import Any, Mapping, Sequence

from ipcosim.controllers.errors import DesignError
from ipcosim.controllers.laws.base import (
    NOT_IN_DESIGN,
    CurrentEstimatorLaw,
    Designed,
    LawEntry,
    LawParameterError,
    ParamSpec,
    check_nonneg,
    design_params_from,
    design_states,
    dot,
    estimator_gain_specs,
    estimator_gains,
    fmu_message,
    fmu_name,
    model_specs,
    right_inverse,
    sampled_model,
    state_dim,
    unit_div,
    zoh_lists,
)
from ipcosim.controllers.linear import Builder, Lin, lsum
from ipcosim.controllers.thesis import (
    THESIS_DOUBLE_MASS_OBSERVER_FACTOR,
    THESIS_DOUBLE_MASS_Q_DIAGONAL,
    THESIS_DOUBLE_MASS_R,
    THESIS_SINGLE_MASS_OBSERVER_POLES,
    THESIS_SINGLE_MASS_Q_DIAGONAL,
    THESIS_SINGLE_MASS_R,
)
from ipcosim.fmus.expm import Matrix, as_matrix
from ipcosim.fmus.kinds import get
from ipcosim.fmus.params import PlantParams
from ipcosim.fmus.physics import MEASURED


def output_filter_lists(time_constant: float, sample_period: float) -> tuple[Matrix, list[float], list[float]]:
    """Discrete ``1/(tau s + 1)^2`` filter (zero-order hold) as ``(Ad, Bd, Cd)`` of a 2-state system,
    state ``[y1, y2]`` with ``y1' = (u - y1)/tau``, ``y2' = (y1 - y2)/tau``, output ``y2``."""
    a = 1.0 / time_constant
    Ad, Bd = zoh_lists([[-a, 0.0], [a, -a]], [a, 0.0], sample_period)
    return Ad, Bd, [0.0, 1.0]


@dataclass(frozen=True)
class LQRCoefficients:
    """Everything the LQR law computes with, as plain floats (design-model state order).

    ``K`` (n), ``N``: the feedback ``u = -K x^ + N r``; ``M`` (n x p): the current-estimator gain;
    ``Ad`` (n x n), ``Bd`` (n): the zero-order-hold model for ``sample_period``; ``C`` (p x n): the
    measured rows. Made from an ``ipcosim.controllers.design.LQRDesign`` (:meth:`from_design`) or
    from gains stored in a controller FMU (no numpy needed).
    """

    states: tuple[str, ...]
    outputs: tuple[str, ...]
    sample_period: float
    K: tuple[float, ...]
    N: float
    M: tuple[tuple[float, ...], ...]
    Ad: tuple[tuple[float, ...], ...]
    Bd: tuple[float, ...]
    C: tuple[tuple[float, ...], ...]

    @classmethod
    def from_design(cls, design: Any) -> LQRCoefficients:
        """The coefficients of an ``LQRDesign`` (numpy arrays become tuples of floats)."""
        def rows(m: Any) -> tuple[tuple[float, ...], ...]:
            return tuple(tuple(float(v) for v in row) for row in as_matrix(m))
        return cls(states=tuple(design.model.states), outputs=tuple(design.model.outputs),
                   sample_period=float(design.sample_period), K=rows(design.K)[0], N=float(design.N),
                   M=rows(design.M), Ad=rows(design.Ad), Bd=tuple(r[0] for r in rows(design.Bd)),
                   C=rows(design.model.C))


class LQR(CurrentEstimatorLaw):
    """LQR state feedback on a discrete current estimator, ``u = sat(-K x^ + N r)``
    (see ``ipcosim.controllers.design``).

    Parameters
    ----------
    kind : str
        Plant kind.
    design : LQRDesign or LQRCoefficients
        From ``ipcosim.controllers.design.design_lqr`` (its ``sample_period`` is the law's), or the
        plain coefficients (what a controller FMU runs on).
    voltage_limit : float
        [V].
    output_filter_time_constant : float
        If > 0, each measured position passes through ``1/(tau s + 1)^2`` (zero-order-hold
        discretized) before the estimator: the thesis's double-mass filters, tau = 0.0008 s.
    """

    def __init__(self, kind: str, design: Any, voltage_limit: float = 10.0,
                 output_filter_time_constant: float = 0.0) -> None:
        coef = design if isinstance(design, LQRCoefficients) else LQRCoefficients.from_design(design)
        super().__init__(kind, coef.sample_period, voltage_limit)
        if coef.outputs != tuple(self.measured):
            raise LawParameterError("design", f"LQR design is for outputs {coef.outputs}, the "
                                              f"{kind} plant measures {self.measured}")
        self.design = design
        self.coefficients = coef
        tau = check_nonneg("output_filter_time_constant", output_filter_time_constant)
        self.filter = output_filter_lists(tau, self.sample_period) if tau > 0 else None
        self._Cpinv = right_inverse(coef.C)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self._filt: list[list[float]] | None = None

    def _filter(self, y: Sequence[float]) -> Sequence[float]:
        if self.filter is None:
            return y
        Ad, Bd, Cd = self.filter
        if self._filt is None:  # start at rest at the first measurement
            self._filt = [[v, v] for v in y]
        out = [dot(s, Cd) for s in self._filt]
        self._filt = [[dot(Ad[0], s) + Bd[0] * v, dot(Ad[1], s) + Bd[1] * v] for s, v in zip(self._filt, y)]
        return out

    def _compute(self, y: Sequence[float], r: float) -> float:
        d = self.coefficients
        x_hat = self._correct(self._filter(y))
        u = d.N * r - sum(map(mul, d.K, x_hat))
        limit = self.voltage_limit
        u_applied = limit if u > limit else (-limit if u < -limit else u)
        self.x_pred = [sum(map(mul, row, x_hat)) + b * u_applied for row, b in zip(d.Ad, d.Bd)]
        return u


# ============================================================================ parameters and sets

def lqr_specs(kind: str) -> list[ParamSpec]:
    states = design_states(kind)
    specs = []
    for s in states:
        dim = state_dim(s)
        specs.append(ParamSpec(f"Q_{s}", 0.0, unit_div({}, {b: 2 * e for b, e in dim.items()}),
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


#: The thesis's LQR by plant kind: (Q diagonal, R, observer pole factor, observer poles or None, output filter
#: time constant [s]).
THESIS_LQR: dict[str, tuple[tuple[float, ...], float, float, tuple[complex, ...] | None, float]] = {
    "single-mass": (THESIS_SINGLE_MASS_Q_DIAGONAL, THESIS_SINGLE_MASS_R, 0.0, THESIS_SINGLE_MASS_OBSERVER_POLES, 0.0),
    "double-mass": (THESIS_DOUBLE_MASS_Q_DIAGONAL, THESIS_DOUBLE_MASS_R, THESIS_DOUBLE_MASS_OBSERVER_FACTOR, None,
                    0.0008),
}


def _thesis_lqr(kind: str) -> tuple[tuple[float, ...], float, float, tuple[complex, ...] | None, float]:
    """The thesis's LQR on plant kind ``kind`` (:data:`THESIS_LQR`); an error naming a kind it has none for."""
    name = get(kind).name  # an unknown kind: the registry's error
    try:
        return THESIS_LQR[name]
    except KeyError:
        raise LawParameterError("kind", f"the LQR has no thesis weights for plant kind {kind!r} (it has them for "
                                        f"{', '.join(THESIS_LQR)})") from None


def _lqr_values(kind: str, parameter_set: str) -> dict[str, Any]:
    """The thesis's weights and observer poles; ``discrete``: the same weights, K from the discrete LQR."""
    states = design_states(kind)
    Q, R, factor, poles, tau = _thesis_lqr(kind)
    v = {f"Q_{s}": float(Q[i]) for i, s in enumerate(states)}
    v.update(R=float(R), observer_pole_factor=factor, output_filter_time_constant=tau,
             discrete_design=parameter_set == "discrete")
    if poles is not None:
        upper = [p for p in poles if p.imag >= 0]
        for i, p in enumerate(upper, 1):
            v[f"observer_pole_{i}_re"] = float(p.real)
            v[f"observer_pole_{i}_im"] = float(p.imag)
    return v


# ============================================================================ design and gains

def lqr_design_from(kind: str, v: Mapping[str, Any], backend: str = "control"):
    """The LQR design the flat values describe (``ipcosim.controllers.design.design_lqr``; numpy, scipy
    and, for ``backend="control"``, python-control are imported here)."""
    import numpy as np  # noqa: PLC0415 -- the design stack, imported only to design

    from ipcosim.controllers.design import design_lqr, design_model  # noqa: PLC0415

    states = design_states(kind)
    model = design_model(design_params_from(kind, v))
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
        raise DesignError(fmu_name(exc.parameter, kind), fmu_message(exc, kind)) from None


def lqr_gain_specs(kind: str) -> list[ParamSpec]:
    """The LQR's gains as flat parameters: ``K_<state>`` and ``N`` (``u = -K x^ + N r``) and the
    current-estimator gain ``M_<state>_<output>`` (``x^ = x- + M (y - C x-)``), design-model order.

    A controller FMU ships them designed for its default parameters; setting them replaces the
    design (one set of names for the gains of every flavour of the FMU).
    """
    states, outputs = design_states(kind), MEASURED[kind]
    specs = [ParamSpec(f"K_{s}", 0.0, unit_div({"V": 1}, state_dim(s)),
                       f"LQR gain on the estimated {s} (u = -K x^ + N r)") for s in states]
    specs.append(ParamSpec("N", 0.0, "V/m", "reference gain N = -1/(C1 (A - B K)^-1 B)"))
    return specs + estimator_gain_specs(states, outputs)


#: LQR parameters that only the design stack turns into gains (weights, observer poles).
def lqr_weight_parameters(kind: str) -> tuple[str, ...]:
    """Names of the LQR parameters that enter only through the design (``Q_*``, ``R``, ``observer_*``)."""
    return tuple(s.name for s in lqr_specs(kind) if s.name != "output_filter_time_constant")


def lqr_design_parameters(kind: str) -> tuple[str, ...]:
    """Every LQR parameter the gains depend on: weights, observer poles, ``model_*``, ``sample_period``."""
    return LQR_LAW.design_parameters(kind)


def lqr_gains(law: LQR) -> dict[str, float]:
    """``{K_<state>, N, M_<state>_<output>: value}`` of an LQR law (``lqr_gain_specs`` names)."""
    c = law.coefficients
    out = {f"K_{s}": k for s, k in zip(c.states, c.K)}
    out["N"] = c.N
    out.update(estimator_gains(c))
    return out


def lqr_from_gains(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> LQR:
    """An LQR law from flat values and given gains, in plain Python (no numpy, scipy or python-control).

    The zero-order-hold model ``Ad, Bd`` comes from the ``model_*`` values and ``sample_period``
    (``ipcosim.fmus.linearize.linear_matrices`` and a plain-Python matrix exponential); ``K``, ``N``
    and ``M`` are taken as given.
    """
    m = sampled_model(kind, values, gains)
    coef = LQRCoefficients(K=tuple(float(gains[f"K_{s}"]) for s in m["states"]), N=float(gains["N"]), **m)
    return LQR(kind, coef, float(values["voltage_limit"]),
               output_filter_time_constant=float(values["output_filter_time_constant"]))


def _build_lqr(kind: str, v: Mapping[str, Any], backend: str) -> LQR:
    return LQR(kind, lqr_design_from(kind, v, backend), float(v["voltage_limit"]),
               output_filter_time_constant=float(v["output_filter_time_constant"]))


def lqr_design_for(kind: str, params: PlantParams, sample_period: float = 1e-3, backend: str = "control"):
    """The thesis's LQR design (App. A.2 / B.3 weights and observer poles) on ``params``."""
    values = dict(LQR_LAW.set_values(kind, "thesis"))
    values.update({f"model_{k}": v for k, v in vars(params).items() if k not in NOT_IN_DESIGN},
                  sample_period=sample_period)
    full = LQR_LAW.defaults(kind)
    full.update(values)
    return lqr_design_from(kind, full, backend)


# ============================================================================ linear model

def linear_lqr(law: LQR, b: Builder) -> tuple[Lin, list[str]]:
    import numpy as np  # noqa: PLC0415 -- the analysis stack, imported only to analyse

    d = law.design
    p, n = len(law.measured), d.Ad.shape[0]
    ys = [b.input(j) for j in range(p)]
    notes = []
    if law.filter is not None:
        # the law's filter as plain lists (the controllers' stdlib runtime): Ad (2 x 2), Bd (2), Cd (2)
        Af, Bf, Cf = (np.asarray(m, dtype=float) for m in law.filter)
        Bf, Cf = Bf.reshape(2), Cf.reshape(2)
        filtered = []
        for y in ys:
            xf = [b.state(), b.state()]
            filtered.append(lsum([xf[i] * Cf[i] for i in range(2)]))
            for i in range(2):
                b.feed(xf[i], lsum([xf[j] * Af[i, j] for j in range(2)]) + y * Bf[i])
        ys = filtered
        notes.append("output filters 1/(tau s + 1)^2 included")
    xp = [b.state() for _ in range(n)]
    C, M, K = d.model.C, d.M, d.K
    innov = [ys[j] - lsum([xp[i] * C[j, i] for i in range(n)]) for j in range(p)]
    xh = [xp[i] + lsum([innov[j] * M[i, j] for j in range(p)]) for i in range(n)]
    u = lsum([xh[i] * -K[0, i] for i in range(n)])
    for i in range(n):
        b.feed(xp[i], lsum([xh[j] * d.Ad[i, j] for j in range(n)]) + u * d.Bd[i, 0])
    return u, notes


LQR_DESIGNED = Designed(lqr_gain_specs, lqr_weight_parameters, lqr_gains, lqr_from_gains)
# discrete: the thesis's weights, K from the discrete LQR at the sample period it runs at
LQR_LAW = LawEntry("LQR", {"single-mass": ("thesis", "discrete"), "double-mass": ("thesis", "discrete")},
                   lambda kind: lqr_specs(kind) + model_specs(kind), _lqr_values, _build_lqr, classes=(LQR,),
                   model_based=True, designed=LQR_DESIGNED, linear=linear_lqr)
