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

import csv
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.errors import UsageError, closest
from ipcosim.harness.studies import cost as costmod
from ipcosim.harness.studies.cases import SweepCase, case_seed
from ipcosim.harness.studies.robustness import fmt
from ipcosim.harness.studies.runners import RunSpec

#: Default search range around a nominal value g: [g / DEFAULT_FACTOR, g * DEFAULT_FACTOR].
DEFAULT_FACTOR = 2.0


class TuneError(UsageError):
    """Bad tuning parameters or bounds."""


def parse_params(text: str, parameters: Mapping[str, Any]) -> list[str]:
    """``controller.a,controller.b`` -> names, each checked against the scenario's parameters."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise TuneError("--params: give at least one COMPONENT.VARIABLE")
    for n in names:
        if n not in parameters:
            raise TuneError(f"--params: unknown parameter {n!r}; {closest(n, parameters)}")
    if len(set(names)) != len(names):
        raise TuneError(f"--params {text!r}: a parameter is listed twice")
    return names


def parse_bounds(items: Iterable[str], names: Sequence[str],
                 parameters: Mapping[str, Any]) -> list[tuple[float, float]]:
    """Search bounds per parameter: ``--bounds NAME=LO:HI`` or the default factor-2 range
    around the nominal value (a zero nominal needs explicit bounds)."""
    given: dict[str, tuple[float, float]] = {}
    for item in items:
        name, sep, rng = item.partition("=")
        name = name.strip()
        lo_text, sep2, hi_text = rng.partition(":")
        if not sep or not sep2:
            raise TuneError(f"--bounds {item!r}: expected COMPONENT.VARIABLE=LOW:HIGH")
        if name not in names:
            raise TuneError(f"--bounds {item!r}: {name} is not in --params")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            raise TuneError(f"--bounds {item!r}: LOW and HIGH must be numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise TuneError(f"--bounds {item!r}: need finite LOW < HIGH")
        given[name] = (lo, hi)
    bounds = []
    for n in names:
        if n in given:
            bounds.append(given[n])
            continue
        g = parameters[n]
        if not isinstance(g, (int, float)) or not math.isfinite(g) or g == 0:
            raise TuneError(f"--params: {n} has nominal value {g!r}; give its range with --bounds {n}=LOW:HIGH")
        a, b = g / DEFAULT_FACTOR, g * DEFAULT_FACTOR
        bounds.append((min(a, b), max(a, b)))
    return bounds


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


# --------------------------------------------------------------------------- outputs

def tuned_parameter_set(scenario: str, best: Mapping[str, float],
                        parameter_set: str | None = None) -> tuple[dict[str, Any], str | None]:
    """The complete parameter set to write for a tuned scenario.

    When every tuned parameter belongs to one component that binds a parameter-set file (the
    controller's ``thesis``/``tuned`` set), the result is that set with the tuned values put in,
    names relative to the component -- a drop-in replacement selectable with
    ``--parameter-set autotuned``. Otherwise the tuned values alone, as ``component.variable``.

    Returns
    -------
    (values, component)
        ``component`` is None in the second case.
    """
    components = {n.split(".", 1)[0] for n in best}
    if len(components) == 1:
        component = components.pop()
        try:
            from ipcosim.harness.scenario.ssp import load_scenario
            from ipcosim.harness.scenario.structure import select_parameter_set

            sc = load_scenario(scenario)
            if parameter_set:
                sc = select_parameter_set(sc, parameter_set)
            comp = sc.component(component)
        except Exception:  # noqa: BLE001 -- not a scenario with files (e.g. a pure stand-in)
            comp = None
        if comp is not None:
            file_sets = [b for b in comp.bindings if b.source is not None]
            if file_sets:
                values: dict[str, Any] = {}
                for b in file_sets:
                    values.update({p.name: p.value for p in b.parameters})
                values.update({n.split(".", 1)[1]: float(v) for n, v in best.items()})
                return values, component
    return {n: float(v) for n, v in best.items()}, None


TABLE_METRICS = ("cost", "itae_position", "settling_time_s", "overshoot_m", "steady_state_error_m",
                 "max_abs_angle_rad", "peak_voltage_V", "rms_voltage_V", "upright")


def before_after_markdown(res: TuneResult, label_before: str = "scenario gains") -> str:
    """Before/after table of parameter values and metrics."""
    lines = [f"| | {label_before} | tuned |", "|---|---|---|"]
    for n in res.names:
        lines.append(f"| {n} | {fmt(res.nominal[n], 6)} | {fmt(res.best[n], 6)} |")
    for m in TABLE_METRICS:
        before, after = res.nominal_row.get(m), res.best_row.get(m)
        lines.append(f"| {m} | {fmt(before)} | {fmt(after)} |")
    lines.append(f"| status | {res.nominal_row['status']} | {res.best_row['status']} |")
    return "\n".join(lines) + "\n"


def write_evaluations(path: Path, rows: Sequence[Mapping[str, Any]], names: Sequence[str]) -> None:
    """Every run of the tuning as CSV (parameters, cost, status, metrics)."""
    if not rows:
        return
    keys = ["index", "status", "cost", *names]
    for r in rows:
        keys += [k for k in r if k not in keys and k not in ("seed", "success")]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow(["" if r.get(k) is None else r.get(k) for k in keys])


# --------------------------------------------------------------------------- a scenario's tuning (ipcosim tune)


def _scenario_dir(scenario: str) -> Path | None:
    """The scenario's folder (where its .ssv files live), or None."""
    path = Path(scenario)
    if path.is_dir():
        return path
    if path.suffix == ".ssp" and path.exists():
        return path.parent
    from ipcosim.harness.support.paths import SCENARIO_DIR

    candidate = SCENARIO_DIR / scenario
    return candidate if candidate.is_dir() else None


def install_path(scenario: str) -> Path:
    """Where ``--install`` puts a tuned set: ``autotuned.ssv`` in the scenario's folder (beside its other
    sets); for a scenario shipped in an installed wheel, in the user's copy of it
    (``ipcosim.harness.support.paths.user_scenario_dir``, made by :func:`install`), never in site-packages.

    Raises
    ------
    UsageError
        If the scenario has no folder (an archive, a pure stand-in).
    """
    folder = _scenario_dir(scenario)
    if folder is None or Path(scenario).suffix == ".ssp":
        raise UsageError(f"--install: scenario {scenario!r} has no folder to install a parameter set into")
    from ipcosim.harness.support.paths import SCENARIO_DIR, in_checkout, user_scenario_dir

    if not in_checkout() and folder.resolve().is_relative_to(SCENARIO_DIR.resolve()):
        return user_scenario_dir() / folder.name / "autotuned.ssv"
    return folder / "autotuned.ssv"


def install(scenario: str, path: Path, text: str) -> None:
    """Write the tuned set ``text`` to ``path`` (:func:`install_path`), first copying the shipped
    scenario's SSD and parameter sets into the user's folder when ``path`` is there."""
    import os
    import shutil

    folder = _scenario_dir(scenario)
    if folder is not None and path.parent != folder and not (path.parent / "SystemStructure.ssd").exists():
        shutil.copytree(folder, path.parent, dirs_exist_ok=True, ignore=shutil.ignore_patterns("autotuned.ssv"))
    staged = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    staged.write_text(text)
    os.replace(staged, path)


def starting_set(scenario: str, parameter_set: str | None = None) -> str | None:
    """The parameter set a tuning starts from: ``parameter_set``, else ``thesis`` where the scenario has it."""
    from ipcosim.harness.studies.specs import PURE_SCENARIOS

    if parameter_set is None and scenario not in PURE_SCENARIOS:
        from ipcosim.harness.scenario.ssp import load_scenario

        if "thesis" in load_scenario(scenario).parameter_sets:
            return "thesis"
    return parameter_set


def robustness_objective(scenario: str, spec: RunSpec, fixed: Mapping[str, Any], parameter_set: str | None,
                         max_peak_sensitivity: float | None = None, min_delay_margin: float | None = None,
                         spread: float | None = None, min_phase_margin: float | None = None) -> Robustness | None:
    """The robust objective of ``--max-peak-sensitivity``, ``--min-delay-margin``, ``--min-phase-margin``,
    ``--spread`` (None without any); the spread scales the plant parameters of
    ``robustness.DEFAULT_UNCERTAINTY``.

    Raises
    ------
    UsageError
        A limit that is not a number > 0, a spread not in (0, 1), or a phase margin not below 180 deg.
    """
    from ipcosim.harness.studies.robustness import DEFAULT_UNCERTAINTY

    limits = (("--max-peak-sensitivity", max_peak_sensitivity, math.inf), ("--min-delay-margin", min_delay_margin,
              math.inf), ("--min-phase-margin", min_phase_margin, 180.0), ("--spread", spread, 1.0))
    if all(value is None for _, value, _ in limits):
        return None
    for flag, value, top in limits:
        if value is not None and not (math.isfinite(value) and 0 < value < top):
            raise UsageError(f"{flag} {value}: expected a number > 0" + (f" and < {top:g}" if top < math.inf else ""))
    names = list(dict.fromkeys(n for kind in DEFAULT_UNCERTAINTY.values() for n in kind))
    plants = spread_plants(spec.parameters, names, spread) if spread else ()
    return Robustness(scenario, parameter_set, {k: float(v) for k, v in fixed.items()},
                      max_peak_sensitivity, min_delay_margin, plants, min_phase_margin)


@dataclass
class TunedFiles:
    """What :meth:`TuneStudy.write` wrote: the tuned set (``ssv``, and ``installed`` beside the scenario with
    ``--install``), the report ``tune.md`` and every run (``evaluations``); ``table`` is the report's
    before/after table."""

    ssv: Path
    installed: Path | None
    report: Path
    evaluations: Path
    table: str


@dataclass
class TuneStudy:
    """The tuning of a scenario, checked and ready to run (:func:`tune_study`): :meth:`run` tunes,
    :meth:`write` writes the tuned set, the report and the evaluations."""

    scenario: str
    spec: RunSpec
    flavour: str
    names: list[str]
    bounds: list[tuple[float, float]]
    parameter_set: str | None
    out: Path
    ssv: Path
    install: Path | None = None
    robust: Robustness | None = None
    budget: int = 200
    seed: int = 0
    w_angle: float = costmod.W_ANGLE
    w_voltage: float = costmod.W_VOLTAGE

    def plan_line(self, executor: Any) -> str:
        """One line: what is tuned within which bounds, the budget and where it runs."""
        ranges = ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in self.bounds)
        return (f"tune {self.spec.name}: {', '.join(self.names)} within {ranges}, budget {self.budget} runs on "
                f"{executor.description}, {self.flavour}")

    def run(self, executor: Any, progress: bool = True) -> TuneResult:
        """Tune on ``executor`` (:func:`tune`); an interruption aborts the executor and writes nothing."""
        from ipcosim.harness.studies.specs import for_executor

        try:
            return tune(for_executor(self.spec, executor), self.names, self.bounds, budget=self.budget,
                        executor=executor, seed=self.seed, w_angle=self.w_angle, w_voltage=self.w_voltage,
                        progress=progress, robust=self.robust)
        except KeyboardInterrupt:
            executor.abort()
            raise

    def write(self, res: TuneResult) -> TunedFiles:
        """Write every run (``evaluations.csv``), the tuned parameter set (``ssv``, and ``install`` when
        given; :func:`tuned_parameter_set`) and the report ``tune.md``."""
        from ipcosim.harness.scenario.ssv import ssv_text

        files = TunedFiles(self.ssv, self.install, self.out / "tune.md", self.out / "evaluations.csv",
                           before_after_markdown(res, f"{self.parameter_set} gains" if self.parameter_set
                                                 else "scenario gains"))
        write_evaluations(files.evaluations, res.evaluations, self.names)
        values, component = tuned_parameter_set(self.scenario, res.best, self.parameter_set)
        text = ssv_text(values, "autotuned", self._description(res))
        self.ssv.parent.mkdir(parents=True, exist_ok=True)
        self.ssv.write_text(text)
        if self.install is not None:
            install(self.scenario, self.install, text)
        files.report.write_text(self._report(res, files.table, component))
        return files

    def _installed_scenario(self) -> str:
        """How to name the scenario that holds the installed set: its name, or the user's copy's folder."""
        folder = _scenario_dir(self.scenario)
        return self.scenario if self.install is None or self.install.parent == folder else str(self.install.parent)

    def _description(self, res: TuneResult) -> str:
        scenario_hash = getattr(self.spec, "scenario_hash", "") or self.spec.key
        return (f"ipcosim tune {self.spec.name} (scenario hash {scenario_hash}): J = {res.best_cost:.6g} "
                f"(scenario gains: {res.nominal_cost:.6g}), {len(res.evaluations)} runs, seed {self.seed}, "
                f"w_angle {self.w_angle:g}, w_voltage {self.w_voltage:g}")

    def _report(self, res: TuneResult, table: str, component: str | None) -> str:
        """``tune.md``: what was tuned, the cost, the before/after table and how to run the tuned set."""
        if component is None:
            usage = "It holds the tuned values as component.variable (apply them with --set)."
        elif self.install is not None:
            usage = (f"It is the complete `{component}` parameter set ({self.parameter_set or 'default'} with the "
                     f"tuned values), installed as `{self.install}`: `ipcosim run {self._installed_scenario()} "
                     f"--parameter-set autotuned` runs it.")
        else:
            usage = (f"It is the complete `{component}` parameter set ({self.parameter_set or 'default'} with the "
                     f"tuned values); copy it beside the scenario (or tune with --install) to run it with "
                     f"`--parameter-set autotuned`.")
        same = "" if res.best_cost < res.nominal_cost else \
            "The optimiser found nothing better than the scenario's gains; the written set repeats them.\n"
        return (f"# Tuning {self.spec.name}\n\n{self._description(res)}.\n\n"
                f"Cost J = ITAE(x - r) + {self.w_angle:g} ITAE(theta) + {self.w_voltage:g} ISE(u); infinite when "
                f"the pendulum falls.\n\n{table}\n{same}\nTuned parameter set: `{self.ssv}`. {usage}\n")


