"""Automatic gain tuning: differential evolution over controller parameters, evaluated in
parallel by the sweep engine.

The cost of a gain set is :func:`ipcosim.harness.studies.cost.cost` of one run of the scenario with
those gains (ITAE of the cart position + weighted ITAE of the angle + weighted ISE of the
voltage; infinite when the pendulum falls). ``scipy.optimize.differential_evolution`` proposes a
population per generation; its ``workers`` map hands the whole generation to the sweep engine,
so the runs of a generation go in parallel on the local pool or a Dask cluster. The
scenario's own gains (the thesis's) are put into the initial population, so the result is never
worse than them.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.errors import UsageError
from ipcosim.harness.studies import cost as costmod
from ipcosim.harness.studies.cases import SweepCase, case_seed
from ipcosim.harness.studies.robustness_summary import fmt
from ipcosim.harness.studies.runners import RunSpec


class TuneError(UsageError):
    """Bad tuning parameters or bounds."""


@dataclass
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes
    ----------
    names : list of str
        Tuned parameters.
    nominal, best : dict
        Scenario's values and the best found.
    nominal_cost, best_cost : float
        Cost J (inf when the pendulum fell).
    nominal_row, best_row : dict
        The sweep rows (metrics) of the nominal and the best run.
    evaluations : list of dict
        Every run made (flat sweep rows plus ``cost``), in order.
    generations : int
        Differential-evolution generations carried out.
    """

    names: list[str]
    nominal: dict[str, float]
    best: dict[str, float]
    nominal_cost: float
    best_cost: float
    nominal_row: dict[str, Any]
    best_row: dict[str, Any]
    evaluations: list[dict[str, Any]] = field(default_factory=list)
    generations: int = 0
    message: str = ""


@dataclass(frozen=True)
class Robustness:
    """What the robust objective asks of a candidate besides a low cost (``ipcosim tune --max-peak-sensitivity
    --min-delay-margin --spread``).

    The loop limits are those of ``ipcosim analyze`` (loop broken at the plant input,
    ``ipcosim.harness.analysis.analyze.loop_limits``), checked before any run on the nominal plant and
    on every plant of the spread; a candidate that misses one is not run. The others run on the
    nominal plant and on every plant of the spread, and count with their worst run.

    Attributes
    ----------
    scenario : str
        The scenario whose loop is analysed.
    parameter_set : str, optional
        Its parameter set.
    fixed : mapping
        The fixed ``--set`` values (``component.variable``).
    max_peak_sensitivity : float, optional
        Largest peak |S| at the plant input allowed.
    min_delay_margin : float, optional
        Smallest delay margin allowed [s].
    min_phase_margin : float, optional
        Smallest phase margin allowed [deg] (its magnitude, at the crossover nearest -180 deg).
    spread : tuple of mapping
        Plant variations (``plant.variable`` -> value), run besides the nominal plant.
    """

    scenario: str
    parameter_set: str | None = None
    fixed: Mapping[str, float] = field(default_factory=dict)
    max_peak_sensitivity: float | None = None
    min_delay_margin: float | None = None
    spread: tuple[Mapping[str, float], ...] = ()
    min_phase_margin: float | None = None

    def violation(self, values: Mapping[str, float]) -> tuple[float, dict[str, float]]:
        """``(how far the loop limits are missed, 0 = met; {worst peak_sensitivity, delay_margin_s,
        phase_margin_deg})`` of the candidate ``values`` over the nominal plant and the spread (inf when a loop
        is unstable)."""
        from ipcosim.harness.analysis.analyze import loop_limits, scenario_loop

        if self.max_peak_sensitivity is None and self.min_delay_margin is None and self.min_phase_margin is None:
            return 0.0, {}
        worst = {"peak_sensitivity": 0.0, "delay_margin_s": math.inf, "phase_margin_deg": math.inf}
        for plant in ({}, *self.spread):
            loop, _ = scenario_loop(self.scenario, self.parameter_set, {**self.fixed, **values, **plant})
            limits = loop_limits(loop)
            if limits is None:
                return math.inf, {}
            worst["peak_sensitivity"] = max(worst["peak_sensitivity"], limits[0])
            worst["delay_margin_s"] = min(worst["delay_margin_s"], limits[1])
            worst["phase_margin_deg"] = min(worst["phase_margin_deg"], limits[2])
        excess = 0.0
        if self.max_peak_sensitivity is not None:
            excess += max(0.0, worst["peak_sensitivity"] / self.max_peak_sensitivity - 1.0)
        if self.min_delay_margin is not None:
            excess += max(0.0, 1.0 - worst["delay_margin_s"] / self.min_delay_margin)
        if self.min_phase_margin is not None:
            excess += max(0.0, 1.0 - worst["phase_margin_deg"] / self.min_phase_margin)
        return excess, worst


