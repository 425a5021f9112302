"""Monte Carlo robustness: success rate, metric distributions and one figure per metric.

A run is a success when its status is ``ok``: the task's success criterion,
``ipcosim.fmus.metrics.success_status`` (upright, |mean error| <= 1 mm over the final window, the motor
cart's residual peak-to-peak within its bound). The success rate is reported with its 95 % Wilson score
interval, beside the distribution of the residual amplitude (median, 90th percentile).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.fmus.kinds import ByKind, PlantKind

#: The plant parameters of each kind of physical quantity, by their unit (masses, viscous dampings, springs).
QUANTITY_UNITS = {"masses": ("kg",), "dampings": ("N.s/m", "N.m.s/rad"), "spring": ("N/m",)}


def quantities(kind: PlantKind, *groups: str) -> tuple[str, ...]:
    """``plant.<name>`` of each parameter of ``kind`` whose unit is one of ``groups``' (``QUANTITY_UNITS``),
    in the parameter class's order."""
    units = {u for g in groups for u in QUANTITY_UNITS[g]}
    return tuple(f"plant.{f.name}" for f in kind.params.__dataclass_fields__.values() if f.metadata["unit"] in units)


#: Default uncertainty of ``compare --robustness``: masses, friction (viscous damping) and the
#: spring stiffness, each uniform within +-20 % of its nominal value.
DEFAULT_UNCERTAINTY = ByKind(lambda k: quantities(k, "masses", "dampings", "spring"))
DEFAULT_SPREAD = 0.2


def default_vary(kind: str, parameters: Mapping[str, Any] | None = None, spread: float = DEFAULT_SPREAD) -> list[str]:
    """``--vary`` expressions of the default uncertainty for plant ``kind`` (only the
    parameters the scenario has, when ``parameters`` is given)."""
    names = DEFAULT_UNCERTAINTY[kind]
    if parameters is not None:
        names = tuple(n for n in names if n in parameters)
    return [f"{n}=uniform({1 - spread:g},{1 + spread:g})*nominal" for n in names]


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval of a success proportion (nan, nan for n = 0)."""
    if n <= 0:
        return (math.nan, math.nan)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def _numeric(rows: Iterable[Mapping[str, Any]], name: str) -> np.ndarray:
    values = []
    for r in rows:
        v = r.get(name)
        if isinstance(v, bool):
            values.append(1.0 if v else 0.0)
        elif isinstance(v, (int, float)) and math.isfinite(v):
            values.append(float(v))
    return np.asarray(values, dtype=float)


def summarize(rows: Sequence[Mapping[str, Any]], metric_names: Sequence[str]) -> dict[str, Any]:
    """Success rate and the distribution of each metric over the runs that completed.

    Returns
    -------
    dict
        ``runs``, ``counts`` (per status), ``success_rate``, ``success_ci95`` and ``metrics``:
        per metric ``n`` (runs with a value), ``mean``, ``std``, ``min``, ``p5``, ``median``,
        ``p90``, ``p95``, ``max`` (``ipcosim.harness.studies.columns.array_distribution``).
    """
    from ipcosim.harness.studies.columns import array_distribution

    counts: dict[str, int] = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    completed = [r for r in rows if r["status"] != "error"]
    return _summary(len(rows), counts, {name: array_distribution(_numeric(completed, name)) for name in metric_names})


def _summary(n: int, counts: dict[str, int], metrics: dict[str, dict[str, float]]) -> dict[str, Any]:
    ok = counts.get("ok", 0)
    lo, hi = wilson_interval(ok, n)
    return {"runs": n, "counts": counts, "success_rate": ok / n if n else math.nan,
            "success_ci95": [lo, hi], "metrics": metrics}


def summarize_results(path: Path, metric_names: Sequence[str], limit: int | None = None) -> dict[str, Any]:
    """:func:`summarize` of the rows of a results file, read back in memory independent of their number
    (``ipcosim.harness.studies.columns``: numpy's functions on a metric's values when there are at most
    ``limit``, default ``columns.IN_MEMORY_VALUES``, else the same numbers from passes over them on disk)."""
    from ipcosim.harness.studies import columns

    limit = columns.IN_MEMORY_VALUES if limit is None else limit
    with columns.ResultColumns(path, metric_names) as cols:
        completed = [s for s in cols.counts if s != "error"]
        metrics = {name: columns.distribution(cols.source(name, completed), limit) for name in metric_names}
        return _summary(cols.runs, dict(cols.counts), metrics)


#: Runs drawn in a sweep's figures: every run of a sweep up to this size, else a random sample of this many
#: (the summary's numbers are always of every run).
FIGURE_RUNS = 5000


def figure_rows(path: Path, limit: int | None = None, seed: int = 0) -> tuple[list[dict[str, Any]], int]:
    """The rows of a results file a sweep's figures draw, and the number of rows in the file: every row when there
    are at most ``limit`` (default :data:`FIGURE_RUNS`), else ``limit`` of them drawn uniformly at random
    (reservoir sampling, reproducible with ``seed``), in file order."""
    from ipcosim.harness.studies.store import iter_results

    limit = limit or FIGURE_RUNS
    rng = np.random.default_rng(seed)
    kept: list[tuple[int, dict[str, Any]]] = []
    n = 0
    _, rows = iter_results(path)
    for n, row in enumerate(rows, start=1):
        if len(kept) < limit:
            kept.append((n, row))
        else:
            j = int(rng.integers(n))
            if j < limit:
                kept[j] = (n, row)
    kept.sort(key=lambda item: item[0])
    return [row for _, row in kept], n


def fmt(value: Any, digits: int = 4) -> str:
    """A number for a table: 4 significant digits, '-' for missing."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, float)):
        if value == 0:
            return "0"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.{digits}g}"
    return str(value)


