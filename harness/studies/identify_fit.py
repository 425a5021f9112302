"""The fit of an identification (:mod:`ipcosim.harness.studies.identify`): the output-error problem of one log
and how it is solved.

The estimator is an output-error fit. It replays the logged voltage through the project's own plant
model (:func:`ipcosim.fmus.plant.replay`: the same ``Plant`` the plant FMUs and the virtual rig
step, on the lab bench's input path, ``ipcosim.fmus.instruments.REALISM["lab"]``; run in C by
:mod:`ipcosim.harness.native.replay` where a compiler is found, :func:`simulator`), compares the
simulated positions with the logged encoder readings, and minimizes the sum of squared
differences (each output scaled by its spread in the log): scipy's trust-region least squares
approaches the optimum, a final pass of small-step Gauss-Newton steps (:func:`_polish`) finishes it
where the stick-slip friction makes the cost rough, restarted from nearby points where it stops with a
reading a count or more off (:func:`_unstick`). Only the parameters named in ``fit`` move; every
other constant (motor, gearbox, pendulum mass and length) stays at the preset's value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Sequence

import numpy as np

from ipcosim.fmus.instruments import Instruments
from ipcosim.fmus.physics import MEASURED, state_names
from ipcosim.fmus.plant import replay
from ipcosim.harness.studies.identify_log import IdentifyError, Log

#: Parameters whose nominal may be 0: their fit scale [their unit] and start value.
ZERO_NOMINAL = {"b": (0.1, 0.05), "b1": (0.1, 0.05), "b2": (0.1, 0.05), "Bc": (0.01, 0.005)}
#: Parameters that can only be estimated >= 0 (the rest: > 0).
NONNEGATIVE = ("b", "b1", "b2", "Bc", "Beq", "Ba", "Bf", "Bp", "K")
HELD_OUT = 0.25
HAC_LAG = 1000
#: Forward-difference step of the Jacobian, relative to the (scaled) parameter. Stick-slip friction
#: makes the outputs step when a cart's stick decision flips: a step of 1e-3 measured those flips and
#: led the fit astray (a 12 s double-mass log ended 8 % off in Ma, held-out NRMSE 85 %); 1e-2 averages
#: over them (the same log: every parameter within 2 %, NRMSE 98.8 %).
FD_STEP = 1e-2
#: The final pass (:func:`_polish`): Gauss-Newton steps from central differences at these relative steps of
#: the scaled parameters, tried in order until one lowers the cost, with step lengths ``POLISH_LENGTHS``; at
#: most ``POLISH_ITERATIONS`` steps, within ``SIMULATION_BUDGET``. 1e-5 is about a tenth of a standard error: it
#: measures the slope between the stick decisions that flip, where the trust region's 1 % secant stopped; the
#: larger steps take over where a flip sits inside the small one.
POLISH_STEPS = (1e-5, 1e-4, 1e-3)
POLISH_LENGTHS = (1.0, 0.5, 0.25)
POLISH_ITERATIONS = 8
#: Simulations of the log the fit may spend before its interval (the final pass ends early rather than exceed it);
#: each refit's final pass gets what the log's had. A larger budget does not help: a fit stuck in the roughness
#: stays stuck (a double-mass log given 1200: the final pass stopped at 389, still 2.5 counts off).
SIMULATION_BUDGET = 330
#: A fit is stuck when some reading of the fitted part lies farther than this from its simulation [encoder counts]:
#: the true parameters explain every reading to within half a count, and every seeded fit that ended below one count
#: had all its truths inside their intervals; above it, a stick-slip episode of the log ends a count or more away
#: from where the estimate puts it.
STUCK_COUNTS = 1.0
#: Restarts of the final pass while the fit is stuck (:func:`_unstick`): from the best point so far moved by
#: ``RESTART_SIZES`` (in turn) times a draw of the sandwich's covariance (seeded by ``RESTART_SEED``), each finished by
#: ``RESTART_ITERATIONS`` Gauss-Newton steps, the lowest cost kept; at most ``RESTARTS`` of them and
#: ``RESTART_BUDGET`` simulations of the log.
RESTARTS = 24
RESTART_SIZES = (10.0, 30.0)
RESTART_ITERATIONS = 3
RESTART_BUDGET = 600
RESTART_SEED = 0
#: Central-difference step of the Jacobian behind the interval: ten standard errors, so that the few stick
#: decisions that flip inside it add little to a slope measured over many samples (a step of 1e-5 with one flip
#: inside it made one column, and so the information on that parameter, tens of times too large).
COVARIANCE_STEP = 1e-3
#: Relative standard error (from the encoders' resolution alone) above which a parameter is refused.
UNIDENTIFIABLE = 0.3
#: Variance inflation (the information on a parameter alone over what is left of it after the other fitted
#: parameters, from central differences over ``COVARIANCE_STEP`` at the start) above which a parameter is refused as
#: not separable from them. On the identify experiments' 20 s logs: Kt beside Ra 1.6e8 (they enter as Kt / Ra but
#: for the armature's 0.07 ms time constant); the default fit at most 26 (single mass) and 77 (double mass); the
#: amplifier gain beside Kt 290 to 1100 and Kb beside Kt and the damping 230 to 840 (docs/identify.md, Parameters).
INFLATION = 1e4


class _Problem:
    """The output-error problem of one log: parameters scaled to ~1, residuals scaled per output."""

    def __init__(self, log: Log, kind: str, fit: Sequence[str], base: Any, instruments: Instruments,
                 simulator: Callable[..., Any] = replay) -> None:
        self.log, self.kind, self.fit, self.base = log, kind, tuple(fit), base
        self.instruments = instruments
        self.simulator = simulator    # ``ipcosim.fmus.plant.replay`` or its native twin (:func:`simulator`)
        self.scale = np.array([ZERO_NOMINAL.get(n, (getattr(base, n), 0))[0] or 1.0 for n in fit])
        self.start = np.array([getattr(base, n) or ZERO_NOMINAL.get(n, (0, 1.0))[1] for n in fit]) / self.scale
        x0 = [0.0] * len(state_names(kind))
        for j, name in enumerate(MEASURED[kind]):
            x0[state_names(kind).index(name)] = float(log.y[0, j])
        self.x0 = x0
        self.n_fit = int(round(len(log.time) * (1 - HELD_OUT)))
        self.spread = np.maximum(log.y[: self.n_fit].std(axis=0), 1e-9)
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.simulations = 0          # replays of the log so far (``Identification.simulations``)

    def params(self, theta: np.ndarray) -> Any:
        return replace(self.base, **{n: float(t * s) for n, t, s in zip(self.fit, theta, self.scale)})

    def simulate(self, theta: np.ndarray, rows: int) -> np.ndarray:
        """Simulated positions for the first ``rows`` rows of the log."""
        return np.asarray(self.simulator(self.params(theta), self.log.voltage[: rows - 1], self.log.step, self.x0,
                                         self.instruments))

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Scaled differences simulated - measured over the fitted part (cached for the last ``theta``)."""
        if self._last is not None and np.array_equal(self._last[0], theta):
            return self._last[1]
        r = self._residuals(theta)
        self._last = (theta.copy(), r)
        return r

    def _residuals(self, theta: np.ndarray) -> np.ndarray:
        y = self.log.y[: self.n_fit]
        self.simulations += 1
        try:
            sim = self.simulate(theta, self.n_fit)
        except (FloatingPointError, ValueError):
            return np.full(y.size, 1e3)
        return ((sim - y) / self.spread).ravel()

    def cost(self, theta: np.ndarray) -> float:
        """Half the sum of the squared scaled residuals."""
        r = self.residuals(theta)
        return 0.5 * float(r @ r)

    def central_jacobian(self, theta: np.ndarray, step: float) -> np.ndarray:
        """Central differences of the residuals at the relative ``step``, two simulations per parameter."""
        cols = []
        for i in range(len(theta)):
            d = step * max(abs(theta[i]), 1e-3)
            up, down = theta.copy(), theta.copy()
            up[i] += d
            down[i] -= d
            cols.append((self._residuals(up) - self._residuals(down)) / (2 * d))
        return np.column_stack(cols)

    def jacobian(self, theta: np.ndarray, r0: np.ndarray | None = None) -> np.ndarray:
        """Forward differences of the residuals, one simulation per parameter."""
        r0 = self.residuals(theta) if r0 is None else r0
        cols = []
        for i in range(len(theta)):
            d = FD_STEP * max(1.0, abs(theta[i]))
            t = theta.copy()
            t[i] += d
            cols.append((self._residuals(t) - r0) / d)
        return np.column_stack(cols)


