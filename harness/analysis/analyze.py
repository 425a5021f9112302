"""Linear analysis of a scenario's closed loop: margins, sensitivity, closed-loop poles, limits.

The loop is broken at the plant input (the voltage). The plant is the scenario's plant linearized
about upright *with* the motor inductance (``ipcosim.fmus.linearize``), discretized exactly with a
zero-order hold at the controller's sample period; the controller is the law of the scenario's
controller component as a linear discrete system (``ipcosim.harness.analysis.linear_law``). Their product
``L(z) = -C(z) P(z)`` is the loop transfer function at the plant input of the sampled-data loop,
exact at the sample instants, so ``L(e^{jwT})`` for ``0 < w < pi/T`` is its frequency response.

Reported (``analyze``):

* closed-loop poles (eigenvalues of the interconnection; ``z`` and ``s = ln(z)/T``) and stability;
* gain margins: the range of a real gain ``k`` in front of the plant for which the loop stays
  stable (upper and lower limits: a loop around an unstable plant has both), from the phase
  crossovers, each limit checked by the closed-loop poles just inside and outside it;
* phase margin at every gain crossover and the delay margin ``min (PM_i mod 2 pi) / w_i``;
* peak of the sensitivity ``S = 1/(1 + L)`` and of ``T = L/(1 + L)`` over frequency;
* the limit cycle each cart's Coulomb friction would drive, by the describing function
  (``ipcosim.harness.analysis.limit_cycle``): its frequency and the amplitude of every measured signal;
* the plant's right-half-plane zeros and poles from the voltage to the motor-cart position and
  the lower bound they put on ``||S||inf`` and ``||T||inf`` of *every* stabilizing controller
  that measures that position only (Skogestad & Postlethwaite, *Multivariable Feedback
  Control*, Thm. 5.3): ``|(z + p)/(z - p)|`` for one real RHP zero ``z`` and one RHP pole ``p``;
  the same for the sampled plant, ``|1 - conj(p) z| / |z - p|`` outside the unit circle.

Not part of the FMU runtime: it needs python-control, numpy and, for the figures (``analyze_plots``),
matplotlib.
"""
from __future__ import annotations

import cmath
import functools
import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import control
import numpy as np

from ipcosim.controllers.catalog import LAWS, REGISTRY, build_law, entry, model_name
from ipcosim.errors import IpcosimError, UsageError
from ipcosim.fmus.kinds import PLANT_MODELS
from ipcosim.fmus.linearize import linearize
from ipcosim.fmus.params import DEFAULT_PRESET, KINDS, PLANT_KINDS, ParameterError, preset
from ipcosim.fmus.physics import MEASURED
from ipcosim.harness.analysis import limit_cycle
from ipcosim.harness.analysis.linear_law import LinearLaw, linear_law


class AnalysisError(IpcosimError, ValueError):
    """A scenario whose loop cannot be analysed (no controller or plant this module knows)."""


# ----------------------------------------------------------------------------- the loop
@dataclass(frozen=True)
class Loop:
    """The sampled-data loop broken at the plant input.

    Attributes
    ----------
    plant : control.StateSpace
        Discrete plant, voltage -> measured positions (ZOH, sample period ``T``).
    plant_continuous : control.StateSpace
        The same, continuous (with the inductance).
    controller : LinearLaw
        Measured positions -> voltage.
    L : control.StateSpace
        ``-C(z) P(z)``: the loop transfer function at the plant input (1 x 1, discrete).
    """

    law: str
    kind: str
    T: float
    plant: Any
    plant_continuous: Any
    controller: LinearLaw
    L: Any
    law_object: Any = None
    plant_values: Mapping[str, float] = field(default_factory=dict)


