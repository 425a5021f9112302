"""The residual cycle of a loop on the lab bench: every cart's Coulomb friction and every encoder's counts at once.

Each nonlinearity is replaced by its describing function, a real gain that depends on the amplitude of the
sinusoid at its input (Slotine & Li, *Applied Nonlinear Control*, ch. 5; Gelb & Vander Velde, *Multiple-Input
Describing Functions*, 1968):

* the Coulomb friction ``-b sign(v)`` of a cart, a relay on its velocity: ``N(A) = 4 b / (pi A)``, a viscous
  damping that shrinks as the cart swings faster (``describing.relay_gain``);
* the mid-tread quantizer of an encoder of step ``q`` (a reading is the nearest count) on the measured signal:
  ``N(A) = (4 q / (pi A)) sum_{k=1..n} sqrt(1 - ((2k - 1) q / (2 A))^2)`` for ``A > q/2``, ``n`` the thresholds
  ``(k - 1/2) q`` below ``A``, and 0 below the first threshold (``describing.quantizer_gain``): no reading changes, the
  law does not see the signal at all.

The quasi-linear loop is the sampled loop of ``ipcosim.harness.analysis.limit_cycle.closed_loop`` (the plant with
its inductance, zero-order hold, the law's linear transcription), with each friction gain a force on its cart
against the cart's velocity, each quantizer gain in front of the law's reading of its signal, and the lab bench's
computation delay (the voltage computed from one sample's readings acts from the next sample). The harmonic
balance of all the nonlinearities together is that this loop has a pair of eigenvalues ``e^{+-jwT}`` on the unit
circle, whose eigenvector swings every nonlinearity's input with the amplitude its gain was taken at. With the
amplitudes written ``s r`` (``r`` their ratios, one of them 1), :func:`predict_residual` alternates two steps
until the ratios settle: for the ratios ``r`` the largest scale ``s`` at which the loop's spectral radius reaches 1
(large ``s``: the gains of the linear loop, stable; small ``s``: a cart held by its friction, a signal the law
does not see, unstable), then the ratios the critical eigenvector gives. The cycle's frequency is that
eigenvalue's angle over ``T``; the amplitude of every measured signal is its eigenvector component at that scale.

A law's own Coulomb friction compensation (the LQG's ``friction_<b>`` with its threshold ``friction_velocity``)
acts on the cart as a second nonlinearity of the same velocity: its describing function
(``describing.compensation_gain``) is taken off the relay's, as if the law's velocity estimate were the cart's velocity
(its lag is left out). Its breakaway term (:data:`LEFT_OUT_LAW_TERMS`) is left out. A law's dither (a square
wave of voltage at half the sample rate) swings each cart's velocity by a triangle of half-width
``describing.dither_velocity`` about the slow cycle: the plant's friction is averaged over that triangle
(``describing.dithered_relay_gain``, a saturation), the law's compensation over the two velocities it reads
(``describing.compensation_gain``); what the dither does to the encoders (a fraction of a micrometre) is left out.

Where the approximation is weak (``docs/studies.md``, "The residual cycle"): the describing functions keep the
first harmonic only, and the quantizer's is worst at the amplitudes the cycle sits at (a few counts: the reading
is a square-ish wave); all the nonlinearities are taken to swing at one frequency, in the phase the linear loop
gives them, about a count level (an offset between the signal's centre and the count grid changes the quantizer's
gain); stiction above the kinetic force, the DAC's codes and a law's nonlinear breakaway term are left out;
whether the cycle is stable is not checked. The sticking phases of stick-slip (the relay's describing function
assumes a cart that never dwells at rest) are taken in one way only: on the double mass the motor cart's travel
while the passive cart rests, ``2 b2 / K``, is added to its peak-to-peak (:func:`with_windup`).
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ipcosim.errors import IpcosimError
from ipcosim.fmus.linearize import COULOMB_CARTS
from ipcosim.fmus.physics import MEASURED
from ipcosim.harness.analysis.describing import (
    compensation_gain,
    dither_velocity,
    dithered_relay_gain,
    quantizer_gain,
    reading_peak_to_peak,
)

#: Largest loop the bound searches from (nonlinearity input amplitudes scale as s r) and the smallest [the ratios'
#: units: m, rad, m/s].
SCALE_RANGE = (1e1, 1e-9)
#: Points of the scale's log grid searched for the loop's last crossing of the unit circle.
SCALE_GRID = 90
#: Thresholds of each encoder where the search looks for a crossing beside the grid: a quantizer's gain dips
#: below 1 just under each threshold (0.80 at 1.5 counts, 0.91 at 2.5, 0.94 at 3.5: a loop that tolerates
#: little less gain on that signal balances there, a dip the grid would step over).
THRESHOLDS_SEARCHED = 30
#: Halvings of the grid step (in log s) that locate the crossing: 2^-32 of a grid step.
BISECTIONS = 32
#: Ratio iterations (fixed point) before the prediction gives up.
MAX_ITERATIONS = 60
#: The ratios have settled when none moves by more than this (relative).
RATIO_TOLERANCE = 1e-3
#: Eigenvalues this close to z = 1 are the loop's own integrators the nonlinearities do not move.
INTEGRATOR_TOLERANCE = 1e-9
#: A critical eigenvalue slower than this [rad/s] is a drift, not a cycle.
SLOWEST_CYCLE_RAD_S = 0.05


class NoCycle(IpcosimError, ArithmeticError):
    """The harmonic balance finds no cycle for this loop (the message says why)."""


@dataclass(frozen=True)
class _Nonlinearity:
    name: str          # the friction parameter (b, b1, b2) or the measured signal
    kind: str          # "friction" or "encoder"
    size: float        # Coulomb force [N] or encoder step [m or rad]
    row: np.ndarray    # its input: row over the closed-loop state
    compensated: float = 0.0   # the law's compensation of that force [N] (friction)
    threshold: float = 0.0     # the velocity from which the law starts compensating [m/s]
    dither: float = 0.0        # the velocity half-width of the law's dither on this cart [m/s] (friction)

    def gain(self, amplitude: float) -> float:
        if self.kind == "encoder":
            return quantizer_gain(amplitude, self.size)
        return (dithered_relay_gain(amplitude, self.size, self.dither)
                - compensation_gain(amplitude, self.compensated, self.threshold, self.dither))


class QuasiLinearLoop:
    """The sampled closed loop with each nonlinearity's describing gain in place (:meth:`matrix`).

    States: the plant's, the law's, then ``delay`` samples of the voltage in transit.
    """

    def __init__(self, loop: Any, params: Any, forces: Mapping[str, float], resolutions: Mapping[str, float],
                 delay: int, compensation: Mapping[str, tuple[float, float]] | None = None,
                 dither: float = 0.0) -> None:
        from ipcosim.harness.analysis.limit_cycle import sampled_plant

        model, _, Ad, Bd = sampled_plant(params, loop.T)
        n = len(model.states)
        law = loop.controller
        Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (law.A, law.B, law.C, law.D))
        self.states, self.T, self.kind = model.states, loop.T, loop.kind
        self.C = np.asarray(model.C)
        m, size = Ac.shape[0], n + Ac.shape[0] + delay
        self.n, self.size = n, size
        u_now = np.zeros((1, size))          # the voltage the law computes now, as a row over the state
        self.base = np.zeros((size, size))   # the loop with exact readings and no friction, less the reading terms
        self.base[:n, :n] = Ad
        self.base[n:n + m, n:n + m] = Ac
        u_now[0, n:n + m] = Cc[0]
        self.reading_in = np.zeros((size, len(self.C)))   # where each reading enters: the law's state and voltage
        self.reading_in[n:n + m] = Bc
        if delay:
            self.base[:n, n + m + delay - 1] = Bd[:, 0]
            self.base[n + m + 1:n + m + delay, n + m:n + m + delay - 1] = np.eye(delay - 1)
            out = n + m
        else:
            out = None
        self.voltage_row, self.voltage_col, self.Dc = out, Bd[:, :1], Dc
        if out is None:
            self.base[:n] += Bd[:, :1] @ u_now
        else:
            self.base[out] += u_now[0]
        self.nonlinearities: list[_Nonlinearity] = []
        self.friction_in: dict[str, np.ndarray] = {}
        self._add_nonlinearities(model, (Ad, Bd), forces, resolutions, compensation or {}, dither)

    def _add_nonlinearities(self, model: Any, sampled: tuple[np.ndarray, np.ndarray], forces: Mapping[str, float],
                            resolutions: Mapping[str, float], compensation: Mapping[str, tuple[float, float]],
                            dither: float) -> None:
        """Each cart with a Coulomb force (its velocity in, a force on it out; its velocity swing under the law's
        ``dither`` [V]) and each encoder with a step."""
        Ad, Bd = sampled
        pad = np.zeros(self.size - self.n)
        for j, (name, velocity) in enumerate(COULOMB_CARTS[self.kind]):
            if forces.get(name, 0.0) > 0.0:
                row = np.zeros(self.size)
                row[model.states.index(velocity)] = 1.0
                comp, threshold = compensation.get(name, (0.0, 0.0))
                swing = dither_velocity(Ad, Bd, model.states.index(velocity), dither) if dither else 0.0
                self.nonlinearities.append(_Nonlinearity(name, "friction", float(forces[name]), row, comp, threshold,
                                                         swing))
                self.friction_in[name] = np.concatenate([Bd[:, 1 + j], pad])
        for i, signal in enumerate(model.outputs):
            if resolutions.get(signal, 0.0) > 0.0:
                row = np.concatenate([self.C[i], pad])
                self.nonlinearities.append(_Nonlinearity(signal, "encoder", float(resolutions[signal]), row))

    def matrix(self, gains: Mapping[str, float]) -> np.ndarray:
        """The loop's matrix with these describing gains (a friction's damping [N s/m], an encoder's factor)."""
        phi = self.base.copy()
        reading = np.array([gains.get(s, 1.0) for s in MEASURED[self.kind]])[:, None] * self.C  # y_law = N C x
        phi[:, :self.n] += self.reading_in @ reading
        direct = self.Dc @ reading                                  # the law's feedthrough of the readings
        if self.voltage_row is None:
            phi[:self.n, :self.n] += self.voltage_col @ direct
        else:
            phi[self.voltage_row, :self.n] += direct[0]
        for nl in self.nonlinearities:
            if nl.kind == "friction":   # the force -N v on its cart, held over the sample
                phi -= gains[nl.name] * np.outer(self.friction_in[nl.name], nl.row)
        return phi

    def at(self, amplitudes: np.ndarray) -> np.ndarray:
        """:meth:`matrix` with each nonlinearity's gain at its input amplitude (``amplitudes``, in order)."""
        return self.matrix({nl.name: nl.gain(a) for nl, a in zip(self.nonlinearities, amplitudes)})


