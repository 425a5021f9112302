"""The controller comparison (``ipcosim compare``): every plant x controller scenario once, optionally a
robustness sweep of each, then the report (``ipcosim.harness.studies.report``).

:func:`comparison` loads the scenarios and checks the request (no run yet); :meth:`Comparison.run` co-simulates
every scenario once, as one sweep whose case parameter picks the scenario, and with ``robustness`` a resumable
sweep of each under ``out/robustness/<scenario>/``; :meth:`Comparison.write` writes the report,
``metrics.csv`` and ``metrics.json``.
"""
from __future__ import annotations

import csv
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.errors import IpcosimError, UsageError


def available_scenarios() -> list[str]:
    """The plant x controller scenarios of the project, in report order, plus any other folder
    that is not one of the generator's variants (swing-up, tap, lab: they pose other tasks)."""
    from ipcosim.harness.scenario.scenarios import VARIANTS
    from ipcosim.harness.studies.report import SCENARIOS
    from ipcosim.harness.support.paths import SCENARIO_DIR

    found = sorted(p.name for p in SCENARIO_DIR.iterdir() if (p / "SystemStructure.ssd").exists()) \
        if SCENARIO_DIR.is_dir() else []
    return [s for s in SCENARIOS if s in found] + [s for s in found if s not in SCENARIOS and s not in VARIANTS]


def _pset(scenario: str, wanted: str | None) -> str | None:
    """``wanted`` if the scenario has that parameter set, else None (its default binding)."""
    if not wanted:
        return None
    try:
        from ipcosim.harness.scenario.ssp import load_scenario

        return wanted if wanted in load_scenario(scenario).parameter_sets else None
    except Exception:  # noqa: BLE001 -- reported when the scenario itself is loaded
        return None


def _plant_kind(scenario: str, spec: Any) -> str:
    """The plant kind of a scenario (``ipcosim.fmus.kinds.plant_kind``: by name, else by its plant's parameters)."""
    from ipcosim.fmus.kinds import plant_kind

    plant = [n.partition(".")[2] for n in spec.parameters if n.partition(".")[0] == "plant"]
    return plant_kind(scenario, parameters=plant)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


