"""What every control law shares: the law base class and its helpers (sample period, voltage limit,
measurement checks, filtered derivatives, the current estimator of the LQR and LQG), the flat parameter
description (``ParamSpec``: the FMU variables of a law), the design model's parameters, and the registry
entry (``LawEntry``) each law module declares and ``ipcosim.controllers.catalog`` collects.

Pure Python (standard library only): it runs inside every controller FMU.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from operator import mul
from typing import Any, Callable, Mapping, Sequence

from ipcosim.controllers.errors import ControllerParameterError, DesignError
from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus import kinds
from ipcosim.fmus.expm import Matrix, as_matrix, expm
from ipcosim.fmus.linearize import linear_matrices
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

G = 9.81


class LawParameterError(ControllerParameterError):
    """A control-law parameter is invalid; ``parameter`` names it."""


class LawInputError(IpcosimError, ValueError):
    """A measurement or reference handed to ``step`` is not a finite number."""


def check_finite(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise LawParameterError(name, f"parameter {name} = {value!r} is not a number") from None
    if not math.isfinite(v):
        raise LawParameterError(name, f"parameter {name} = {v} is not finite")
    return v


def check_nonneg(name: str, value: float) -> float:
    v = check_finite(name, value)
    if v < 0:
        raise LawParameterError(name, f"parameter {name} = {v} must be >= 0")
    return v


def check_positive(name: str, value: float) -> float:
    v = check_finite(name, value)
    if v <= 0:
        raise LawParameterError(name, f"parameter {name} = {v} must be > 0")
    return v


def _check_kind(kind: str) -> str:
    if kind not in KINDS:
        raise LawParameterError("kind", f"unknown plant kind {kind!r}; {closest(kind, KINDS)}")
    return kind


def check_sample_period(sample_period: float, name: str = "sample_period") -> float:
    """A sample period must be a positive finite number of seconds (raises ``DesignError`` naming it)."""
    try:
        T = float(sample_period)
    except (TypeError, ValueError):
        raise DesignError(name, f"{name} = {sample_period!r} s is not a number") from None
    if not (math.isfinite(T) and T > 0):
        raise DesignError(name, f"{name} = {T} s must be positive and finite")
    return T


def zoh_lists(A: Sequence[Sequence[float]], B: Sequence[float], T: float) -> tuple[Matrix, list[float]]:
    """Exact zero-order-hold discretization ``(Ad, Bd)`` of ``x' = A x + B u`` (one input), in plain Python."""
    n = len(A)
    aug = [[float(a) * T for a in row] + [float(b) * T] for row, b in zip(A, B)] + [[0.0] * (n + 1)]
    E = expm(aug)
    return [row[:n] for row in E[:n]], [row[n] for row in E[:n]]


def rest_state(states: Sequence[str]) -> tuple[float, ...]:
    """The design state at rest per metre of reference: 1 for every cart position, 0 for the velocities
    and the pendulum angle (both carts stand at the reference, the pendulum upright)."""
    return tuple(1.0 if s.endswith("cart_position") else 0.0 for s in states)