def make_loop(law_name: str, kind: str, law_values: Mapping[str, Any], plant_values: Mapping[str, float]) -> Loop:
    """The loop of ``law_name`` (flat catalog values) around the ``kind`` plant (preset overrides).

    Raises
    ------
    ControllerParameterError, ParameterError
        A bad law or plant parameter (naming it).
    """
    law, lin = _law_and_model(kind, law_name, tuple(sorted(dict(law_values).items(), key=lambda kv: kv[0])))
    params = preset(DEFAULT_PRESET[kind], **dict(plant_values))
    model = linearize(params, inductance=True)
    pc = control.ss(model.A, model.B, model.C, model.D)
    return loop_from(pc, lin, law_name, kind, law, dict(plant_values))


def _law_and_model(kind: str, law_name: str, values: tuple) -> tuple[Any, LinearLaw]:
    """The law and its linear model (kept for the last few sets of values: a sweep's runs share their law)."""
    try:
        return _cached_law(kind, law_name, values)
    except TypeError:   # a value that cannot be a key (a list): built each time
        law = build_law(kind, law_name, dict(values))
        return law, linear_law(law)


@functools.lru_cache(maxsize=8)
def _cached_law(kind: str, law_name: str, values: tuple) -> tuple[Any, LinearLaw]:
    law = build_law(kind, law_name, dict(values))
    return law, linear_law(law)


def loop_from(plant_continuous: Any, controller: LinearLaw, law: str = "", kind: str = "",
              law_object: Any = None, plant_values: Mapping[str, float] | None = None) -> Loop:
    """The loop of a continuous plant (voltage -> measurements) sampled with a zero-order hold at
    the controller's period, closed by ``controller`` (``u = C(z) y``)."""
    pd = control.c2d(plant_continuous, controller.T, method="zoh")
    cd = control.ss(controller.A, controller.B, controller.C, controller.D, controller.T)
    L = -control.series(pd, cd)
    return Loop(law, kind, controller.T, pd, plant_continuous, controller, L, law_object, dict(plant_values or {}))


def binding_values(component) -> dict[str, Any]:
    """The values a scenario's parameter bindings give a component, by parameter name."""
    values: dict[str, Any] = {}
    for pset in component.bindings:
        for p in pset.parameters:
            values[p.name] = p.value
    return values


def scenario_loop(scenario: str, parameter_set: str | None = None,
                  set: Mapping[str, float] | None = None) -> tuple[Loop, dict[str, Any]]:
    """The loop of a scenario's ``controller`` and ``plant`` components (with the ``--set`` values ``set``).

    Returns
    -------
    (Loop, dict)
        The loop and a description (scenario, law, kind, parameter set, plant parameters set).
    """
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = load_scenario(scenario)
    if parameter_set:
        sc = select_parameter_set(sc, parameter_set)
    loop, info, _ = loop_of_scenario(sc, set)
    info["parameter_set"] = parameter_set or (sc.bound_sets[0] if sc.bound_sets else "default")
    return loop, info


def loop_of_scenario(sc: Any, set: Mapping[str, Any] | None = None,
                     law_overrides: Mapping[str, Any] | None = None) -> tuple[Loop, dict[str, Any], dict[str, Any]]:
    """The loop of a parsed scenario's ``controller`` and ``plant`` (its bound values, then ``set``, then the
    law's ``law_overrides``): ``(loop, description, every plant value bound or set)``."""
    from pathlib import PurePosixPath

    try:
        ctrl, plant = sc.component("controller"), sc.component("plant")
    except KeyError as exc:
        raise AnalysisError(str(exc).strip("'\"")) from None
    ctrl_model, plant_model = PurePosixPath(ctrl.source).stem, PurePosixPath(plant.source).stem
    found = [(lw, k) for lw in LAWS for k in KINDS if model_name(k, lw) == ctrl_model]
    if not found:
        raise AnalysisError(f"{sc.origin}: controller {ctrl_model!r} is not a law of the catalog; analyze "
                            f"knows {', '.join(model_name(k, lw) for lw in LAWS for k in KINDS)}")
    kind_plant = PLANT_MODELS.get(plant_model)
    if kind_plant is None:
        raise AnalysisError(f"{sc.origin}: plant {plant_model!r} is not a plant model analyze knows "
                            f"({', '.join(PLANT_MODELS)})")
    law_name, kind = found[0]
    law_values, plant_values = binding_values(ctrl), binding_values(plant)
    for key, value in (set or {}).items():
        comp, _, var = key.partition(".")
        if comp not in ("controller", "plant"):
            raise UsageError(f"--set {key}: analyze uses the controller's and plant's parameters only")
        (law_values if comp == "controller" else plant_values)[var] = value
    law_values.update(law_overrides or {})
    phys = {f for f in PLANT_KINDS[kind_plant].__dataclass_fields__}
    plant_phys = {k: float(v) for k, v in plant_values.items() if k in phys}
    try:
        loop = make_loop(law_name, kind, law_values, plant_phys)
    except ParameterError as exc:
        raise AnalysisError(f"{sc.origin}: plant: {exc}") from None
    return loop, {"scenario": sc.name, "law": law_name, "kind": kind, "controller": ctrl_model,
                  "plant_parameters": plant_phys}, plant_values