def spread_plants(parameters: Mapping[str, Any], names: Sequence[str], fraction: float) -> tuple[dict[str, float], ...]:
    """The spread of a robust tuning: two corners, every one of ``names`` (``plant.variable``, those the
    scenario has) scaled by ``1 - fraction`` and by ``1 + fraction``."""
    present = [n for n in names if n in parameters]
    return tuple({n: float(parameters[n]) * (1.0 + sign * fraction) for n in present} for sign in (-1.0, 1.0))


class SweepMap:
    """The ``workers`` map handed to differential evolution: evaluates a generation through the
    sweep engine and returns the (surrogate) costs. With a :class:`Robustness`, a candidate is
    first checked against the loop limits, then run on the nominal plant and every plant of the
    spread; its row is its worst run's (``runs`` of them)."""

    def __init__(self, spec: RunSpec, names: Sequence[str], executor: Any, seed: int,
                 w_angle: float, w_voltage: float, budget: int,
                 on_row: Callable[[dict[str, Any]], None] | None = None, robust: Robustness | None = None) -> None:
        from ipcosim.harness.studies.sweep import run_sweep

        self._run_sweep = run_sweep
        self.spec, self.names, self.executor, self.seed = spec, list(names), executor, seed
        self.w_angle, self.w_voltage, self.budget = w_angle, w_voltage, budget
        self.robust = robust
        self.rows: list[dict[str, Any]] = []
        self.on_row = on_row
        self.generations = 0
        self._runs = 0

    @property
    def remaining(self) -> int:
        """Candidates left in the budget (runs, without a spread)."""
        return max(0, self.budget - len(self.rows))

    def evaluate(self, vectors: Sequence[Sequence[float]]) -> list[dict[str, Any]]:
        """Evaluate one candidate per parameter vector; return their rows (with ``cost``)."""
        start = len(self.rows)
        candidates = [dict(zip(self.names, map(float, v))) for v in vectors]
        plants = ({}, *self.robust.spread) if self.robust else ({},)
        checks = [self.robust.violation(c) if self.robust else (0.0, {}) for c in candidates]
        cases, owner = [], {}
        for i, (values, (excess, _)) in enumerate(zip(candidates, checks)):
            for plant in (plants if excess == 0.0 else ()):
                cases.append(SweepCase(index=self._runs, params={**values, **plant},
                                       seed=case_seed(self.seed, self._runs)))
                owner[self._runs] = i
                self._runs += 1
        runs: dict[int, list[dict[str, Any]]] = {}
        for row in (self._run_sweep(self.spec, cases, executor=self.executor).rows if cases else []):
            row["cost"] = costmod.cost(row, self.w_angle, self.w_voltage) if row["status"] != "error" else math.inf
            runs.setdefault(owner[row["index"]], []).append(row)
        out = []
        for i, (values, (excess, worst)) in enumerate(zip(candidates, checks)):
            if excess > 0.0:
                row = {"index": start + i, **values, "status": "limits", "cost": math.inf, "violation": excess}
            else:
                row = dict(max(runs[i], key=lambda r: (r["status"] == "error", r["cost"])))
                row.update(index=start + i, **values)
                if self.robust:
                    row["runs"] = len(runs[i])
            row.update(worst)
            out.append(row)
            self.rows.append(row)
            if self.on_row:
                self.on_row(row)
        return out

    def __call__(self, func: Callable, iterable: Iterable) -> list[float]:
        vectors = [np.asarray(x, dtype=float) for x in iterable]
        rows = self.evaluate(vectors[:self.remaining])  # the budget is a hard limit on runs
        self.generations += 1
        stop = self.spec.stop_time or 1.0
        costs = [self._surrogate(r, stop) for r in rows]
        return costs + [math.inf] * (len(vectors) - len(rows))  # members not run: never selected

    def _surrogate(self, row: Mapping[str, Any], stop: float) -> float:
        """The optimiser's finite cost: a fall ranks below any run, an error below any fall, missed loop limits
        below any error (the further missed, the worse)."""
        if row["status"] == "limits":
            return 2.0 * costmod.FALL_PENALTY * (1.0 + min(float(row["violation"]), 1e6))
        if row["status"] == "error":
            return 2.0 * costmod.FALL_PENALTY
        return costmod.surrogate_cost(row, stop, self.w_angle, self.w_voltage)


def population_size(popsize: int, dims: int) -> int:
    """Members of scipy's differential-evolution population (``max(5, popsize * dims)``)."""
    return max(5, popsize * dims)


