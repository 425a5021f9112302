"""Monte Carlo robustness: success rate, metric distributions and one figure per metric.

A run is a success when its status is ``ok``: the task's success criterion,
``ipcosim.fmus.metrics.success_status`` (upright, |mean error| <= 1 mm over the final window, the motor
cart's residual peak-to-peak within its bound). The success rate is reported with its 95 % Wilson score
interval, beside the distribution of the residual amplitude (median, 90th percentile).

A robustness study, one idea to a module:

    robustness_summary  the numbers: success rate with its interval, the metrics' distributions, as text
    robustness_figures  the figures: histograms and the metric against each varied parameter
    robustness_factors  what varies: the default uncertainty and the factors, alone and together
    robustness          (this module) a robustness sweep of a scenario, checked and ready to run: sweep_study
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ipcosim.harness.studies.robustness_factors import (
    DEFAULT_SPREAD,
    DEFAULT_UNCERTAINTY,
    EXTRA_DELAY,
    FACTOR_SPREAD,
    FACTORS,
    FRICTION_SPREAD,
    QUANTITY_UNITS,
    decisive_factor,
    default_vary,
    factor_cases,
    factor_cell,
    factor_runs,
    factor_study,
    quantities,
)
from ipcosim.harness.studies.robustness_figures import (
    FIGURE_RUNS,
    STATUS_COLORS,
    figure_rows,
    histogram,
    plot_distributions,
    plot_parameters,
    shown_tick_labels,
    tick_labels_overlap,
)
from ipcosim.harness.studies.robustness_summary import (
    amplitude_note,
    fmt,
    summarize,
    summarize_results,
    summary_line,
    summary_markdown,
    wilson_interval,
)


def write_summary(rows: Sequence[Mapping[str, Any]] | Path, spec: Any, varied: Sequence[str], out: Path,
                  extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Write a robustness sweep's ``summary.json``, ``summary.md`` and ``figures/`` (the metric against each
    varied parameter, then every metric's distribution) under ``out``; returns the summary
    (:func:`summarize` with the scenario's name and ``extra``, e.g. the variations and the seed).

    Parameters
    ----------
    rows : sequence of mapping, or Path
        The sweep's rows, or its results file (read back in memory independent of its size:
        :func:`summarize_results`, and the figures draw :func:`figure_rows`).
    spec : RunSpec
        The scenario that ran (its ``name`` and ``metric_names``).
    varied : sequence of str
        The parameters the sweep varied (``component.variable``).
    out : Path
        The sweep's folder.
    extra : mapping, optional
        Recorded in the summary beside the scenario's name.
    """
    import json

    if isinstance(rows, Path):
        summary = summarize_results(rows, spec.metric_names)
        drawn, total = figure_rows(rows)
    else:
        summary = summarize(rows, spec.metric_names)
        drawn, total = list(rows), len(rows)
    summary.update({"scenario": spec.name, **(extra or {})})
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    md = summary_markdown(summary, title=f"Robustness of {spec.name}")
    from ipcosim.harness.support.extras import optional_figure

    sample = f" (a random {len(drawn)} of {total} runs)" if len(drawn) < total else ""
    figures = optional_figure(lambda: plot_distributions(drawn, spec.metric_names, out / "figures",
                                                         title=spec.name + sample),
                              "the sweep's figures") or []
    metric = "itae_position" if "itae_position" in spec.metric_names else spec.metric_names[0]
    by_param = optional_figure(lambda: plot_parameters(drawn, list(varied), metric, out / "figures",
                                                       title=f"{spec.name}: {metric} against each varied "
                                                             f"parameter{sample}"),
                               "the sweep's figures")
    if by_param is not None:
        figures.insert(0, by_param)
    md += "\n" + "\n".join(f"![{p.stem}](figures/{p.name})" for p in figures) + "\n"
    (out / "summary.md").write_text(md)
    return summary


@dataclass
class SweepStudy:
    """A robustness sweep of one scenario, checked and ready to run (:func:`sweep_study`, ``ipcosim sweep``):
    :meth:`run` runs the cases into ``out`` (resuming finished ones), :meth:`write` writes the summary.

    Attributes
    ----------
    spec : RunSpec
        The scenario's run spec (fixed values applied).
    flavour : str
        Which FMUs run it, and why (``ipcosim.harness.studies.specs.study_spec``).
    varies : list of Vary
        The variations (``ipcosim.harness.api.grammar.parse_all``).
    cases : list of SweepCase
        The runs.
    out : Path
        The sweep's folder.
    metadata : dict
        What ``metadata.json`` records of the request (variations, fixed values, samples, seed, set).
    """

    spec: Any
    flavour: str
    varies: list
    cases: list
    out: Path
    metadata: dict[str, Any] = field(default_factory=dict)

    def plan_line(self, executor: Any) -> str:
        """One line: the scenario, the runs, where they run, the flavour and the folder."""
        return (f"sweep {self.spec.name}: {len(self.cases)} runs on {executor.description}, {self.flavour} -> "
                f"{self.out}")

    def run(self, executor: Any, progress: bool = True, extra: Mapping[str, Any] | None = None) -> Any:
        """The sweep on ``executor`` (``run_sweep``; ``extra`` joins the metadata). An interruption aborts
        the executor; the finished runs stay in ``out`` and a second run resumes them."""
        from ipcosim.harness.studies.specs import for_executor
        from ipcosim.harness.studies.sweep import run_sweep

        try:
            return run_sweep(for_executor(self.spec, executor), self.cases, out=self.out, executor=executor,
                             progress=progress, extra_metadata={**self.metadata, **(extra or {})})
        except KeyboardInterrupt:
            executor.abort()
            raise

    def write(self, result: Any) -> dict[str, Any]:
        """The summary, its Markdown and its figures (:func:`write_summary`); returns the summary."""
        return write_summary(result.path if result.path is not None else result.rows, self.spec,
                             [v.name for v in self.varies], self.out,
                             {"vary": self.metadata["vary"], "seed": self.metadata["seed"]})