# ----------------------------------------------------------------------------- frequency response
def frequency_grid(T: float, n: int = 6000, w_min: float = 1e-2) -> np.ndarray:
    """Log-spaced frequencies [rad/s] from ``w_min`` to the Nyquist frequency pi/T."""
    return np.logspace(math.log10(w_min), math.log10(math.pi / T), n)


def loop_response(loop: Loop, w: np.ndarray) -> np.ndarray:
    """``L(e^{jwT})`` at the frequencies ``w`` [rad/s]."""
    A, B, C, D = (np.asarray(m) for m in (loop.L.A, loop.L.B, loop.L.C, loop.L.D))
    n = A.shape[0]
    out = np.empty(len(w), dtype=complex)
    eye = np.eye(n)
    for i, wi in enumerate(w):
        z = cmath.exp(1j * wi * loop.T)
        out[i] = (C @ np.linalg.solve(z * eye - A, B) + D)[0, 0]
    return out


def closed_loop_poles(loop: Loop, gain: float = 1.0) -> np.ndarray:
    """Poles (z) of the loop closed with ``gain`` in front of the plant (u_plant = gain u_ctrl)."""
    return np.linalg.eigvals(np.asarray(control.feedback(loop.L * gain, 1, sign=-1).A))


def is_stable(poles: np.ndarray, tol: float = 1e-9) -> bool:
    """All discrete poles strictly inside the unit circle."""
    return bool(np.all(np.abs(poles) < 1.0 - tol))


def _crossings(w: np.ndarray, f: np.ndarray) -> list[int]:
    return [i for i in range(len(w) - 1) if f[i] == 0 or (f[i] < 0) != (f[i + 1] < 0)]


def _refine(loop: Loop, w0: float, w1: float, fn, iters: int = 60) -> float:
    f0 = fn(loop_response(loop, np.array([w0]))[0])
    for _ in range(iters):
        wm = math.sqrt(w0 * w1)
        fm = fn(loop_response(loop, np.array([wm]))[0])
        if (fm < 0) == (f0 < 0):
            w0, f0 = wm, fm
        else:
            w1 = wm
    return math.sqrt(w0 * w1)


def gain_margins(loop: Loop, w: np.ndarray, Lw: np.ndarray) -> dict[str, Any]:
    """Range of real gains in front of the plant that keep the loop stable (around k = 1)."""
    candidates = []
    for i in _crossings(w, Lw.imag):
        wc = _refine(loop, w[i], w[i + 1], lambda v: v.imag)
        Lc = loop_response(loop, np.array([wc]))[0]
        if Lc.real < 0:
            candidates.append((-1.0 / Lc.real, wc))
    L_nyq = loop_response(loop, np.array([math.pi / loop.T]))[0]  # z = -1: L is real there
    if L_nyq.real < 0:
        candidates.append((-1.0 / L_nyq.real, math.pi / loop.T))
    L_dc = _dc_response(loop)  # z = 1: L is real there too (a loop without integrator can lose it at rest)
    if L_dc is not None and L_dc < 0:
        candidates.append((-1.0 / L_dc, 0.0))
    upper = [(k, wc) for k, wc in candidates if k > 1.0]
    lower = [(k, wc) for k, wc in candidates if 0 < k < 1.0]
    up = min(upper) if upper else (math.inf, None)
    lo = max(lower) if lower else (0.0, None)
    return {"upper": up[0], "upper_frequency_rad_s": up[1], "lower": lo[0], "lower_frequency_rad_s": lo[1]}