def _critical(phi: np.ndarray) -> tuple[float, complex, np.ndarray]:
    """``(spectral radius, that eigenvalue, its eigenvector)``, leaving out the loop's integrators at z = 1."""
    values, vectors = np.linalg.eig(phi)
    keep = np.abs(values - 1.0) > INTEGRATOR_TOLERANCE
    if not keep.any():
        return 0.0, 0j, vectors[:, 0]
    k = int(np.argmax(np.where(keep, np.abs(values), -1.0)))
    return float(abs(values[k])), complex(values[k]), vectors[:, k]


def _last_crossing(ql: QuasiLinearLoop, ratios: np.ndarray) -> float:
    """The largest scale ``s`` at which the loop with amplitudes ``s ratios`` reaches the unit circle."""
    hi, lo = SCALE_RANGE
    thresholds = [(k + 0.5) * nl.size / r for nl, r in zip(ql.nonlinearities, ratios) if nl.kind == "encoder"
                  for k in range(THRESHOLDS_SEARCHED)]     # each quantizer's gain dips lowest at its thresholds
    grid = np.array(sorted({*np.logspace(math.log10(hi), math.log10(lo), SCALE_GRID),
                            *(t for t in thresholds if lo < t < hi)}, reverse=True))
    if _critical(ql.at(grid[0] * ratios))[0] >= 1.0:
        raise NoCycle("the loop is unstable even at the largest amplitudes (its linear loop is not stable)")
    for a, b in zip(grid, grid[1:]):
        if _critical(ql.at(b * ratios))[0] >= 1.0:
            for _ in range(BISECTIONS):       # bisection in log s: stable at a, not at b
                mid = math.sqrt(a * b)
                a, b = (mid, b) if _critical(ql.at(mid * ratios))[0] < 1.0 else (a, mid)
            return math.sqrt(a * b)
    raise NoCycle("the loop stays stable at every amplitude: no cycle")


