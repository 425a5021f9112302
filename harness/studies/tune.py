"""A scenario's gain tuning (``ipcosim tune``, :func:`tune_study`): the parameters to tune and their search
ranges checked against the scenario, the set it starts from, the robust objective and where it writes,
every option before any run; then the search and the files.

The tuning, one idea to a module:

    tune_search   the search: differential evolution whose generations run as sweeps (tune, TuneResult)
    tune_outputs  what it writes: the tuned parameter set, the before/after table, every run, --install
    tune          (this module) a scenario's tuning, checked and ready to run: tune_study, TuneStudy
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from ipcosim.errors import UsageError, closest
from ipcosim.harness.studies import cost as costmod
from ipcosim.harness.studies.runners import RunSpec
from ipcosim.harness.studies.tune_outputs import (
    TABLE_METRICS,
    _scenario_dir,
    before_after_markdown,
    install,
    install_path,
    tuned_parameter_set,
    write_evaluations,
)
from ipcosim.harness.studies.tune_search import (
    Robustness,
    SweepMap,
    TuneError,
    TuneResult,
    plan_population,
    population_size,
    spread_plants,
    tune,
)

#: Default search range around a nominal value g: [g / DEFAULT_FACTOR, g * DEFAULT_FACTOR].
DEFAULT_FACTOR = 2.0


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
    from ipcosim.harness.studies.robustness_factors import DEFAULT_UNCERTAINTY

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


__all__ = ["tune_study", "TuneStudy", "TunedFiles", "parse_params", "parse_bounds", "starting_set",
           "robustness_objective", "DEFAULT_FACTOR", "TuneError", "TuneResult", "Robustness", "spread_plants",
           "SweepMap", "population_size", "plan_population", "tune", "tuned_parameter_set", "TABLE_METRICS",
           "before_after_markdown", "write_evaluations", "install_path", "install"]