def _searched(params: str, bounds: Sequence[str], spec: RunSpec) -> tuple[list[str], list[tuple[float, float]]]:
    """The parameters to tune and their search ranges, checked against the scenario's parameters."""
    names = parse_params(params, spec.parameters)
    return names, parse_bounds(bounds, names, spec.parameters)


def _outputs(scenario: str, out: Path | str | None, ssv: Path | str | None,
             install: bool) -> tuple[Path, Path, Path | None]:
    """Where a tuning writes: its folder (created), the tuned set and, with ``install``, the copy beside the
    scenario (checked before any run)."""
    from ipcosim.harness.master.results import claim_output
    from ipcosim.harness.studies.specs import default_out

    installed = install_path(scenario) if install else None  # refused before the folder is made
    folder = claim_output(Path(out) if out else default_out(scenario, "tune"), "tune")
    return folder, Path(ssv) if ssv else folder / "autotuned.ssv", installed


def tune_study(scenario: str, params: str, *, bounds: Sequence[str] = (), set: Mapping[str, float] | None = None,
               budget: int = 200, seed: int = 0, stop_time: float | None = None, step: float | None = None,
               w_angle: float | None = None, w_voltage: float | None = None, fmus: str = "auto",
               parameter_set: str | None = None, out: Path | str | None = None, ssv: Path | str | None = None,
               install: bool = False, max_peak_sensitivity: float | None = None,
               min_delay_margin: float | None = None, spread: float | None = None,
               min_phase_margin: float | None = None) -> TuneStudy:
    """The tuning of ``params`` of a scenario, every option checked before any run (``ipcosim tune``).

    Parameters
    ----------
    scenario : str
        Scenario name or path, or ``pure:single-mass-lqr``.
    params : str
        The parameters to tune, ``component.variable`` comma-separated (:func:`parse_params`).
    bounds : sequence of str
        ``COMP.VAR=LOW:HIGH`` search ranges (:func:`parse_bounds`; default nominal/2 .. nominal*2).
    set : mapping, optional
        Fixed ``component.variable`` values in every run.
    budget, seed : int
        Runs, exactly (candidates with a spread), and the optimiser's seed.
    stop_time, step : float, optional
        The run's experiment [s] (default: the scenario's).
    w_angle, w_voltage : float, optional
        Cost weights (default ``cost.W_ANGLE``, ``cost.W_VOLTAGE``).
    fmus : {'auto', 'python', 'native'}
        FMU flavour (``ipcosim.harness.studies.specs.study_spec``).
    parameter_set : str, optional
        The set to start from (default: ``thesis`` where the scenario has it, :func:`starting_set`).
    out : Path or str, optional
        Output folder (created here; default ``out/tune/<scenario>``).
    ssv : Path or str, optional
        Where the tuned set goes (default ``OUT/autotuned.ssv``).
    install : bool
        Also put it beside the scenario (:func:`install_path`).
    max_peak_sensitivity, min_delay_margin, spread, min_phase_margin : float, optional
        The robust objective (:func:`robustness_objective`).

    Raises
    ------
    UsageError
        Any option that does not fit the scenario, named (TuneError for parameters, bounds and budget).
    """
    from ipcosim.harness.studies.specs import study_spec

    set = dict(set or {})
    pset = starting_set(scenario, parameter_set)
    spec, flavour = study_spec(scenario, fmus, names=list(set), check=lambda s: _searched(params, bounds, s),
                               stop_time=stop_time, step=step, set=set, parameter_set=pset)
    names, ranges = _searched(params, bounds, spec)
    plan_population(budget, len(names))  # checks the budget before starting workers
    folder, ssv_path, installed = _outputs(scenario, out, ssv, install)
    robust = robustness_objective(scenario, spec, set, pset, max_peak_sensitivity, min_delay_margin, spread,
                                  min_phase_margin)
    weights = (costmod.W_ANGLE if w_angle is None else w_angle, costmod.W_VOLTAGE if w_voltage is None else w_voltage)
    return TuneStudy(scenario, spec, flavour, names, ranges, pset, folder, ssv_path, installed, robust, budget, seed,
                     *weights)