def _resolutions(problem: _Problem) -> np.ndarray:
    """Each measured output's encoder resolution [m or rad] (1e-9 where the bench has none)."""
    inst = problem.instruments
    return np.maximum([inst.pendulum_resolution if n == "pendulum_angle" else inst.cart_resolution
                       for n in problem.log.outputs], 1e-9)


def _check_identifiable(problem: _Problem, J: np.ndarray) -> None:
    """Refuse a parameter whose standard error from the encoders' resolution alone exceeds ``UNIDENTIFIABLE``, or
    exceeds ``sqrt(INFLATION)`` times what it would be were the other parameters known (told apart from them only by
    an effect a hundred times smaller than its own: Kt beside Ra, through the armature's 0.07 ms time constant)."""
    sigma = np.tile(_resolutions(problem) / math.sqrt(12) / problem.spread, problem.n_fit)
    Jw = J / sigma[:, None]
    H = Jw.T @ Jw
    for i, name in enumerate(problem.fit):
        rest = [j for j in range(len(problem.fit)) if j != i]
        # the information on parameter i left after the others explain what they can (Schur complement)
        info = H[i, i] - (H[i, rest] @ np.linalg.pinv(H[np.ix_(rest, rest)]) @ H[rest, i] if rest else 0.0)
        start = problem.start[i]
        limit = UNIDENTIFIABLE * max(start, 1.0)
        if not info > 0 or 1 / math.sqrt(info) > limit or info < H[i, i] / INFLATION:
            if H[i, i] > 0 and 1 / math.sqrt(H[i, i]) <= limit:   # moved alone, but as another fitted one moves
                partner = max(rest, key=lambda j: abs(H[i, j]) / math.sqrt(H[i, i] * H[j, j]))
                raise IdentifyError(f"{problem.log.display}: cannot identify {name} apart from "
                                    f"{problem.fit[partner]}: the log moves as much when one changes as when the "
                                    "other does (fit one of them; docs/identify.md, Parameters)")
            raise IdentifyError(f"{problem.log.display}: cannot identify {name}: the excitation did not move it "
                                f"(the outputs change by less than the encoders resolve when {name} changes)")