def sweep_study(scenario: str, vary: Sequence[str], *, set: Mapping[str, float] | None = None,
                samples: int | None = None, seed: int = 0, fmus: str = "auto", parameter_set: str | None = None,
                stop_time: float | None = None, step: float | None = None, out: Path | str | None = None,
                fresh: bool = False, realism: str | None = None) -> SweepStudy:
    """A robustness sweep of ``scenario``, every option checked before any run.

    Parameters
    ----------
    scenario : str
        Scenario name or path, or ``pure:single-mass-lqr``.
    vary : sequence of str
        ``COMP.VAR=FORM`` variations (``ipcosim.harness.api.grammar.FORMS_HELP``).
    set : mapping, optional
        Fixed ``component.variable`` values in every run (``--set``).
    samples : int, optional
        Runs per grid point (default 100 with a random form, else 1).
    seed : int
        Master seed.
    fmus : {'auto', 'python', 'native'}
        FMU flavour (``ipcosim.harness.studies.specs.study_spec``).
    parameter_set : str, optional
        The scenario's parameter set to bind.
    stop_time, step : float, optional
        The run's experiment [s] (default: the scenario's).
    out : Path or str, optional
        The sweep's folder (default ``out/sweep/<scenario>``).
    fresh : bool
        Discard results already there (``ipcosim.harness.studies.store.discard_results``).
    realism : {'ideal', 'lab'}, optional
        Run every case on this bench (:func:`realism_values`; ``set`` wins over its values); the plant
        kind comes from the scenario's name.
    """
    from ipcosim.harness.api.grammar import parse_all
    from ipcosim.harness.master.results import claim_output
    from ipcosim.harness.studies.cases import make_cases
    from ipcosim.harness.studies.specs import default_out, study_spec
    from ipcosim.harness.studies.store import discard_results

    folder = claim_output(Path(out) if out else default_out(scenario), "sweep")  # before any work
    set = {**(_bench(scenario, realism) if realism else {}), **(set or {})}
    parsed: list[tuple[Any, Any]] = []  # (spec, its --vary parsed): the last is the spec chosen

    def check(candidate: Any) -> None:
        parsed.append((candidate, parse_all(vary, candidate.parameters)))

    spec, flavour = study_spec(scenario, fmus, names=[*set, *(v.partition("=")[0].strip() for v in vary)],
                               check=check, stop_time=stop_time, step=step, set=set, parameter_set=parameter_set)
    varies = next(v for s, v in reversed(parsed) if s is spec)  # --vary parsed once, against the spec that runs
    cases = make_cases(varies, spec.parameters, samples=samples, seed=seed)
    if fresh and folder.exists():
        discard_results(folder)
    return SweepStudy(spec, flavour, varies, cases, folder,
                      {"vary": list(vary), "set": set, "samples": samples, "seed": seed,
                       "parameter_set": parameter_set})


def _bench(scenario: str, realism: str) -> dict[str, float]:
    """:func:`~ipcosim.harness.analysis.residual_cycle.realism_values` for the plant kind the scenario's name
    says."""
    from ipcosim.errors import UsageError
    from ipcosim.fmus.kinds import plant_kind
    from ipcosim.fmus.params import KINDS
    from ipcosim.harness.analysis.residual_cycle import realism_values

    kind = plant_kind(str(scenario))
    if kind is None:
        raise UsageError(f"--realism {realism}: cannot tell the plant kind of scenario {scenario!r} from its name "
                         f"({' or '.join(KINDS)}); give the bench's values with --set")
    try:
        return realism_values(realism, kind)
    except ValueError as exc:
        raise UsageError(f"--realism: {exc}") from None


__all__ = ["sweep_study", "SweepStudy", "write_summary", "QUANTITY_UNITS", "quantities", "DEFAULT_UNCERTAINTY",
           "DEFAULT_SPREAD", "default_vary", "FACTORS", "FACTOR_SPREAD", "EXTRA_DELAY", "FRICTION_SPREAD",
           "factor_runs", "factor_cases", "factor_study", "decisive_factor", "factor_cell", "wilson_interval",
           "summarize", "summarize_results", "fmt", "summary_markdown", "summary_line", "amplitude_note",
           "FIGURE_RUNS", "figure_rows", "histogram", "plot_distributions", "shown_tick_labels",
           "tick_labels_overlap", "STATUS_COLORS", "plot_parameters"]