def summary_markdown(summary: Mapping[str, Any], title: str = "Robustness") -> str:
    """The summary as Markdown (success rate line + distribution table)."""
    lo, hi = summary["success_ci95"]
    counts = ", ".join(f"{k} {v}" for k, v in sorted(summary["counts"].items()))
    lines = [f"## {title}", "",
             f"Success rate: **{100 * summary['success_rate']:.1f} %** of {summary['runs']} runs "
             f"(95 % CI {100 * lo:.1f}-{100 * hi:.1f} %); {counts}." + (f" The {amplitude_note(summary)}."
                                                                if amplitude_note(summary) else ""), "",
             "| metric | runs | mean | std | min | p5 | median | p95 | max |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary["metrics"].items():
        if not s.get("n"):
            lines.append(f"| {name} | 0 | - | - | - | - | - | - | - |")
            continue
        lines.append(f"| {name} | {s['n']} | " + " | ".join(fmt(s[k]) for k in
                                                         ("mean", "std", "min", "p5", "median", "p95", "max")) + " |")
    return "\n".join(lines) + "\n"


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


def summary_line(summary: Mapping[str, Any]) -> str:
    """The success rate with its 95 % interval and the counts per status, on one line."""
    lo, hi = summary["success_ci95"]
    counts = ", ".join(f"{k} {v}" for k, v in sorted(summary["counts"].items()))
    return (f"success rate {100 * summary['success_rate']:.1f} % (95 % CI {100 * lo:.1f}-{100 * hi:.1f} %) "
            f"of {summary['runs']} runs: {counts}"
            + (f"; {amplitude_note(summary)}" if amplitude_note(summary) else ""))


def amplitude_note(summary: Mapping[str, Any]) -> str:
    """The motor cart's residual peak-to-peak over the runs (median, 90th percentile), which the success criterion
    bounds (``docs/metrics.md``); empty when the runs did not measure it."""
    amp = summary["metrics"].get("cart_peak_to_peak_m") or {}
    if not amp.get("n"):
        return ""
    return (f"motor-cart residual peak-to-peak median {1e3 * amp['median']:.3g} mm, 90th percentile "
            f"{1e3 * amp['p90']:.3g} mm")


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


def histogram(xg: np.ndarray, xb: np.ndarray, name: str, title: str = "") -> Any:
    """The figure of one metric's distribution: successful (``xg``) and failed (``xb``) runs
    stacked, its x tick labels apart (:func:`_readable_ticks`). A few runs far outside the rest
    (:func:`ipcosim.harness.api.plot.axis_limits`) are counted in the legend instead of stretching the axis."""
    import matplotlib.pyplot as plt

    from ipcosim.harness.api.plot import axis_limits

    fig, ax = plt.subplots(figsize=(5.0, 3.2), dpi=100)
    allx = np.concatenate([xg, xb])
    labels = [f"success ({xg.size})", f"failure ({xb.size})"]
    lo, hi = axis_limits([allx]) or (0.0, 0.0)
    beyond = (allx < lo) | (allx > hi)
    note = None
    if beyond.any() and hi > lo:  # a few runs far out would squash the rest into one bar: counted, not drawn
        xg, xb = xg[(xg >= lo) & (xg <= hi)], xb[(xb >= lo) & (xb <= hi)]
        far = allx[beyond]
        note = (f"{far.size} run(s) off the axis: " + (f"{far.min():.4g}" if far.size == 1 else
                                                        f"{far.min():.4g} .. {far.max():.4g}"))
        allx = allx[~beyond]
    bins = np.histogram_bin_edges(allx, bins=min(30, max(5, int(np.sqrt(allx.size)) + 1)))
    if np.ptp(allx) == 0:
        bins = np.array([allx[0] - 0.5, allx[0] + 0.5]) if allx[0] == 0 else \
            np.array([allx[0] * 0.99, allx[0] * 1.01])
        bins = np.sort(bins)
    ax.hist([xg, xb], bins=bins, stacked=True, color=["tab:green", "tab:red"],
            label=labels)
    ax.set_xlabel(name)
    ax.set_ylabel("runs")
    if title:
        ax.set_title(title, fontsize=9)
    if note:
        ax.plot([], [], " ", label=note)  # in the legend, where it cannot cover a bar or the title
    ax.legend(fontsize=8)
    fig.tight_layout()
    _readable_ticks(fig, ax.xaxis)
    fig.tight_layout()
    return fig


def plot_distributions(rows: Sequence[Mapping[str, Any]], metric_names: Sequence[str], out_dir: Path,
                       title: str = "") -> list[Path]:
    """One histogram per metric (successful and failed runs stacked), as PNG files.

    Returns
    -------
    list of Path
        The written figures, ``out_dir/<metric>.png``.
    """
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    completed = [r for r in rows if r["status"] != "error"]
    good = [r for r in completed if r["status"] == "ok"]
    bad = [r for r in completed if r["status"] != "ok"]
    paths = []
    for name in metric_names:
        xg, xb = _numeric(good, name), _numeric(bad, name)
        if xg.size + xb.size == 0:
            continue
        fig = histogram(xg, xb, name, title)
        path = out_dir / f"{name}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def shown_tick_labels(axis: Any, renderer: Any) -> list[Any]:
    """Window extents of the tick labels ``axis`` draws (those of ticks inside its view)."""
    lo, hi = sorted(axis.get_view_interval())
    slack = 1e-9 * max(abs(lo), abs(hi), 1.0)
    return [tick.label1.get_window_extent(renderer) for tick in axis.get_major_ticks()
            if lo - slack <= tick.get_loc() <= hi + slack and tick.label1.get_visible() and tick.label1.get_text()]


def tick_labels_overlap(fig: Any, axis: Any) -> bool:
    """Whether two of ``axis``'s drawn tick labels overlap, or come closer than 0.4 of the
    font size (a later layout pass may shift them by a pixel), once ``fig`` is drawn."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = sorted((b for b in shown_tick_labels(axis, renderer)), key=lambda b: b.x0)
    gap = 0.4 * axis.get_ticklabels()[0].get_size() * fig.dpi / 72 if boxes else 0.0  # [px]
    return any(a.x1 + gap > b.x0 and a.y1 > b.y0 and b.y1 > a.y0 for a, b in zip(boxes, boxes[1:]))


def _readable_ticks(fig: Any, axis: Any) -> None:
    """At most six ticks written in full (no ``+1`` offset nor ``1e6`` factor beside
    the axis); rotated when they
    still touch, fewer when even that does not part them."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    axis.set_major_formatter(formatter)
    for nbins, rotation in ((6, 0), (6, 30), (4, 30), (3, 45), (2, 45)):
        axis.set_major_locator(MaxNLocator(nbins=nbins))
        for label in axis.get_ticklabels():
            label.set_rotation(rotation)
            label.set_horizontalalignment("right" if rotation else "center")
        axis.set_tick_params(rotation=rotation)
        if not tick_labels_overlap(fig, axis):
            return


STATUS_COLORS = {"ok": "tab:green", "unsettled": "tab:orange", "hunting": "tab:purple", "fell": "tab:red",
                 "error": "black"}


def plot_parameters(rows: Sequence[Mapping[str, Any]], parameters: Sequence[str], metric: str, out_dir: Path,
                    title: str = "") -> Path | None:
    """Which parameter values fail: one panel per varied parameter, ``metric`` against the
    parameter's value, each run coloured by its status. Written to ``out_dir/parameters.png``."""
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parameters = [p for p in parameters if any(isinstance(r.get(p), (int, float)) for r in rows)]
    if not parameters:
        return None
    out_dir.mkdir(parents=True, exist_ok=True)
    n = len(parameters)
    cols = min(n, 3)
    nrows = (n + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), dpi=100, squeeze=False)
    for ax, name in zip(axes.ravel(), parameters):
        for status, color in STATUS_COLORS.items():
            pts = [(r[name], r.get(metric)) for r in rows if r["status"] == status
                   and isinstance(r.get(name), (int, float))]
            if not pts:
                continue
            xs = [p[0] for p in pts]
            ys = [p[1] if isinstance(p[1], (int, float)) and math.isfinite(p[1]) else math.nan for p in pts]
            if status == "error":
                finite = [y for r in rows for y in [r.get(metric)] if isinstance(y, (int, float)) and math.isfinite(y)]
                ys = [min(finite) if finite else 0.0] * len(xs)
            ax.scatter(xs, ys, s=12, color=color, label=f"{status} ({len(xs)})", alpha=0.8)
        ax.set_xlabel(name)
        ax.set_ylabel(metric)
        ax.grid(True, alpha=0.3)
        values = [y for r in rows for y in [r.get(metric)] if isinstance(y, (int, float)) and math.isfinite(y)]
        if values and min(values) > 0 and max(values) / min(values) > 100:
            ax.set_yscale("log")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    axes[0][0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = out_dir / "parameters.png"
    fig.savefig(path)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------- what decides it

#: The factors of :func:`factor_study`, in table order: the plant parameters each draws (uniform within
#: +-``FACTOR_SPREAD`` of nominal, per plant kind), or, for ``lab bench`` and ``delay``, a change of the bench.
FACTORS: dict[str, Mapping[str, tuple[str, ...]]] = {
    "masses": ByKind(lambda k: quantities(k, "masses")),
    "dampings": ByKind(lambda k: quantities(k, "dampings")),
    "spring": ByKind(lambda k: quantities(k, "spring"), only=lambda k: bool(quantities(k, "spring"))),
    "pendulum length": ByKind(lambda k: ("plant.Lp",)),
    "motor Kt, Ra": ByKind(lambda k: ("plant.Kt", "plant.Ra")),
    "lab bench": {},
    "delay": {},
}
#: Relative half-width of each drawn factor (default 0.2).
FACTOR_SPREAD = {"motor Kt, Ra": 0.1}
#: Extra transport delay of the ``delay`` factor [s] (on top of the lab bench's computation delay when both act).
EXTRA_DELAY = 1e-3
#: Relative half-width of the drawn Coulomb friction of the ``lab bench`` factor (the value is fitted, not measured).
FRICTION_SPREAD = 0.2


def factor_runs(kind: str, factors: Sequence[str]) -> tuple[list[str], dict[str, float]]:
    """``(--vary expressions, fixed values)`` of the runs with ``factors`` acting together on plant ``kind``.

    The lab bench is :func:`realism_values` of ``lab`` with each cart's Coulomb friction drawn within
    +-``FRICTION_SPREAD`` of its fitted value; the delay adds ``EXTRA_DELAY`` to the voltage's.
    """
    unknown = [f for f in factors if f not in FACTORS]
    if unknown:
        raise ValueError(f"unknown robustness factor {unknown[0]!r}; known: {', '.join(FACTORS)}")
    vary: list[str] = []
    fixed: dict[str, float] = {}
    for factor in factors:
        spread = FACTOR_SPREAD.get(factor, DEFAULT_SPREAD)
        vary += [f"{n}=uniform({1 - spread:g},{1 + spread:g})*nominal" for n in FACTORS[factor].get(kind, ())]
    if "lab bench" in factors:
        from ipcosim.harness.analysis.residual_cycle import realism_values

        for name, value in realism_values("lab", kind).items():
            if name in ("plant.b", "plant.b1", "plant.b2"):
                lo, hi = value * (1 - FRICTION_SPREAD), value * (1 + FRICTION_SPREAD)
                vary.append(f"{name}=uniform({lo:g},{hi:g})")
            else:
                fixed[name] = value
    if "delay" in factors:
        fixed["plant.input_delay"] = fixed.get("plant.input_delay", 0.0) + EXTRA_DELAY
    return vary, fixed


def factor_cases(spec: Any, kind: str, factors: Sequence[str], samples: int, seed: int = 0) -> list[Any]:
    """The runs of ``factors`` together on ``spec``'s scenario: ``samples`` draws, or one run when nothing is
    drawn (a deterministic bench: repeating it would count one outcome many times)."""
    from ipcosim.harness.api.grammar import parse_all
    from ipcosim.harness.studies.cases import make_cases

    vary, fixed = factor_runs(kind, factors)
    varies = parse_all(vary, spec.parameters)
    return make_cases(varies, spec.parameters, samples=samples if varies else 1, seed=seed, fixed=fixed)


def factor_study(scenario: str, kind: str, parameter_set: str | None = None, samples: int = 200,
                 stop_time: float = 15.0, seed: int = 0, executor: Any = None, fmus: str = "auto",
                 lab_parameter_set: str | None = None) -> dict[str, dict[str, Any]]:
    """Success of one scenario's loop under each factor of ``FACTORS`` alone, then all together.

    Returns ``{factor or "all together": summarize(...)}`` (a factor the plant kind lacks, such as the
    single mass's spring, is left out). The cells with the lab bench (it alone, all together) bind
    ``lab_parameter_set`` (default: ``parameter_set``), the others ``parameter_set``. Runs go through the sweep
    engine on ``executor`` (default: a local pool), on the native flavour where it can run them
    (``ipcosim.harness.studies.specs.study_spec``).
    """
    from ipcosim.harness.studies.specs import for_executor, study_spec
    from ipcosim.harness.studies.sweep import open_executor, run_sweep

    rows = [(f,) for f in FACTORS if f in ("lab bench", "delay") or FACTORS[f].get(kind)] + [tuple(FACTORS)]
    vary, fixed = factor_runs(kind, tuple(FACTORS))
    names = [v.partition("=")[0] for v in vary] + list(fixed)
    sets = {parameter_set, lab_parameter_set or parameter_set}
    specs = {p: study_spec(scenario, fmus, names=names, stop_time=stop_time, parameter_set=p)[0] for p in sets}
    own = executor is None
    executor = open_executor() if own else executor
    out: dict[str, dict[str, Any]] = {}
    try:
        specs = {p: for_executor(spec, executor) for p, spec in specs.items()}
        for factors in rows:
            spec = specs[lab_parameter_set or parameter_set if "lab bench" in factors else parameter_set]
            cases = factor_cases(spec, kind, factors, samples, seed)
            result = run_sweep(spec, cases, executor=executor)
            label = factors[0] if len(factors) == 1 else "all together"
            out[label] = summarize(result.rows, spec.metric_names)
    finally:
        if own:
            executor.close()
    return out


def decisive_factor(summaries: Mapping[str, Mapping[str, Any]], level: float = 0.95) -> str:
    """The factor that breaks a loop first: the one alone with the lowest success rate, if below ``level``;
    else ``none alone``."""
    alone = {k: s["success_rate"] for k, s in summaries.items() if k != "all together"}
    worst = min(alone, key=lambda k: alone[k])
    return worst if alone[worst] < level else "none alone"


def factor_cell(summary: Mapping[str, Any]) -> str:
    """One table cell: the success rate with its Wilson 95 % interval (a single deterministic run: its outcome)."""
    n = summary["runs"]
    if n == 1:
        status = next(iter(summary["counts"]))
        return "ok (1 run)" if status == "ok" else f"{status} (1 run)"
    lo, hi = summary["success_ci95"]
    return f"{100 * summary['success_rate']:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})"