def harmonic_balance(ql: QuasiLinearLoop) -> dict[str, Any]:
    """Amplitudes and frequency at which every nonlinearity of ``ql`` balances (module docstring).

    Raises
    ------
    NoCycle
        No nonlinearity, no crossing, a drift instead of a cycle, or ratios that do not settle.
    """
    nls = ql.nonlinearities
    if not nls:
        raise NoCycle("no nonlinearity: the loop is linear")
    ratios = np.array([1e-2 if nl.kind == "friction" else nl.size for nl in nls])
    ratios = ratios / ratios[0]
    for _ in range(MAX_ITERATIONS):
        s = _last_crossing(ql, ratios)
        _, lam, vec = _critical(ql.at(s * ratios))
        seen = np.array([abs(nl.row @ vec) for nl in nls])
        if seen[0] == 0.0:
            raise NoCycle(f"the cycle does not reach {nls[0].name}")
        new = np.maximum(seen / seen[0], 1e-300)
        settled = np.all(np.abs(new - ratios) <= RATIO_TOLERANCE * new)
        ratios = new
        if settled:
            break
    else:
        raise NoCycle(f"the amplitude ratios did not settle in {MAX_ITERATIONS} iterations")
    s = _last_crossing(ql, ratios)
    _, lam, vec = _critical(ql.at(s * ratios))
    w = abs(cmath.phase(lam)) / ql.T
    if w < SLOWEST_CYCLE_RAD_S:
        raise NoCycle(f"the critical eigenvalue is real ({lam.real:.6g}): a drift, not a cycle")
    scale = s * ratios[0] / abs(nls[0].row @ vec)
    return {"frequency_Hz": w / (2 * math.pi), "scale": scale, "vector": vec,
            "amplitudes": {nl.name: float(s * r) for nl, r in zip(nls, ratios)},
            "gains": {nl.name: nl.gain(s * r) for nl, r in zip(nls, ratios)}}