@dataclass
class Comparison:
    """A comparison of scenarios, loaded and checked (:func:`comparison`); :meth:`run` fills ``results``
    and ``robustness``, :meth:`write` writes them.

    Attributes
    ----------
    specs : dict
        Run spec of each scenario that loaded, by name.
    results : dict
        By scenario: its sweep row with ``cost`` (inf for a run that failed) and the controller's
        ``gains``, or an error row for a scenario that did not load or run.
    robustness : dict
        By scenario: the robustness summary (``ipcosim.harness.studies.robustness.summarize``); empty
        without ``robustness``.
    """

    names: list[str]
    out: Path
    parameter_set: str | None = None
    stop_time: float | None = None
    robust: bool = False
    samples: int = 20
    seed: int = 0
    specs: dict[str, Any] = field(default_factory=dict)
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    robustness: dict[str, dict[str, Any]] = field(default_factory=dict)
    executor_description: str = ""
    log: Callable[[str], None] = _stderr

    def run(self, executor: Any, progress: bool = True) -> Comparison:
        """One run of every scenario on ``executor``, then (``robust``) the robustness sweeps; returns self.
        On an interruption the executor is aborted (robustness runs finished so far stay on disk)."""
        self.executor_description = executor.description
        try:
            self.results.update(self._run_all(executor, progress))
            if self.robust:
                self.robustness = {name: self._robustness(name, spec, executor, progress)
                                   for name, spec in self.specs.items()}
        except KeyboardInterrupt:
            executor.abort()
            raise
        return self

    def _run_all(self, executor: Any, progress: bool) -> dict[str, dict[str, Any]]:
        """One run of every scenario, as one sweep whose case parameter picks the scenario."""
        from ipcosim.harness.studies.cases import SweepCase, case_seed
        from ipcosim.harness.studies.cost import cost
        from ipcosim.harness.studies.runners import SCENARIO_PARAM, MultiSpec
        from ipcosim.harness.studies.specs import for_executor
        from ipcosim.harness.studies.sweep import run_sweep

        if not self.specs:
            return {}
        names, spec_list = list(self.specs), list(self.specs.values())
        multi = for_executor(MultiSpec(specs=spec_list), executor)
        cases = [SweepCase(index=i, params={SCENARIO_PARAM: float(i)}, seed=case_seed(self.seed, i))
                 for i in range(len(spec_list))]
        results: dict[str, dict[str, Any]] = {}
        for row in run_sweep(multi, cases, executor=executor, progress=progress).rows:
            name = names[row["index"]]
            row = {k: v for k, v in row.items() if k != SCENARIO_PARAM}
            row["cost"] = cost(row) if row["status"] != "error" else math.inf
            row["gains"] = getattr(spec_list[row["index"]], "gains", "") or ""
            results[name] = row
        return results

    def _robustness(self, name: str, spec: Any, executor: Any, progress: bool) -> dict[str, Any]:
        """A resumable robustness sweep of one scenario (masses, friction, stiffness within +-20 %) on the
        flavour its comparison run took, under ``out/robustness/<scenario>/``, summarized."""
        from ipcosim.harness.api.grammar import parse_all
        from ipcosim.harness.studies import robustness as rob
        from ipcosim.harness.studies.cases import make_cases
        from ipcosim.harness.studies.specs import for_executor, spec_for
        from ipcosim.harness.studies.sweep import run_sweep

        plain = spec_for(name, stop_time=self.stop_time, parameter_set=_pset(name, self.parameter_set),
                         fmus=getattr(spec, "fmus", "python"))
        varies = parse_all(rob.default_vary(_plant_kind(name, plain), plain.parameters), plain.parameters)
        cases = make_cases(varies, plain.parameters, samples=self.samples, seed=self.seed)
        if progress:
            self.log(f"compare: robustness of {name}, {len(cases)} runs")
        res = run_sweep(for_executor(plain, executor), cases, executor=executor, out=self.out / "robustness" / name,
                        progress=progress, extra_metadata={"vary": [v.text for v in varies], "seed": self.seed})
        return rob.summarize(res.rows, plain.metric_names)

    def write(self, claims: Callable[[Any], Sequence[Any]] | None = None) -> dict[str, Path]:
        """Write the report (``ipcosim.harness.studies.report.render``), ``metrics.csv`` and ``metrics.json``;
        returns render's files and ``metrics_csv``/``metrics_json``. ``claims``: results -> the claims judged
        on them (``render``'s ``claims``), shown in the report."""
        from ipcosim.harness.studies.report import render
        from ipcosim.harness.studies.store import package_versions

        meta = {"scenarios": len(self.names),
                "stop time": f"{self.stop_time:g} s" if self.stop_time else "scenario default",
                "executor": self.executor_description, "packages": package_versions()}
        files = render(self.results, self.out, robustness=self.robustness or None, robustness_note=self.note,
                       meta=meta, claims=claims(self.results) if claims else ())
        return {**files, **self._write_metrics()}

    @property
    def note(self) -> str:
        """How the robustness column was obtained ("" without one)."""
        if not self.robust:
            return ""
        return (f"Robust success: share of {self.samples} runs per scenario (seed {self.seed}) that stay upright "
                f"and settle in the +-2 % band when the masses, viscous friction and spring stiffness are each "
                f"drawn uniformly within +-20 % of nominal (Wilson 95 % interval); per-run results under "
                f"robustness/.")

    def _write_metrics(self) -> dict[str, Path]:
        """``metrics.csv`` (one row per scenario, every key any row has) and ``metrics.json`` (non-finite
        numbers as null, without the time series)."""
        keys: dict[str, None] = {"scenario": None}
        for row in self.results.values():
            for k in row:
                if k not in ("series", "params"):
                    keys.setdefault(k, None)
        paths = {"metrics_csv": self.out / "metrics.csv", "metrics_json": self.out / "metrics.json"}
        with open(paths["metrics_csv"], "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(list(keys))
            for name, row in self.results.items():
                w.writerow([name if k == "scenario" else ("" if row.get(k) is None else row.get(k)) for k in keys])
        clean = {n: {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                     for k, v in r.items() if k != "series"} for n, r in self.results.items()}
        paths["metrics_json"].write_text(json.dumps({"results": clean, "robustness": self.robustness}, indent=2)
                                         + "\n")
        return paths

    def counts(self) -> tuple[int, int]:
        """(scenarios that succeed, scenarios that failed to run)."""
        statuses = [r.get("status") for r in self.results.values()]
        return statuses.count("ok"), statuses.count("error")

    def failure(self) -> str | None:
        """The error when every scenario failed to run (None otherwise)."""
        if self.results and all(r.get("status") == "error" for r in self.results.values()):
            name, row = next(iter(self.results.items()))
            return f"every scenario failed to run; {name}: {row.get('error')}"
        return None


def comparison(scenarios: Sequence[str] | None = None, out: Path | str = "out/compare", *, fmus: str = "auto",
               parameter_set: str | None = None, stop_time: float | None = None, robustness: bool = False,
               samples: int = 20, seed: int = 0, progress: bool = True,
               log: Callable[[str], None] = _stderr) -> Comparison:
    """A comparison of ``scenarios`` (default: :func:`available_scenarios`), checked and loaded, ready to run.

    Parameters
    ----------
    scenarios : sequence of str, optional
        Scenario names or paths.
    out : Path or str
        The report folder (created here).
    fmus : {'auto', 'python', 'native'}
        FMU flavour (``ipcosim.harness.studies.specs.study_spec``).
    parameter_set : str, optional
        Bound in every scenario that has it (else each scenario's own binding).
    stop_time : float, optional
        Simulated seconds per run [s] (default: the scenarios').
    robustness, samples, seed
        Add a robustness sweep of ``samples`` runs per scenario, seeded by ``seed``.
    progress : bool
        Name each scenario's flavour on ``log`` (and the sweeps show their progress).
    log : callable
        Where notes go (default: stderr).

    Raises
    ------
    UsageError
        No scenarios, or ``samples`` < 1.

    A scenario that cannot be loaded gets an error row in ``results`` instead of a spec; FMUs missing
    (a fresh checkout) are built once, as ``ipcosim build`` does.
    """
    from ipcosim.harness.studies.executors import one_line
    from ipcosim.harness.studies.specs import study_spec

    names = list(scenarios) if scenarios is not None else available_scenarios()
    if not names:
        raise UsageError("no scenarios found (ssp/<plant>-<controller>/SystemStructure.ssd); "
                         "pass --scenarios or run 'ipcosim build'")
    if samples < 1:
        raise UsageError(f"--samples {samples}: need at least 1")
    study = Comparison(names, Path(out), parameter_set, stop_time, robustness, samples, seed, log=log)
    study.out.mkdir(parents=True, exist_ok=True)
    for name in names:
        try:  # FMUs not built yet are built on first use (ipcosim.harness.api.engine.build_missing)
            spec, flavour = study_spec(name, fmus, stop_time=stop_time, series=True,
                                       parameter_set=_pset(name, parameter_set))
            if progress:
                log(f"compare: {name}: {flavour}")
            study.specs[name] = spec
        except (IpcosimError, OSError, ValueError) as exc:
            study.results[name] = {"status": "error", "error": one_line(exc).split(": ", 1)[-1]}
            log(f"compare: {name}: {study.results[name]['error']}")
    return study