def _covariance(J: np.ndarray, r: np.ndarray, m: int, lag: int = HAC_LAG) -> np.ndarray:
    """Newey-West covariance of the least-squares estimate (``m`` residuals per sample)."""
    p = J.shape[1]
    scores = (J * r[:, None]).reshape(-1, m, p).sum(axis=1)     # one score per sample
    n = len(scores)
    nfft = 1 << (2 * n - 1).bit_length()
    F = np.fft.rfft(scores, nfft, axis=0)
    S = np.zeros((p, p))
    for a in range(p):
        for b in range(a, p):
            c = np.fft.irfft(F[:, a] * np.conj(F[:, b]), nfft)   # c[l] = sum_t s_a[t+l] s_b[t]
            w = 1 - np.arange(lag + 1) / (lag + 1)
            v = w[0] * c[0] + np.sum(w[1:] * (c[1: lag + 1] + c[-lag:][::-1]))
            S[a, b] = S[b, a] = v
    Hinv = np.linalg.pinv(J.T @ J)
    return Hinv @ S @ Hinv


def simulator(kind: str) -> tuple[Callable[..., Any], str]:
    """The simulation of the log and its name: the native replay (:mod:`ipcosim.harness.native.replay`, the same
    numbers 30 to 40 times faster) where a C compiler is found, else :func:`ipcosim.fmus.plant.replay`
    (``python (<why>)``)."""
    from ipcosim.harness.native.replay import ReplayUnavailable, native_replay

    try:
        return native_replay(kind), "native"
    except ReplayUnavailable as exc:
        return replay, f"python ({exc})"


def _fit(problem: _Problem, start: np.ndarray, max_nfev: int = 20) -> Any:
    """``scipy.optimize.least_squares`` of the problem's residuals from ``start`` (bounded, trust region): the
    approach to the optimum, which :func:`_polish` finishes (more of these steps would stop in the roughness)."""
    from scipy.optimize import least_squares

    return least_squares(problem.residuals, start, jac=lambda t: problem.jacobian(t), method="trf",
                         bounds=(_lower(problem), np.inf), x_scale=1.0, xtol=1e-8, ftol=1e-10, max_nfev=max_nfev)


@dataclass
class _Finished:
    """The end of :func:`_polish`: the estimate, its cost and the Jacobian there."""

    problem: _Problem
    x: np.ndarray
    cost: float
    jac: np.ndarray | None
    budget: float = math.inf      # the simulations the final pass was given (a refit gets as many)
    refit_simulations: int = 0    # what the interval's refits spent (:func:`_bootstrap`)