def law_compensation(loop: Any) -> dict[str, tuple[float, float]]:
    """What the law compensates of each cart's Coulomb friction: ``{parameter: (force [N], threshold [m/s])}``
    (its ``friction`` in the carts' order and its ``friction_velocity``; empty for a law without)."""
    compensated = tuple(getattr(loop.law_object, "friction", ()) or ())
    threshold = float(getattr(loop.law_object, "friction_velocity", 0.0) or 0.0)
    return {name: (float(compensated[i]), threshold) for i, (name, _) in enumerate(COULOMB_CARTS[loop.kind])
            if i < len(compensated) and compensated[i] > 0}


def predict_residual(loop: Any, params: Any, forces: Mapping[str, float], resolutions: Mapping[str, float],
                     delay: int = 0) -> dict[str, Any]:
    """The residual cycle the lab bench's nonlinearities drive together (module docstring).

    Parameters
    ----------
    loop : analyze.Loop
        The loop (its law's linear transcription, its sample period and plant kind).
    params : PlantParams
        The plant (its spring, masses, dampings).
    forces : mapping
        Coulomb force [N] per friction parameter (``b``; ``b1``, ``b2``), before the law's compensation.
    resolutions : mapping
        Encoder step per measured signal (``MEASURED`` names) [m or rad]; 0 or absent: exact readings.
    delay : int
        The computation delay in samples (the lab bench's: 1).

    Returns
    -------
    dict
        ``found`` (False: ``reason`` says why), ``frequency_Hz``, ``signals``: per measured signal its
        ``amplitude``, ``peak_to_peak`` (2 amplitudes) and ``reading_peak_to_peak`` (whole counts of its
        encoder), ``motor_cart_peak_to_peak_m``, the nonlinearities' input ``amplitudes`` and ``gains``, the
        ``coulomb_forces_N`` and what the law ``compensated_N`` of them.
    """
    comp = law_compensation(loop)
    dither = float(getattr(loop.law_object, "dither_amplitude", 0.0) or 0.0)
    ql = QuasiLinearLoop(loop, params, forces, resolutions, delay, comp, dither)
    out: dict[str, Any] = {"coulomb_forces_N": {k: float(v) for k, v in forces.items()},
                           "compensated_N": {k: c for k, (c, _) in comp.items()},
                           "resolutions": {k: float(v) for k, v in resolutions.items()},
                           "delay_samples": delay, "dither_V": dither,
                           "dither_velocity_m_s": {nl.name: nl.dither for nl in ql.nonlinearities if nl.dither},
                           "nonlinearities": [f"{nl.kind} {nl.name}" for nl in ql.nonlinearities]}
    try:
        hb = harmonic_balance(ql)
    except NoCycle as exc:
        return {**out, "found": False, "reason": str(exc)}
    signals = {}
    for i, signal in enumerate(MEASURED[loop.kind]):
        a = float(abs(np.concatenate([ql.C[i], np.zeros(ql.size - ql.n)]) @ hb["vector"]) * hb["scale"])
        signals[signal] = {"amplitude": a, "peak_to_peak": 2 * a,
                           "reading_peak_to_peak": reading_peak_to_peak(a, resolutions.get(signal, 0.0))}
    motor = MEASURED[loop.kind][0]
    return {**out, "found": True, "reason": None, "frequency_Hz": hb["frequency_Hz"], "signals": signals,
            "motor_cart_peak_to_peak_m": signals[motor]["peak_to_peak"], "amplitudes": hb["amplitudes"],
            "gains": hb["gains"]}