def _dc_response(loop: Loop) -> float | None:
    """``L(1)``, the loop's gain at rest (z = 1), or None where ``L`` has a pole there (an integrator)."""
    A, B, C, D = (np.asarray(m) for m in (loop.L.A, loop.L.B, loop.L.C, loop.L.D))
    M = np.eye(A.shape[0]) - A
    if A.shape[0] and np.linalg.cond(M) > 1e12:
        return None
    return float((C @ np.linalg.solve(M, B) + D)[0, 0].real) if A.shape[0] else float(D[0, 0])


def phase_margins(loop: Loop, w: np.ndarray, Lw: np.ndarray) -> list[dict[str, float]]:
    """Phase margin and delay margin at every gain crossover (|L| = 1)."""
    out = []
    for i in _crossings(w, np.abs(Lw) - 1.0):
        wc = _refine(loop, w[i], w[i + 1], lambda v: abs(v) - 1.0)
        Lc = loop_response(loop, np.array([wc]))[0]
        pm = math.degrees(cmath.phase(-Lc))  # angle of L measured from -180 deg
        delay = math.radians(pm % 360.0) / wc
        out.append({"frequency_rad_s": wc, "phase_margin_deg": pm, "delay_margin_s": delay})
    return out


def worst_phase_margin(pms: Sequence[Mapping[str, float]]) -> float | None:
    """The phase margin [deg] of the loop: at the gain crossover whose phase is nearest -180 deg (the smallest
    ``|phase_margin_deg|`` of :func:`phase_margins`; a loop around an unstable plant crosses several times), or
    None without a crossover."""
    return min((d["phase_margin_deg"] for d in pms), key=abs, default=None)


def loop_limits(loop: Loop, n: int = 1500) -> tuple[float, float, float] | None:
    """``(peak |S|, delay margin [s], |phase margin| [deg])`` of a loop on an ``n``-point grid (what a tuner
    constrains, cheaper than :func:`analyze_loop`), or None when the closed loop is unstable. No gain
    crossover: infinite margins."""
    if not is_stable(closed_loop_poles(loop)):
        return None
    w = frequency_grid(loop.T, n)
    Lw = loop_response(loop, w)
    pms = phase_margins(loop, w, Lw)
    pm = worst_phase_margin(pms)
    return (peak(loop, w, np.abs(1.0 / (1.0 + Lw)))[0], min((d["delay_margin_s"] for d in pms), default=math.inf),
            math.inf if pm is None else abs(pm))


# ----------------------------------------------------------------------------- disk and sensor margins
def disk_margin(loop: Loop, w: np.ndarray, Lw: np.ndarray) -> dict[str, float]:
    """The balanced (skew 0) disk margin of the loop: ``control.disk_margins`` on a fine grid between the neighbours
    of the point of ``w`` where ``|S - 1/2|`` (from the loop's response ``Lw``) peaks.

    ``alpha = 1 / max_w |S - 1/2|`` (Seiler, Packard and Gahinet, "An introduction to disk margins", 2020): the
    loop stays stable for every complex gain ``(1 + alpha/2 d) / (1 - alpha/2 d)``, ``|d| <= 1``, in front of it,
    i.e. for simultaneous gain factors in ``[(1 - alpha/2)/(1 + alpha/2), (1 + alpha/2)/(1 - alpha/2)]`` and
    phase changes of ``+-2 atan(alpha/2)``.
    """
    dev = np.abs(1.0 / (1.0 + Lw) - 0.5)
    i = int(np.argmax(dev))
    grid = np.linspace(w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)], 401)
    alphas = control.disk_margins(loop.L, grid, skew=0.0, returnall=True)[0]
    k = int(np.argmin(alphas))
    alpha = float(alphas[k])
    g = (1 + alpha / 2) / (1 - alpha / 2) if alpha < 2 else math.inf
    return {"alpha": alpha, "frequency_rad_s": float(grid[k]), "gain_lower": 1 / g if math.isfinite(g) else 0.0,
            "gain_upper": g if math.isfinite(g) else None,
            "gain_dB": 20 * math.log10(g) if math.isfinite(g) else None,
            "phase_deg": math.degrees(2 * math.atan(alpha / 2))}


