"""The outcome of an identification (:mod:`ipcosim.harness.studies.identify`): the estimates with their
95 % intervals and the fit's quality (:class:`Identification`).

Held-out check: the first ``1 - HELD_OUT`` of the log is fitted; the rest is simulated on from the
start with the estimate and reported as NRMSE per output (``1 - ||y - y_sim|| / ||y - mean y||``).

Intervals (:func:`_half_widths`): the wider of two. The sandwich: the Gauss-Newton linearization
``theta - theta* ~ H^-1 J' r`` with ``H = J'J`` gives the covariance ``H^-1 S H^-1``, ``S`` the
Bartlett-weighted sum of the scores' autocovariances up to ``HAC_LAG`` samples (Newey-West: a cart that
sticks holds the same count error for many samples), ``J`` by central differences over
``COVARIANCE_STEP``; +- 1.96 standard errors. It sees the measurement's errors but not where in the
stick-slip roughness the fit stopped, which on the lab bench is the larger error. The refits
(:func:`_bootstrap`, ``refits`` of them): synthetic logs of the estimate, read by encoders with a random
sub-count zero offset, fitted as the log was but without the restarts; +- ``t(0.975, refits)`` times the
refits' root-mean-square deviation from the estimate. They see both. Neither says anything of a model that is wrong (the
held-out NRMSE is the check for that; docs/identify.md). Coulomb forces' intervals are clipped at 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from ipcosim.fmus.instruments import quantize
from ipcosim.harness.studies.identify_fit import (
    NONNEGATIVE,
    _covariance,
    _finish,
    _Finished,
    _fit,
    _largest_counts,
    _Problem,
    _resolutions,
)

#: The motor and amplifier constants that enter the motion (about) only through the force per volt; a fit of one of
#: them with the others at the preset makes it carry the others' errors (``Identification.parameters[...]["note"]``).
FORCE_PER_VOLT = ("Kt", "Ra", "amplifier_gain")
#: A fit is not valid when some reading of the fitted part lies farther than this from its simulation [encoder
#: counts]: the true model explains every reading to within half a count, a finished fit of it leaves at most 1.11
#: (docs/identify.md, Figures: 40 seeded fits) and 1.50 with a hidden motor error the default fit carries (Under
#: model error: 14 valid fits); a model that lacks what moved the plant (a constant off that is not fitted) leaves
#: its error in the readings: 141 to 176 counts for 10 % of Lp, 14 for 10 % of Kt held at the preset.
INVALID_COUNTS = 3.0
#: Refits behind the interval (:func:`_bootstrap`): synthetic logs of the estimate, each read by encoders with
#: their own sub-count zero offset, each fitted as the log was (from the preset, trust region and final pass).
BOOTSTRAP_REFITS = 8
BOOTSTRAP_SEED = 0


@dataclass
class Identification:
    """Estimates, intervals and fit quality of one identification (``to_json``: ``--json``, docs/identify.md)."""

    plant: str
    preset: str
    parameters: dict[str, dict[str, Any]]
    nrmse: dict[str, float]
    held_out_from_s: float
    fit_time_s: float
    simulations: int                # replays of the log the fit spent
    source: str
    values: dict[str, float] = field(default_factory=dict)   # every plant parameter of the identified model
    outputs: tuple[str, ...] = ()
    time: np.ndarray | None = field(default=None, repr=False)
    measured: np.ndarray | None = field(default=None, repr=False)
    simulated: np.ndarray | None = field(default=None, repr=False)
    input_delay_s: float = 0.0
    written: list[Path] = field(default_factory=list)   # the files ``options.out`` received
    fit_cpu_s: float = 0.0                                # CPU time of the fit (``fit_time_s``: wall)
    #: per output, the largest |simulated - measured| over the fitted part in encoder counts (<= 0.5: the
    #: estimate explains every reading to within the encoder's rounding, as the true parameters do)
    largest_residual_counts: dict[str, float] = field(default_factory=dict)
    #: how the log was simulated: ``native`` (:mod:`ipcosim.harness.native.replay`) or ``python (<why not>)``
    replay: str = "native"
    refits: int = 0                 # synthetic refits behind the intervals (:func:`_bootstrap`)
    #: per output, the encoder's resolution [m or rad per count] (the unit of ``largest_residual_counts``)
    resolutions: dict[str, float] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        """Whether the fit explains the log to within ``INVALID_COUNTS`` encoder counts: otherwise the model lacks
        something that moved the plant, and the intervals (which assume the model) claim nothing."""
        return max(self.largest_residual_counts.values(), default=0.0) <= INVALID_COUNTS

    @property
    def invalid_reason(self) -> str | None:
        """One line on why the fit is not valid (None when it is)."""
        if self.valid:
            return None
        name, counts = max(self.largest_residual_counts.items(), key=lambda kv: kv[1])
        return (f"the fit is not valid: {name} is {counts:.1f} encoder counts from its simulation (a fit of the right "
                f"model leaves at most {INVALID_COUNTS:g}): the model lacks something that moved the plant (fit more "
                "parameters, e.g. --fit with Lp, Mp or the motor constants); the intervals claim nothing")

    @property
    def fit(self) -> dict[str, float]:
        """Per output, the held-out fit ``1 - NRMSE`` (1 = perfect, 0 = no better than the mean)."""
        return {k: 1.0 - v for k, v in self.nrmse.items()}

    def to_json(self) -> dict[str, Any]:
        """``{"parameters": {NAME: {"value", "ci95", "unit", "valid"}}, "nrmse": {OUTPUT: fraction}, "fit": {OUTPUT:
        1 - nrmse}, "valid": bool, ...}``."""
        parameters = {n: {**p, "valid": self.valid} for n, p in self.parameters.items()}
        return {"parameters": parameters, "nrmse": self.nrmse, "fit": self.fit, "valid": self.valid,
                "invalid_reason": self.invalid_reason, "plant": self.plant, "preset": self.preset,
                "input_delay_s": self.input_delay_s,
                "held_out_from_s": self.held_out_from_s, "fit_time_s": self.fit_time_s, "fit_cpu_s": self.fit_cpu_s,
                "simulations": self.simulations, "largest_residual_counts": self.largest_residual_counts,
                "replay": self.replay, "refits": self.refits, "source": self.source}


def nrmse(y: np.ndarray, y_sim: np.ndarray) -> float:
    """``||y - y_sim|| / ||y - mean(y)||`` (0 = perfect fit, 1 = no better than the mean; the fit is 1 - NRMSE)."""
    spread = np.linalg.norm(y - y.mean())
    return float(np.linalg.norm(y - y_sim) / spread) if spread > 0 else float("nan")


def _bootstrap(finished: _Finished, sim: np.ndarray, refits: int) -> np.ndarray:
    """The estimator's own scatter at the estimate: ``refits`` estimates (scaled) from synthetic logs.

    Each synthetic log is the estimate's simulated motion ``sim`` read by the log's encoders zeroed at the start
    with a sub-count zero offset drawn uniformly (``quantize`` with its phase moved; the same logged voltage,
    the same computation delay), fitted as the log was: from the preset, the trust region, then the final pass
    with the simulations the log's had, but without its restarts (:func:`_unstick`: they would double the
    identification's time). Its estimates scatter as a fit without restarts does -- from the encoders' rounding
    and from where in the stick-slip roughness the fit stops, which no linearization at the estimate sees --
    so the interval is wide enough for a fit stopped where the final pass stops; one the restarts finished lies
    nearer the truth than that.
    """
    problem = finished.problem
    log, res = problem.log, _resolutions(problem)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    x0 = log.y[0]
    draws = []
    for _ in range(refits):
        phase = 0.5 + rng.uniform(-0.5, 0.5, len(res))
        y = np.array([[quantize(v - s, r, p) + s for v, s, r, p in zip(row, x0, res, phase)] for row in sim])
        refit = _Problem(replace(log, y=y), problem.kind, problem.fit, problem.base, problem.instruments,
                         problem.simulator)
        sol = _fit(refit, refit.start)
        draws.append(_finish(refit, sol.x, finished.budget, restarts=False).x)
        finished.refit_simulations += refit.simulations
    return np.array(draws)


def _half_widths(finished: _Finished, sim: np.ndarray, refits: int) -> np.ndarray:
    """Half the width of each 95 % interval (scaled parameters): the wider of the sandwich's ``1.96 se``
    (:func:`_covariance`) and ``t(0.975, refits) * rms`` of the refits' deviations from the estimate
    (:func:`_bootstrap`; none without refits)."""
    from scipy.stats import t as student

    problem = finished.problem
    cov = _covariance(finished.jac, problem.residuals(finished.x), len(problem.log.outputs))
    half = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    if refits:
        rms = np.sqrt(np.mean((_bootstrap(finished, sim, refits) - finished.x) ** 2, axis=0))
        half = np.maximum(half, student.ppf(0.975, refits) * rms)
    return half


def _result(finished: _Finished, preset_name: str, simulations: int, refits: int) -> Identification:
    """Estimates with their intervals (:func:`_half_widths`) and the held-out NRMSE of a finished fit."""
    problem = finished.problem
    log = problem.log
    sim = problem.simulate(finished.x, len(log.time))
    half = _half_widths(finished, sim, refits) * problem.scale
    k = problem.n_fit
    params = problem.params(finished.x)
    units = {f.name: f.metadata["unit"] for f in fields(params)}
    out: dict[str, dict[str, Any]] = {}
    for i, n in enumerate(problem.fit):
        value = float(getattr(params, n))
        lo = value - half[i]
        out[n] = {"value": value, "ci95": [max(lo, 0.0) if n in NONNEGATIVE else lo, value + half[i]],
                  "unit": units[n]}
    counts = _largest_counts(problem, finished.x)
    result = Identification(problem.kind, preset_name, out,
                          {o: nrmse(log.y[k:, j], sim[k:, j]) for j, o in enumerate(log.outputs)},
                          float(log.time[k]), 0.0, simulations + finished.refit_simulations, log.display,
                          {f.name: float(getattr(params, f.name)) for f in fields(params)}, log.outputs,
                          log.time, log.y, sim, problem.instruments.input_delay)
    result.largest_residual_counts = {o: float(c) for o, c in zip(log.outputs, counts)}
    result.resolutions = {o: float(r) for o, r in zip(log.outputs, _resolutions(problem))}
    lumped = [n for n in FORCE_PER_VOLT if n in problem.fit]
    if len(lumped) == 1:
        held = " and ".join(n for n in FORCE_PER_VOLT if n not in problem.fit)
        out[lumped[0]]["note"] = (f"with {held} at the preset, {lumped[0]} carries every error of the force per volt "
                                  "amplifier_gain N Kt / (rg Ra)")
    return result