#: Two cycles whose frequencies differ by more than this factor are distinct: they swing side by side.
DISTINCT_FREQUENCY_RATIO = 1.5


def predict_lab_cycle(loop: Any, params: Any, forces: Mapping[str, float], resolutions: Mapping[str, float],
                      delay: int = 0) -> dict[str, Any]:
    """The residual cycle of the friction and the counts together (:func:`combined_cycle`), with the motor cart's
    travel while a spring-coupled cart rests at the turns (:func:`with_windup`)."""
    return with_windup(combined_cycle(loop, params, forces, resolutions, delay), params, forces)


def spring_windup(params: Any, forces: Mapping[str, float]) -> float:
    """The motor cart's travel [m] while the passive cart rests at a turn: ``2 b2 / K``, the spring wound from one
    friction level to the other (``ipcosim.fmus.metrics.amplitude_bound``'s forced cycle); 0 without a spring or
    without passive-cart friction.

    Examples
    --------
    >>> from ipcosim.fmus.params import preset
    >>> round(spring_windup(preset("thesis-ch4"), {"b2": 0.1047}) * 1e3, 3)   # the lab bench: 1.47 mm
    1.473
    """
    K, b2 = float(getattr(params, "K", 0.0) or 0.0), float(forces.get("b2", 0.0) or 0.0)
    return 2.0 * b2 / K if K > 0.0 and b2 > 0.0 else 0.0