def sensor_loop(loop: Loop, j: int) -> Loop:
    """The loop broken at the controller's ``j``-th measurement, every other loop closed (loop at a time).

    ``L_j`` is minus the response from the ``j``-th input of the controller to the ``j``-th output of the plant, so
    ``closed_loop_poles(sensor_loop(loop, j), k)`` are the poles with the reading multiplied by ``k``, and the
    margins of ``L_j`` are those of a gain or a delay on that sensor alone.
    """
    pd, c = loop.plant, loop.controller
    Ap, Bp, Cp, Dp = (np.asarray(m) for m in (pd.A, pd.B, pd.C, pd.D))
    if not np.allclose(Dp, 0):
        raise AnalysisError("the sampled plant has a direct feedthrough: no sensor loop is built for it")
    E = np.eye(Cp.shape[0])
    E[j, j] = 0.0                  # the controller reads every output but the j-th from the plant
    A = np.block([[Ap + Bp @ c.D @ E @ Cp, Bp @ c.C], [c.B @ E @ Cp, c.A]])
    B = np.vstack([Bp @ c.D[:, [j]], c.B[:, [j]]])
    C = np.hstack([Cp[[j]], np.zeros((1, c.A.shape[0]))])
    return replace(loop, L=-control.ss(A, B, C, np.zeros((1, 1)), loop.T))


def break_point_margins(loop: Loop, w: np.ndarray, Lw: np.ndarray | None = None) -> dict[str, Any]:
    """Gain range (checked by the closed-loop poles), phase and delay margins and disk margin of one broken loop."""
    Lw = loop_response(loop, w) if Lw is None else Lw
    gm = gain_margins(loop, w, Lw)
    gm["checked"] = _check_gain_limits(loop, gm)
    pms = phase_margins(loop, w, Lw)
    return {"gain_lower": gm["lower"], "gain_upper": gm["upper"] if math.isfinite(gm["upper"]) else None,
            "gain_lower_frequency_rad_s": gm["lower_frequency_rad_s"],
            "gain_upper_frequency_rad_s": gm["upper_frequency_rad_s"], "gain_checked": gm["checked"],
            "phase_margin_deg": worst_phase_margin(pms),
            "delay_margin_s": min((d["delay_margin_s"] for d in pms), default=None),
            "disk_margin": disk_margin(loop, w, Lw)}


def sensor_margins(loop: Loop, outputs: Sequence[str], w: np.ndarray) -> dict[str, dict[str, Any]]:
    """:func:`break_point_margins` of the loop broken at each measurement (``outputs``: the plant's measured names)."""
    return {name: break_point_margins(sensor_loop(loop, j), w) for j, name in enumerate(outputs)}