def _polish(problem: _Problem, start: np.ndarray, iterations: int, budget: float = math.inf) -> _Finished:
    """Finish the fit from ``start``: Gauss-Newton steps on small-step central differences, kept only when they
    lower the cost.

    The stick-slip friction makes the cost rough: each stick decision that flips as a parameter changes adds a
    small step to it, and the trust region's 1 % secant (``FD_STEP``) stops in that roughness, 10 to 100
    standard errors from the optimum. Between the flips the cost is smooth; central differences over a tenth of a
    standard error (``POLISH_STEPS``) see that slope, and a step is tried at the lengths ``POLISH_LENGTHS`` and
    taken only if it lowers the cost (no step is forced through a flip); at most ``iterations`` steps and about
    ``budget`` simulations (leaving what the sandwich's Jacobian at the end needs, :func:`_finish`).
    """
    x, cost = np.asarray(start, float), problem.cost(start)
    # a Jacobian and its line search, plus the Jacobian for the interval, must fit in what is left of the budget
    last = problem.simulations + budget - (2 * len(x) + len(POLISH_LENGTHS)) - 2 * len(x)
    for _ in range(iterations):
        for J in (problem.central_jacobian(x, step) for step in POLISH_STEPS if problem.simulations <= last):
            direction = -np.linalg.lstsq(J, problem.residuals(x), rcond=None)[0]
            trial = min((problem.cost(_bounded(problem, x + a * direction)), a) for a in POLISH_LENGTHS)
            if trial[0] < cost:
                x, cost = _bounded(problem, x + trial[1] * direction), trial[0]
                break
        else:
            break
    return _Finished(problem, x, cost, None, budget)


def _finish(problem: _Problem, start: np.ndarray, budget: float, restarts: bool = True) -> _Finished:
    """The final pass (:func:`_polish`, about ``budget`` simulations) and, with ``restarts`` where it leaves the
    fit stuck, its restarts (:func:`_unstick`, ``RESTART_BUDGET`` more); with ``restarts`` (the log's own fit)
    also the sandwich's Jacobian at the end (central differences over ``COVARIANCE_STEP``)."""
    finished = _polish(problem, start, POLISH_ITERATIONS, budget)
    if restarts:
        finished = _unstick(finished, RESTART_BUDGET)
        finished.jac = problem.central_jacobian(finished.x, COVARIANCE_STEP)
    return finished


def _unstick(finished: _Finished, budget: float) -> _Finished:
    """Restart the final pass from points near a stuck estimate (:data:`STUCK_COUNTS`), keeping the lowest cost.

    The cost is a smooth bowl plus a small positive step for each stick decision that flips away from the truth's:
    the final pass stops where every Gauss-Newton step it tries from there crosses a flip that costs more than the
    bowl saves, and more simulations from the same point do not help. From a point a few standard errors away
    (the sandwich's covariance at the stuck estimate: moved mostly along the bowl's flat directions, where the
    flips decide) the steps cross other flips; a restart is kept only where it ends lower than the best point so
    far, and the next one starts from there. Deterministic (``RESTART_SEED``); at most ``RESTARTS`` restarts and
    about ``budget`` simulations, ending early once no reading is a count off.
    """
    problem, best = finished.problem, finished
    if not _stuck(problem, best.x):
        return finished
    end = problem.simulations + budget
    jac = problem.central_jacobian(best.x, COVARIANCE_STEP)
    w, v = np.linalg.eigh(_covariance(jac, problem.residuals(best.x), len(problem.log.outputs)))
    root = v * np.sqrt(np.maximum(w, 0.0))
    rng = np.random.default_rng(RESTART_SEED)
    for k in range(RESTARTS):
        left = end - problem.simulations
        if left < 4 * len(best.x) + len(POLISH_LENGTHS) + 1:
            break
        start = _bounded(problem, best.x + RESTART_SIZES[k % len(RESTART_SIZES)] * root @ rng.standard_normal(len(w)))
        trial = _polish(problem, start, RESTART_ITERATIONS, left)
        if trial.cost < best.cost:
            best = trial
            if not _stuck(problem, best.x):
                break
    return _Finished(problem, best.x, best.cost, None, finished.budget)


def _stuck(problem: _Problem, x: np.ndarray) -> bool:
    """Whether some reading of the fitted part lies more than ``STUCK_COUNTS`` from the simulation of ``x``."""
    return bool(_largest_counts(problem, x).max() > STUCK_COUNTS)


def _largest_counts(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """Per output, the largest |simulated - measured| over the fitted part of the log, in encoder counts."""
    r = problem.residuals(x).reshape(problem.n_fit, len(problem.log.outputs))
    return np.abs(r).max(axis=0) * problem.spread / _resolutions(problem)


def _bounded(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """``x`` kept inside the fit's bounds (:func:`_lower`)."""
    return np.maximum(x, _lower(problem))


def _lower(problem: _Problem) -> np.ndarray:
    """The lower bounds of the scaled parameters: 0 for the ``NONNEGATIVE`` ones, 1e-3 for the rest."""
    return np.array([0.0 if n in NONNEGATIVE else 1e-3 for n in problem.fit])