def with_windup(cycle: dict[str, Any], params: Any, forces: Mapping[str, float]) -> dict[str, Any]:
    """``cycle`` with :func:`spring_windup` added to the motor cart's peak-to-peak (and its reading), where a cycle
    was found.

    The describing function takes the passive cart through its turns sliding; on the bench it rests there (a
    quarter of the double-mass LQG's cycle) while the motor cart winds the spring from one friction level to the
    other, ``2 b2`` of force, ``2 b2 / K`` of travel that the sliding cycle does not contain. Added whole it is an
    upper estimate: the relay's first harmonic already swings the spring by part of it (``docs/studies.md``).
    """
    windup = spring_windup(params, forces)
    if not cycle.get("found") or not windup or not cycle.get("signals"):
        return {**cycle, "spring_windup_m": 0.0}
    motor = next(iter(cycle["signals"]))
    signals = dict(cycle["signals"])
    m = dict(signals[motor])
    m.update(amplitude=m["amplitude"] + windup / 2, peak_to_peak=m["peak_to_peak"] + windup,
             reading_peak_to_peak=m["reading_peak_to_peak"] + windup)
    signals[motor] = m
    return {**cycle, "signals": signals, "motor_cart_peak_to_peak_m": m["peak_to_peak"], "spring_windup_m": windup}


def combined_cycle(loop: Any, params: Any, forces: Mapping[str, float], resolutions: Mapping[str, float],
                   delay: int = 0) -> dict[str, Any]:
    """The residual cycle of the friction and the counts together: how the two are combined.

    The friction relays are balanced together (exact readings), and the encoders together (no friction). Where
    both give a cycle and their frequencies differ by more than :data:`DISTINCT_FREQUENCY_RATIO`, they are two
    cycles side by side: each signal's peak-to-peak is the sum of the two (the swings meet at their peaks sooner
    or later), the frequency the one of the larger motor-cart swing. Where the frequencies are close, they are
    one cycle: every nonlinearity is balanced at once (:func:`predict_residual` with both). With one mechanism
    only, its cycle. A loop with no nonlinearity has no cycle (``found`` True, peak-to-peak 0).

    Returns
    -------
    dict
        :func:`predict_residual`'s keys for the combined cycle, with ``combined`` (how), ``friction`` and
        ``counts`` (each mechanism's own prediction, or None when the plant has none of it) and ``together``
        (every nonlinearity in one balance at one frequency, where both mechanisms give a cycle; else None:
        what one cycle would be where the rule adds two).
    """
    has_friction = any(v > 0 for v in forces.values())
    has_counts = any(v > 0 for v in resolutions.values())
    fr = predict_residual(loop, params, forces, {}, delay) if has_friction else None
    qu = predict_residual(loop, params, {}, resolutions, delay) if has_counts else None
    found = [p for p in (fr, qu) if p is not None and p["found"]]
    joint = predict_residual(loop, params, forces, resolutions, delay) if len(found) == 2 else None
    parts = {"friction": fr, "counts": qu, "together": joint}
    if fr is None and qu is None:
        zero = {s: {"amplitude": 0.0, "peak_to_peak": 0.0, "reading_peak_to_peak": 0.0} for s in MEASURED[loop.kind]}
        return {"found": True, "reason": None, "combined": "no nonlinearity: a linear loop has no cycle",
                "frequency_Hz": None, "signals": zero, "motor_cart_peak_to_peak_m": 0.0, **parts}
    if len(found) == 2:
        f1, f2 = sorted(p["frequency_Hz"] for p in found)
        if f2 / f1 > DISTINCT_FREQUENCY_RATIO:
            return {**_superposed(fr, qu), **parts}
        if joint is not None and joint["found"]:
            return {**joint, "combined": "one cycle: friction and counts balanced together", **parts}
        found = [max(found, key=lambda p: p["motor_cart_peak_to_peak_m"])]
    if found:
        which = "friction" if found[0] is fr else "counts"
        other = qu if which == "friction" else fr
        why = f" ({'counts' if which == 'friction' else 'friction'}: {other['reason']})" if other else ""
        return {**found[0], "combined": f"the {which} cycle alone{why}", **parts}
    reasons = "; ".join(f"{k}: {p['reason']}" for k, p in parts.items() if p is not None)
    return {"found": False, "reason": reasons, "combined": None, **parts}