def peak(loop: Loop, w: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """Largest value on the grid and its frequency."""
    i = int(np.argmax(values))
    return float(values[i]), float(w[i])


# ----------------------------------------------------------------------------- limits
def _rhp(values: np.ndarray, discrete: bool) -> list[complex]:
    if discrete:
        return [complex(v) for v in values if abs(v) > 1.0 + 1e-9]
    return [complex(v) for v in values if v.real > 1e-9]


def _bound(zeros: list[complex], poles: list[complex], discrete: bool) -> float:
    """Thm. 5.3 lower bound on ||S||inf (= on ||T||inf for one zero and one pole)."""
    best = 1.0
    for z in zeros:
        prod = 1.0
        for p in poles:
            num = abs(1 - p.conjugate() * z) if discrete else abs(z + p.conjugate())
            prod *= num / abs(z - p)
        best = max(best, prod)
    return best


def position_only_limit(loop: Loop) -> dict[str, Any]:
    """RHP zeros/poles of voltage -> motor-cart position and the bound on ||S||inf they impose.

    The bound holds for every linear time-invariant controller that stabilizes the plant from
    that one measurement. It also gives the smallest multiplicative input uncertainty that some
    such loop cannot survive: robust stability needs ``||T||inf < 1/delta``.
    """
    pc, pd = loop.plant_continuous[0, 0], loop.plant[0, 0]
    zc, pcp = _rhp(control.zeros(pc), False), _rhp(control.poles(pc), False)
    zd, pdp = _rhp(control.zeros(pd), True), _rhp(control.poles(pd), True)
    bc, bd = _bound(zc, pcp, False), _bound(zd, pdp, True)
    uses_only_position = bool(np.all(loop.controller.B[:, 1:] == 0) and np.all(loop.controller.D[:, 1:] == 0))
    return {"output": "motor-cart position", "rhp_zeros_rad_s": [z.real for z in zc],
            "rhp_poles_rad_s": [p.real for p in pcp], "sensitivity_peak_lower_bound": bc,
            "sensitivity_peak_lower_bound_dB": 20 * math.log10(bc),
            "sampled_rhp_zeros_z": [z.real for z in zd], "sampled_rhp_poles_z": [p.real for p in pdp],
            "sampled_sensitivity_peak_lower_bound": bd,
            "largest_tolerable_input_uncertainty": 1.0 / bc,
            "strongly_stabilizable": _parity_interlacing(zc, pcp, pc),
            "controller_uses_this_output_only": uses_only_position}


def _parity_interlacing(zeros: list[complex], poles: list[complex], pc) -> bool:
    """Youla's parity interlacing property: a stable controller can stabilize the plant iff the
    number of real RHP poles between every pair of real RHP zeros (infinity counts when the plant
    is strictly proper) is even."""
    real_z = sorted(z.real for z in zeros if abs(z.imag) < 1e-9)
    if np.allclose(np.asarray(pc.D), 0):
        real_z.append(math.inf)
    real_p = [p.real for p in poles if abs(p.imag) < 1e-9]
    return all(sum(1 for p in real_p if a < p < b) % 2 == 0 for a, b in zip(real_z, real_z[1:]))


def _closed_loop_matrix(pd, lin: LinearLaw) -> np.ndarray:
    Ap, Bp, Cp = (np.asarray(m) for m in (pd.A, pd.B, pd.C))
    top = np.hstack([Ap + Bp @ lin.D @ Cp, Bp @ lin.C])
    bottom = np.hstack([lin.B @ Cp, lin.A])
    return np.vstack([top, bottom])


def pid_gain_search(loop: Loop) -> dict[str, Any]:
    """Signed log grid of PID gains (the law's own filter and sample period): how many stabilize.

    Evidence beside the parity-interlacing argument, not a proof: the grid spans Kp 0.1..1e7 V/m,
    Ki 0.1..1e9 V/(m s), Kd 0.01..1e4 V s/m, each with both signs and zero.
    """
    from ipcosim.controllers.laws.pid import PID, PIDGains

    own = entry(loop.law).pid_gain_search  # the loop's law is the PID: its own derivative filter
    tau = float(loop.law_object.gains.derivative_time_constant) if own else 1e-3

    def signed(lo: int, hi: int, n: int) -> np.ndarray:
        v = np.logspace(lo, hi, n)
        return np.concatenate([-v[::-1], [0.0], v])

    kps, kis, kds = signed(-1, 7, 17), signed(-1, 9, 11), signed(-2, 4, 13)
    stable, best = 0, math.inf
    for kp in kps:
        for ki in kis:
            for kd in kds:
                law = PID(loop.kind, PIDGains(kp, ki, kd, tau), loop.T, 1e9)
                rho = float(np.max(np.abs(np.linalg.eigvals(_closed_loop_matrix(loop.plant, linear_law(law))))))
                best = min(best, rho)
                stable += rho < 1.0
    return {"gain_sets": int(len(kps) * len(kis) * len(kds)), "stabilizing": int(stable),
            "smallest_spectral_radius": best}



# ----------------------------------------------------------------------------- the report
def _poles_json(zs: np.ndarray, T: float) -> list[dict[str, float]]:
    out = []
    for z in sorted(zs, key=lambda v: -abs(v)):
        s = cmath.log(z) / T if abs(z) > 0 else complex(-math.inf, 0.0)
        out.append({"z_re": float(z.real), "z_im": float(z.imag), "z_abs": float(abs(z)),
                    "s_re": float(s.real), "s_im": float(s.imag)})
    return out


def analyze_loop(loop: Loop, pid_search: bool | None = None) -> dict[str, Any]:
    """Margins, sensitivity peaks, closed-loop poles and the position-only limit of a loop.

    Parameters
    ----------
    loop : Loop
        From ``make_loop`` or ``scenario_loop``.
    pid_search : bool, optional
        Run ``pid_gain_search`` (default: for a PID loop).

    Returns
    -------
    dict
        JSON-ready; margins are ``None`` when the closed loop is unstable (they do not apply).
    """
    w = frequency_grid(loop.T)
    Lw = loop_response(loop, w)
    cl = closed_loop_poles(loop)
    stable = is_stable(cl)
    S, Tc = np.abs(1.0 / (1.0 + Lw)), np.abs(Lw / (1.0 + Lw))
    ms, w_ms = peak(loop, w, S)
    mt, w_mt = peak(loop, w, Tc)
    out: dict[str, Any] = {
        "loop": "broken at the plant input (voltage); sampled-data loop, ZOH, exact at the sample instants",
        "sample_period_s": loop.T, "closed_loop_stable": stable,
        "closed_loop_spectral_radius": float(np.max(np.abs(cl))),
        "closed_loop_marginal": bool(not stable and abs(float(np.max(np.abs(cl))) - 1.0) < 1e-7),
        "open_loop_unstable_poles": int(sum(abs(p) > 1 + 1e-9 for p in np.linalg.eigvals(np.asarray(loop.L.A)))),
        "peak_sensitivity": ms, "peak_sensitivity_dB": 20 * math.log10(ms), "peak_sensitivity_frequency_rad_s": w_ms,
        "peak_complementary_sensitivity": mt, "peak_complementary_sensitivity_frequency_rad_s": w_mt,
        "modulus_margin": 1.0 / ms, "notes": list(loop.controller.notes),
        "closed_loop_poles": _poles_json(cl, loop.T),
        "position_only_limit": position_only_limit(loop),
    }
    if stable:
        gm = gain_margins(loop, w, Lw)
        pms = phase_margins(loop, w, Lw)
        gm["upper_dB"] = 20 * math.log10(gm["upper"]) if math.isfinite(gm["upper"]) else None
        gm["lower_dB"] = 20 * math.log10(gm["lower"]) if gm["lower"] > 0 else None
        gm["checked"] = _check_gain_limits(loop, gm)
        out["gain_margin"] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in gm.items()}
        out["phase_margins"] = pms
        out["phase_margin_deg"] = worst_phase_margin(pms)
        out["delay_margin_s"] = min(d["delay_margin_s"] for d in pms) if pms else None
        out["delay_margin_samples"] = out["delay_margin_s"] / loop.T if pms else None
        out["disk_margin"] = disk_margin(loop, w, Lw)
        out["sensor_margins"] = sensor_margins(loop, MEASURED[loop.kind] if loop.kind else (), w)
    else:  # no margins, and the frequency-domain peaks describe no stable loop
        out.update(gain_margin=None, phase_margins=[], phase_margin_deg=None, delay_margin_s=None,
                   delay_margin_samples=None, peak_sensitivity=None, peak_sensitivity_dB=None,
                   peak_sensitivity_frequency_rad_s=None, peak_complementary_sensitivity=None,
                   peak_complementary_sensitivity_frequency_rad_s=None, modulus_margin=None,
                   disk_margin=None, sensor_margins={})
    out["friction_limit_cycles"] = limit_cycle.report(loop, stable)
    if pid_search if pid_search is not None else loop.law in REGISTRY and entry(loop.law).pid_gain_search:
        out["pid_gain_search"] = pid_gain_search(loop)
    out["statement"] = statement(out)
    return out