def plan_population(budget: int, dims: int) -> tuple[int, int]:
    """(popsize multiplier, generations after the first) for exactly ``budget`` runs, the run
    of the scenario's own values included: that run, a whole first population, then as many
    members of later generations as the budget leaves (the last generation may be cut short).

    Raises
    ------
    TuneError
        If ``budget`` does not cover the scenario's run and one population.
    """
    smallest = 1 + population_size(max(1, math.ceil(5 / dims)), dims)
    if budget < smallest:
        raise TuneError(f"--budget {budget}: need at least {smallest} runs for {dims} parameter(s) (the scenario's "
                        f"own values, then a first population of {smallest - 1})")
    popsize = max(1, math.ceil(5 / dims))
    # grow the population while it leaves room for ~ 8 generations
    while population_size(popsize + 1, dims) * 9 <= budget - 1 and popsize < 15:
        popsize += 1
    maxiter = max(1, math.ceil((budget - 1) / population_size(popsize, dims)) - 1)
    return popsize, maxiter


def tune(spec: RunSpec, names: Sequence[str], bounds: Sequence[tuple[float, float]], budget: int = 200,
         executor: Any = None, seed: int = 0, w_angle: float = costmod.W_ANGLE,
         w_voltage: float = costmod.W_VOLTAGE, progress: bool = False,
         on_row: Callable[[dict[str, Any]], None] | None = None, robust: Robustness | None = None) -> TuneResult:
    """Minimise the tuning cost over ``names`` within ``bounds`` by differential evolution.

    Parameters
    ----------
    spec : RunSpec
        The scenario (its nominal parameter values are the starting point).
    names : sequence of str
        Parameters to tune (``component.variable``).
    bounds : sequence of (float, float)
        Search range of each.
    budget : int
        Number of runs, exactly (the run of the nominal values included).
    executor : LocalExecutor or DaskExecutor, optional
        Where runs go (default: a local pool, closed at the end).
    seed : int
        Seed of the optimiser (and of the runs).
    w_angle, w_voltage : float
        Cost weights.
    progress : bool
        Print one line per generation on stderr.
    on_row : callable, optional
        Called with every candidate's row.
    robust : Robustness, optional
        Loop limits and a plant spread (the robust objective); ``budget`` then counts candidates.
    """
    from ipcosim.harness.studies.executors import open_executor

    population = plan_population(budget, len(names))  # checks the budget before any run
    nominal = {n: float(spec.parameters[n]) for n in names}
    # the start clipped to the bounds, a hair inside: scipy rescales it to [0, 1] and rejects a bound
    # that rounds to just outside
    x0 = np.array([min(max(nominal[n], lo + 1e-12 * (hi - lo)), hi - 1e-12 * (hi - lo))
                   for n, (lo, hi) in zip(names, bounds)])
    own = executor is None
    if own:
        executor = open_executor()
    try:
        mapper = SweepMap(spec, names, executor, seed, w_angle, w_voltage, budget, on_row, robust)
        nominal_row = mapper.evaluate([np.array([nominal[n] for n in names])])[0]
        message = _evolve(mapper, bounds, x0, population, seed, progress, nominal_row["cost"])
    finally:
        if own:
            executor.close()
    candidates = [r for r in mapper.rows if r["status"] not in ("error", "limits")]
    best_row = min(candidates, key=lambda r: r["cost"]) if candidates else nominal_row
    if not (best_row["cost"] < nominal_row["cost"]):
        best_row = nominal_row
    best = {n: float(best_row[n]) for n in names}
    return TuneResult(names=list(names), nominal=nominal, best=best, nominal_cost=nominal_row["cost"],
                      best_cost=best_row["cost"], nominal_row=nominal_row, best_row=best_row,
                      evaluations=mapper.rows, generations=mapper.generations, message=message)


def _evolve(mapper: SweepMap, bounds: Sequence[tuple[float, float]], x0: np.ndarray, population: tuple[int, int],
            seed: int, progress: bool, nominal_cost: float) -> str:
    """Run scipy's differential evolution with ``mapper`` evaluating each generation as one sweep
    (the objective itself is never called), stopping when the run budget is spent; returns the
    optimiser's message. ``population`` is (popsize, maxiter) of :func:`plan_population`."""
    from scipy.optimize import differential_evolution

    popsize, maxiter = population

    def callback(*_: Any, **__: Any) -> bool:
        if progress:
            gen_best = min(r["cost"] for r in mapper.rows)
            print(f"tune: generation {mapper.generations}, {len(mapper.rows)} runs, best cost "
                  f"{fmt(gen_best)} (nominal {fmt(nominal_cost)})", file=sys.stderr, flush=True)
        return mapper.remaining == 0  # True stops the optimiser

    result = differential_evolution(
        lambda x: math.inf, bounds=list(bounds), popsize=popsize, maxiter=maxiter, tol=0.0, atol=0.0,
        polish=False, updating="deferred", workers=mapper, x0=x0, rng=np.random.default_rng(seed),
        init="latinhypercube", callback=callback)
    return str(result.message)