def _superposed(fr: Mapping[str, Any], qu: Mapping[str, Any]) -> dict[str, Any]:
    """Two distinct cycles side by side: the peak-to-peaks add, the larger motor-cart swing names the frequency."""
    signals = {s: {k: fr["signals"][s][k] + qu["signals"][s][k] for k in ("amplitude", "peak_to_peak")}
               for s in fr["signals"]}
    for s in signals:   # the reading of the sum: whole counts, at most the sum of the two readings
        signals[s]["reading_peak_to_peak"] = fr["signals"][s]["reading_peak_to_peak"] + \
            qu["signals"][s]["reading_peak_to_peak"]
    lead = max((fr, qu), key=lambda p: p["motor_cart_peak_to_peak_m"])
    motor = next(iter(signals))
    return {"found": True, "reason": None, "frequency_Hz": lead["frequency_Hz"], "signals": signals,
            "motor_cart_peak_to_peak_m": signals[motor]["peak_to_peak"],
            "combined": f"two cycles side by side (friction at {fr['frequency_Hz']:.3g} Hz, counts at "
                        f"{qu['frequency_Hz']:.3g} Hz): their peak-to-peaks add"}


#: The law parameters the prediction sets to 0: nonlinear terms the linear transcription would make a linear
#: feedback they are not (the LQG's breakaway term pushes a cart at rest with the loop's demand, which the
#: stiction absorbs until the cart breaks away: positive feedback on a frictionless linear plant).
LEFT_OUT_LAW_TERMS = ("friction_breakaway_gain",)