def dot(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(map(mul, a, b))


def saturate(v: float, limit: float) -> float:
    """``v`` clipped to ``+-limit``."""
    return limit if v > limit else (-limit if v < -limit else v)


class FilteredDerivative:
    """Derivative with a first-order low-pass, ``s / (tau s + 1)``, discretized by backward Euler.

    ``d[k] = (tau d[k-1] + y[k] - y[k-1]) / (tau + T)``; ``tau = 0`` gives the backward difference.
    The first sample initializes ``y[k-1] = y[0]`` and ``d = 0`` (a plant at rest).
    """

    def __init__(self, sample_period: float, time_constant: float) -> None:
        self.T = sample_period
        self.tau = time_constant
        self.reset()

    def reset(self) -> None:
        """Forget the past samples."""
        self._prev: float | None = None
        self.value = 0.0

    def update(self, y: float) -> float:
        """Feed the sample of this instant; return the derivative estimate."""
        if self._prev is None:
            self._prev = y
            self.value = 0.0
            return 0.0
        self.value = (self.tau * self.value + (y - self._prev)) / (self.tau + self.T)
        self._prev = y
        return self.value


class DiscreteLaw:
    """Base of the control laws: sample period, voltage limit, measurement checking.

    Parameters
    ----------
    kind : {'single-mass', 'double-mass'}
        Plant the law controls (fixes the measurement order).
    sample_period : float
        T [s] > 0.
    voltage_limit : float
        Output limit [V] > 0 (10 V: the Q4 card's analog output range).
    """

    def __init__(self, kind: str, sample_period: float = 1e-3, voltage_limit: float = 10.0) -> None:
        self.kind = _check_kind(kind)
        try:
            self.sample_period = check_sample_period(sample_period)
        except DesignError as exc:
            raise LawParameterError("sample_period", str(exc)) from None
        self.voltage_limit = check_positive("voltage_limit", voltage_limit)
        self.measured = MEASURED[kind]
        self.ticks = 0
        self.voltage = 0.0

    @property
    def time(self) -> float:
        """Time since the law started, ``ticks * sample_period`` [s] (integer ticks)."""
        return self.ticks * self.sample_period

    def reset(self) -> None:
        """Return to the initial state."""
        self.ticks = 0
        self.voltage = 0.0

    def _inputs(self, measurements: Sequence[float], reference: float) -> tuple[tuple[float, ...], float]:
        try:
            y = tuple(map(float, measurements))
        except (TypeError, ValueError):
            raise LawInputError(f"{type(self).__name__}: measurements must be numbers, got {measurements!r}") from None
        if len(y) != len(self.measured):
            raise LawInputError(f"{type(self).__name__}: expected {len(self.measured)} measurements "
                                f"({', '.join(self.measured)}), got {len(y)}")
        if not all(map(math.isfinite, y)):
            bad = [n for n, v in zip(self.measured, y) if not math.isfinite(v)]
            raise LawInputError(f"{type(self).__name__}: measurement {', '.join(bad)} is not finite "
                                f"at t = {self.time:.6g} s")
        r = float(reference)
        if not math.isfinite(r):
            raise LawInputError(f"{type(self).__name__}: reference = {r} m is not finite at t = {self.time:.6g} s")
        return y, r

    def step(self, measurements: Sequence[float], reference: float) -> float:
        """Compute the voltage for this sample instant (see the module docstring)."""
        y, r = self._inputs(measurements, reference)
        v = saturate(self._compute(y, r), self.voltage_limit)
        self.voltage = v
        self.ticks += 1
        return v

    def _compute(self, y: Sequence[float], r: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    # positions by meaning
    def _motor_cart(self, y: Sequence[float]) -> float:
        return float(y[0])

    def _pendulum_cart(self, y: Sequence[float]) -> float:
        return float(y[kinds.get(self.kind).pendulum_cart_reading])

    def _angle(self, y: Sequence[float]) -> float:
        return float(y[-1])


def right_inverse(C: Sequence[Sequence[float]]) -> Matrix:
    """``C' (C C')^-1`` (the pseudo-inverse of a full-row-rank C; ``C'`` itself for selection rows)."""
    from ipcosim.fmus.expm import matmul, solve  # noqa: PLC0415

    Ct = [list(col) for col in zip(*C)]
    return [list(r) for r in zip(*solve(matmul(as_matrix(C), Ct), [list(r) for r in zip(*Ct)]))]


class CurrentEstimatorLaw(DiscreteLaw):
    """Base of the laws on a discrete current estimator (``coefficients`` with ``C``, ``M``, ``states``):
    ``x^[k] = x-[k] + M (y[k] - C x-[k])``, the first prediction the plant at rest at the measured
    positions. Subclasses predict ``x_pred`` for the next instant."""

    coefficients: Any
    _Cpinv: Matrix

    def reset(self) -> None:
        super().reset()
        self.x_pred: list[float] | None = None
        self.x_hat = [0.0] * len(self.coefficients.states)

    def _correct(self, y: Sequence[float]) -> list[float]:
        """The corrected estimate ``x^`` of this instant (also kept as ``x_hat``)."""
        d = self.coefficients
        xp = self.x_pred
        if xp is None:  # plant assumed at rest at the measured positions
            xp = [sum(map(mul, row, y)) for row in self._Cpinv]
        innovation = [v - sum(map(mul, row, xp)) for v, row in zip(y, d.C)]
        self.x_hat = x_hat = [a + sum(map(mul, row, innovation)) for a, row in zip(xp, d.M)]
        return x_hat


# ============================================================================ the flat parameters

#: The FMU model names' suffix of each plant kind (``ipcosim.fmus.kinds``).
PLANT_SUFFIX = kinds.ByKind(lambda k: k.suffix)

#: Physical constants that do not enter the design model (no inductance, no Coulomb friction, no limit).
NOT_IN_DESIGN = {"La", "voltage_limit", "coulomb_velocity", "b", "b1", "b2"}


class CatalogError(ControllerParameterError):
    """Unknown law, plant kind, parameter set or parameter name."""


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


def unit_div(num: dict[str, int], den: dict[str, int]) -> str:
    exps = dict(num)
    for b, e in den.items():
        exps[b] = exps.get(b, 0) - e
    pos = [f"{b}{e if e != 1 else ''}" for b, e in exps.items() if e > 0]
    neg = [f"{b}{-e if e != -1 else ''}" for b, e in exps.items() if e < 0]
    return (".".join(pos) or "1") + ("/" + ".".join(neg) if neg else "")


_STATE_DIM = {"position": {"m": 1}, "velocity": {"m": 1, "s": -1}, "angle": {"rad": 1},
              "angvel": {"rad": 1, "s": -1}}


def state_dim(state: str) -> dict[str, int]:
    if state == "pendulum_angle":
        return _STATE_DIM["angle"]
    if state == "pendulum_velocity":
        return _STATE_DIM["angvel"]
    return _STATE_DIM["position" if state.endswith("position") else "velocity"]


def design_states(kind: str) -> tuple[str, ...]:
    """States of the design model (``ipcosim.fmus.physics`` order without the motor current)."""
    from ipcosim.fmus.physics import state_names  # noqa: PLC0415
    return state_names(kind)[:-1]


def model_specs(kind: str) -> list[ParamSpec]:
    defaults = dict(PRESETS[DEFAULT_PRESET[kind]][1])
    out = []
    for info in parameter_info(PLANT_KINDS[kind]):
        if info["name"] in NOT_IN_DESIGN:
            continue
        meta = {f.name: f.metadata for f in PLANT_KINDS[kind].__dataclass_fields__.values()}[info["name"]]
        constraint = "positive" if meta.get("positive") else ("nonnegative" if meta.get("nonnegative") else "finite")
        out.append(ParamSpec(f"model_{info['name']}", float(defaults.get(info["name"], info["default"])),
                             info["unit"], f"design model: {info['doc']}", constraint))
    return out


def common_specs() -> list[ParamSpec]:
    return [ParamSpec("sample_period", 1e-3, "s", "controller sample period: the output is updated at k*sample_period "
                                                  "and held in between", "period"),
            ParamSpec("voltage_limit", 10.0, "V", "output limit (the Q4 card's +-10 V analog output range)",
                      "positive")]


def design_params_from(kind: str, values: Mapping[str, Any]) -> PlantParams:
    """The design model's plant parameters from flat ``model_*`` values (others default)."""
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


def estimator_gain_specs(states: tuple[str, ...], outputs: tuple[str, ...]) -> list[ParamSpec]:
    return [ParamSpec(f"M_{s}_{o}", 0.0, unit_div(state_dim(s), state_dim(o)),
                      f"current-estimator gain from the {o} innovation to the estimated {s}")
            for s in states for o in outputs]


def estimator_gains(c: Any) -> dict[str, float]:
    return {f"M_{s}_{o}": m for s, row in zip(c.states, c.M) for o, m in zip(c.outputs, row)}


def sampled_model(kind: str, values: Mapping[str, Any], gains: Mapping[str, float]) -> dict[str, Any]:
    """The coefficient fields every estimator law shares, in plain Python: states, outputs, the
    zero-order-hold model (``linear_matrices`` of the ``model_*`` values and a plain-Python matrix
    exponential), the measured rows C and the estimator gain M taken from ``gains``."""
    A, B, states, outputs = linear_matrices(design_params_from(kind, values), inductance=False)
    T = float(values["sample_period"])
    Ad, Bd = zoh_lists(A, B, T)
    return dict(states=states, outputs=outputs, sample_period=T, Ad=tuple(map(tuple, Ad)), Bd=tuple(Bd),
                M=tuple(tuple(float(gains[f"M_{s}_{o}"]) for o in outputs) for s in states),
                C=tuple(tuple(1.0 if s == o else 0.0 for s in states) for o in outputs))


def fmu_name(parameter: str, kind: str) -> str:
    return {"Q": "Q", "R": "R", "observer_poles": "observer_pole_*", "model": "model_*"}.get(parameter, parameter)


def fmu_message(exc: DesignError, kind: str) -> str:
    where = {"Q": "parameters Q_*", "R": "parameter R", "observer_poles": "parameters observer_pole_*",
             "observer_pole_factor": "parameter observer_pole_factor", "model": "parameters model_*",
             "sample_period": "parameter sample_period"}.get(exc.parameter, f"parameter {exc.parameter}")
    return f"{where}: {exc}"


# ============================================================================ the registry entry

@dataclass(frozen=True)
class Designed:
    """The part of a registry entry for a law whose gains the design stack computes: shipped designed for
    the defaults in its FMU, redesigned when a design parameter changes, or taken as given.

    Attributes
    ----------
    gain_specs : callable
        ``gain_specs(kind)``: the gains as flat parameters.
    weight_parameters : callable
        ``weight_parameters(kind)``: the parameters that enter only through the design (weights, poles, noises).
    gains : callable
        ``gains(law)``: ``{gain parameter: value}`` of a law object.
    from_gains : callable
        ``from_gains(kind, values, gains)``: the law from flat values and given gains, without the design stack.
    """

    gain_specs: Callable[[str], list[ParamSpec]]
    weight_parameters: Callable[[str], tuple[str, ...]]
    gains: Callable[[Any], dict[str, float]]
    from_gains: Callable[[str, Mapping[str, Any], Mapping[str, float]], DiscreteLaw]


@dataclass(frozen=True)
class LawEntry:
    """One control law as the registry (``ipcosim.controllers.catalog``) knows it; its module declares it.

    Attributes
    ----------
    name : str
        The law's name; its FMUs are ``<name><Plant>`` (``LQRSingleMass``).
    sets : mapping
        ``{plant kind: parameter set names}``, the first the default (the one that does the task).
    specs : callable
        ``specs(kind)``: the law's own parameters (after ``sample_period`` and ``voltage_limit``).
    values : callable
        ``values(kind, parameter_set)``: the values a named set fixes.
    build : callable
        ``build(kind, values, backend)``: the law object from checked flat values.
    classes : tuple of type
        The law classes it builds (the entry of a law object is found by its class).
    model_based : bool
        Designed for a plant model (``model_*`` parameters, filled from ``make_law``'s ``design_params``).
    feedback : bool
        A control law (False: an open-loop experiment such as the excitation).
    native : bool
        Has a native (C) flavour (``ipcosim build --native``).
    designed : Designed or None
        Its designed gains, if the design stack computes them.
    linear : callable or None
        ``linear(law, builder) -> (voltage, notes)``: its per-sample arithmetic transcribed into the linear
        expressions of ``ipcosim.controllers.linear`` (None: no linear model).
    pid_gain_search : bool
        ``ipcosim analyze`` also counts, on a log grid, the PID gains that stabilise its loop (the PID's:
        whether any gains of its form would do).
    """

    name: str
    sets: Mapping[str, tuple[str, ...]]
    specs: Callable[[str], list[ParamSpec]]
    values: Callable[[str, str], dict[str, Any]]
    build: Callable[[str, Mapping[str, Any], str], DiscreteLaw]
    classes: tuple[type, ...] = ()
    model_based: bool = False
    feedback: bool = True
    native: bool = True
    designed: Designed | None = None
    linear: Callable[[Any, Any], tuple[Any, list[str]]] | None = None
    pid_gain_search: bool = False

    def model_name(self, kind: str) -> str:
        """FMU model name ``<Law><Plant>``, e.g. ``LQRSingleMass``."""
        return f"{self.name}{PLANT_SUFFIX[kind]}"

    def check(self, kind: str) -> None:
        """Raise ``CatalogError`` unless the law runs on plant ``kind``."""
        if kind not in PLANT_SUFFIX:
            raise CatalogError("kind", f"unknown plant kind {kind!r}; {closest(kind, KINDS)}")
        if kind not in self.sets:
            raise CatalogError("kind", f"control law {self.name} is not available for the {kind} plant")

    def default_set(self, kind: str) -> str:
        """The parameter set used when none is named."""
        return self.sets[kind][0]

    def set_values(self, kind: str, parameter_set: str) -> dict[str, Any]:
        """The values a named parameter set gives (only the parameters it fixes)."""
        self.check(kind)
        sets = self.sets[kind]
        if parameter_set not in sets:
            raise CatalogError("parameter_set", f"{self.model_name(kind)} has no parameter set {parameter_set!r}; "
                                                f"{closest(parameter_set, sets)}")
        return self.values(kind, parameter_set)

    def schema(self, kind: str) -> list[ParamSpec]:
        """Every parameter of the law on ``kind``, with the default set's values as defaults."""
        self.check(kind)
        specs = common_specs() + self.specs(kind)
        values = self.set_values(kind, self.default_set(kind))
        return [replace(s, default=values.get(s.name, s.default)) for s in specs]

    def defaults(self, kind: str) -> dict[str, Any]:
        """``{name: default}`` of every parameter (``schema``)."""
        return {s.name: s.default for s in self.schema(kind)}

    def checked_values(self, kind: str, values: Mapping[str, Any] | None) -> dict[str, Any]:
        """Every parameter of the law: the given values over the defaults, each checked against its schema."""
        spec = {s.name: s for s in self.schema(kind)}
        v = {name: s.default for name, s in spec.items()}
        for name, value in (values or {}).items():
            if name not in spec:
                raise CatalogError(name, f"{self.model_name(kind)} has no parameter {name!r}; {closest(name, spec)}")
            v[name] = value
        for name, s in spec.items():
            reason = s.check(v[name])
            if reason:
                unit = f" {s.unit}" if s.unit and s.unit != "1" else ""
                raise ControllerParameterError(name, f"parameter {name} = {v[name]}{unit}: {reason}")
        return v

    def make(self, kind: str, values: Mapping[str, Any] | None = None, backend: str = "control") -> DiscreteLaw:
        """The law from flat parameter values (missing ones take their defaults), each checked first."""
        return self.build(kind, self.checked_values(kind, values), backend)

    def design_parameters(self, kind: str) -> tuple[str, ...]:
        """Every parameter a designed law's gains depend on: weights, ``model_*``, ``sample_period``."""
        assert self.designed is not None, f"{self.name} has no designed gains"
        return (*self.designed.weight_parameters(kind), *(s.name for s in model_specs(kind)), "sample_period")