def _check_gain_limits(loop: Loop, gm: dict[str, Any]) -> bool:
    """The closed loop is stable just inside each gain limit and unstable just outside it."""
    ok = True
    for key, inside, outside in (("upper", 0.999, 1.001), ("lower", 1.001, 0.999)):
        k = gm[key]
        if k and math.isfinite(k):
            ok &= is_stable(closed_loop_poles(loop, k * inside)) and not is_stable(closed_loop_poles(loop, k * outside))
    return bool(ok)


def statement(result: Mapping[str, Any]) -> str:
    """One paragraph: what the numbers say about the loop and the position-only limit."""
    lim = result["position_only_limit"]
    z, p = lim["rhp_zeros_rad_s"], lim["rhp_poles_rad_s"]
    parts = []
    if result["closed_loop_stable"]:
        parts.append(f"The sampled loop is stable: peak sensitivity {result['peak_sensitivity']:.3g} "
                     f"({result['peak_sensitivity_dB']:.1f} dB), delay margin "
                     f"{result['delay_margin_s'] * 1e3:.3g} ms.")
    elif result["closed_loop_marginal"]:
        parts.append("The sampled loop is marginally stable (a closed-loop pole at z = 1 to rounding: two integrators "
                     "of which the loop drives only a combination): no margins are given.")
    else:
        parts.append(f"The sampled loop is unstable (spectral radius {result['closed_loop_spectral_radius']:.4g}): "
                     "its margins do not exist.")
    if z and p:
        parts.append(
            f"From the voltage to the motor-cart position the plant has a right-half-plane zero at "
            f"{', '.join(f'{v:.4g}' for v in z)} rad/s and a right-half-plane pole at "
            f"{', '.join(f'{v:.4g}' for v in p)} rad/s. Every linear controller that measures that position only "
            f"and stabilizes the loop has ||S||inf = ||T||inf >= |(z + p)/(z - p)| = "
            f"{lim['sensitivity_peak_lower_bound']:.4g} ({lim['sensitivity_peak_lower_bound_dB']:.1f} dB; sampled "
            f"at {result['sample_period_s'] * 1e3:g} ms: >= {lim['sampled_sensitivity_peak_lower_bound']:.4g}), so a "
            f"multiplicative input uncertainty of {100 * lim['largest_tolerable_input_uncertainty']:.2g} % can "
            "destabilize it.")
        if not lim["controller_uses_this_output_only"]:
            parts.append("This controller also measures the pendulum angle, so the bound does not bind it.")
        if not lim["strongly_stabilizable"]:
            parts.append("Between the zero and the zero at infinity lies an odd number of real poles (parity "
                         "interlacing): only an unstable controller can stabilize the plant from this "
                         "measurement, so no PID (poles at z = 1 and inside the unit circle) can.")
    search = result.get("pid_gain_search")
    if search:
        parts.append(f"A signed grid of {search['gain_sets']} PID gain sets stabilizes the sampled loop in "
                     f"{search['stabilizing']} cases (smallest spectral radius "
                     f"{search['smallest_spectral_radius']:.4g}).")
    return " ".join(parts)