def scenario_prediction(sc: Any, set: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The residual cycle of a run of the parsed scenario ``sc`` with the start values ``set`` (``component.name``):
    its plant's spring, friction, encoder resolutions and computation delay, and its law.

    Returns
    -------
    dict
        :func:`predict_lab_cycle`'s result (``found`` False with the ``reason`` where it cannot treat the run).
    """
    from ipcosim.harness.analysis.analyze import binding_values, loop_of_scenario
    from ipcosim.harness.analysis.limit_cycle import plant_of

    given = {k: v for k, v in (set or {}).items() if k.partition(".")[0] in ("controller", "plant")}
    law_values = {**binding_values(sc.component("controller")),
                  **{k.partition(".")[2]: v for k, v in given.items() if k.startswith("controller.")}}
    left_out = {k: 0.0 for k in LEFT_OUT_LAW_TERMS if float(law_values.get(k) or 0.0)}
    loop, _, plant_values = loop_of_scenario(sc, given, left_out)
    params = plant_of(loop)
    forces = {name: float(getattr(params, name)) for name, _ in COULOMB_CARTS[loop.kind]}
    res = {s: float(plant_values.get("pendulum_resolution" if s == "pendulum_angle" else "cart_resolution") or 0.0)
           for s in MEASURED[loop.kind]}
    delay = int(round(float(plant_values.get("input_delay") or 0.0) / loop.T))
    out = predict_lab_cycle(loop, params, forces, res, delay)
    out["law_terms_left_out"] = sorted(left_out)
    return out


def run_bound(sc: Any, set: Mapping[str, Any] | None = None, friction_bound: float | None = None) -> dict[str, Any]:
    """The success criterion's amplitude bound of one run, before it runs (``docs/metrics.md``).

    The predicted motor-cart peak-to-peak (:func:`scenario_prediction`) plus
    ``ipcosim.fmus.metrics.AMPLITUDE_MARGIN_M``; where the prediction cannot treat the run, the friction bound
    ``ipcosim.fmus.metrics.amplitude_bound`` of the run's own ``b2`` and ``K`` (``friction_bound``, else from
    ``set`` over the scenario's values over its plant kind's default preset), and why.

    Returns
    -------
    dict
        ``amplitude_bound_m``, ``amplitude_bound_from`` (``prediction`` or ``friction bound: <why>``) and
        ``predicted_cart_peak_to_peak_m`` (None on the fallback).
    """
    from ipcosim.fmus.metrics import amplitude_bound, predicted_amplitude_bound

    try:
        p = scenario_prediction(sc, set)
        reason = p["reason"]
    except Exception as exc:  # noqa: BLE001 -- a run the prediction cannot treat still has its bound
        p, reason = {"found": False}, f"{type(exc).__name__}: {exc}"
    if p["found"]:
        return {"amplitude_bound_m": predicted_amplitude_bound(p["motor_cart_peak_to_peak_m"]),
                "amplitude_bound_from": "prediction", "predicted_cart_peak_to_peak_m": p["motor_cart_peak_to_peak_m"]}
    if friction_bound is None:
        values = _plant_starts(sc, set)
        friction_bound = amplitude_bound(values["b2"], values["K"])
    return {"amplitude_bound_m": friction_bound,
            "amplitude_bound_from": f"friction bound: {reason}", "predicted_cart_peak_to_peak_m": None}


def _plant_starts(sc: Any, set: Mapping[str, Any] | None) -> dict[str, float]:
    """The plant's ``b2`` and ``K`` of the run: ``set``, else the scenario's bound values, else its plant kind's
    default preset (0 where none has it)."""
    from ipcosim.fmus.params import DEFAULT_PRESET, preset
    from ipcosim.harness.analysis.analyze import binding_values

    try:
        values = binding_values(sc.component("plant"))
        defaults = preset(DEFAULT_PRESET[_kind_of(sc)])
    except (KeyError, LookupError):
        values, defaults = {}, None
    values.update({k.partition(".")[2]: v for k, v in (set or {}).items() if k.startswith("plant.")})
    return {k: float(values.get(k, getattr(defaults, k, 0.0)) or 0.0) for k in ("b2", "K")}


def report(scenario: str, parameter_set: str | None = None, set: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``residual_cycle`` entry of ``ipcosim analyze``: :func:`scenario_prediction` of the scenario with its
    ``--set`` values, on its own bench where its plant has Coulomb friction or encoder counts, else on the lab
    bench's (:func:`realism_values`), and which bench that was."""
    from ipcosim.harness.analysis.analyze import binding_values
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    sc = load_scenario(scenario)
    if parameter_set:
        sc = select_parameter_set(sc, parameter_set)
    values = {f"plant.{k}": v for k, v in binding_values(sc.component("plant")).items()}
    values.update(set or {})
    from ipcosim.fmus.metrics import CYCLE_SOURCES

    own = any(float(values.get(f"plant.{n}") or 0.0) > 0.0 for n in CYCLE_SOURCES)
    if not own:
        values = {**realism_values("lab", _kind_of(sc)), **(set or {})}
    out = scenario_prediction(sc, values)
    out["bench"] = "on the plant's own bench" if own else "on the lab bench: the plant has neither friction nor counts"
    return out


def _kind_of(sc: Any) -> str:
    """The plant kind of a parsed scenario's ``plant`` component."""
    from pathlib import PurePosixPath

    from ipcosim.fmus.kinds import PLANT_MODELS

    return PLANT_MODELS[PurePosixPath(sc.component("plant").source).stem]


def realism_values(name: str, kind: str) -> dict[str, float]:
    """The ``plant.*`` values of the bench ``name`` (``ipcosim.fmus.instruments.realism``: ``ideal``, ``lab``) for
    plant ``kind``: every instrument option that is on, then the plant-parameter overrides."""
    from ipcosim.fmus.instruments import realism

    inst, plant = realism(name, kind)
    out = {f"plant.{f}": float(getattr(inst, f)) for f in inst.__dataclass_fields__ if getattr(inst, f)}
    out.update({f"plant.{k}": float(v) for k, v in plant.items()})
    return out
