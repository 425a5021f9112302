"""The controller comparison report (``ipcosim compare``): metrics table plant x controller,
thesis-style overlaid time series per plant, and, when :func:`render` is given them, claims judged
on the results beside the measured numbers, each marked confirmed or not (the thesis's own claims
are not part of the package). Written as Markdown and as one self-contained HTML page (figures
embedded).

The report is rendered from plain data -- one result row per scenario (metrics, status and,
for the figures, the time series) plus optional robustness summaries -- so it can be checked
without running anything.
"""
from __future__ import annotations

import base64
import html
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from ipcosim.fmus.kinds import ByKind, get
from ipcosim.fmus.params import KINDS
from ipcosim.harness.scenario.scenarios import CONTROLLERS as SCENARIO_CONTROLLERS
from ipcosim.harness.studies.robustness_summary import fmt
from ipcosim.harness.support.extras import optional_figure

CONTROLLERS = ("pid", "cascade-pid", "lqr", "hsmc", "adaptive-hsmc")
#: Each scenario controller's name in the tables and figures: its law's name in the law registry (``LQR``).
CONTROLLER_LABELS = {slug: law for slug, (law, _) in SCENARIO_CONTROLLERS.items()}
PLANT_LABELS = ByKind(lambda k: k.name.replace("-", " "))
CONTROLLER_COLORS = {"pid": "tab:gray", "cascade-pid": "tab:purple", "lqr": "tab:orange", "hsmc": "tab:blue",
                     "adaptive-hsmc": "tab:green"}
#: Colours of the laws outside CONTROLLER_COLORS (an LQG, a discrete LQR), in table order.
EXTRA_COLORS = ("tab:red", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
SCENARIOS = tuple(f"{p}-{c}" for p in KINDS for c in CONTROLLERS)

#: The task's step [m] and the +-2 % band half-width [m].
#: Thesis's steady-state error of the double-mass HSMC [m] (section 4.2.3).

TABLE_COLUMNS = (("status", "status", None), ("settling_time_s", "settling time [s]", 4),
                 ("overshoot_m", "overshoot [m]", 3), ("steady_state_error_m", "steady-state error [m]", 3),
                 ("max_abs_angle_rad", "max abs angle [rad]", 3), ("peak_voltage_V", "peak voltage [V]", 3),
                 ("rms_voltage_V", "RMS voltage [V]", 3), ("upright", "upright", None),
                 ("cart_mean_error_m", "mean error, final 5 s [m]", 3),
                 ("cart_peak_to_peak_m", "residual peak-to-peak [m]", 3),
                 ("cart_frequency_Hz", "residual frequency [Hz]", 3), ("limit_cycle", "limit cycle", None),
                 ("angle_reversals", "angle reversals", None), ("cost", "cost J", 3))


def split(scenario: str) -> tuple[str, str]:
    """``single-mass-adaptive-hsmc`` -> (``single-mass``, ``adaptive-hsmc``)."""
    for plant in KINDS:
        if scenario.startswith(plant + "-"):
            return plant, scenario[len(plant) + 1:]
    return "", scenario


# --------------------------------------------------------------------------- claims


@dataclass(frozen=True)
class Verdict:
    """Outcome of checking one claim: ``confirmed``, ``not confirmed`` or ``not measured``."""

    verdict: str
    measured: str


Results = Mapping[str, Mapping[str, Any]]


# --------------------------------------------------------------------------- figures


def plot_plant(plant: str, results: Results, path: Path) -> Path | None:
    """Thesis-style overlaid time series of every controller on one plant: cart position with the
    reference, pendulum angle and voltage, one line per controller; a run whose pendulum fell ends
    at the fall (an x marks it: what follows is no controller's doing). None if no series."""
    from ipcosim.harness.support.extras import require

    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    laws = [(split(scenario)[1], results[scenario]) for scenario in table_order(results)
            if split(scenario)[0] == plant]
    series = [(c, row["series"]) for c, row in laws if row.get("series")]
    if not series:
        return None
    others = iter(EXTRA_COLORS * (1 + len(laws) // len(EXTRA_COLORS)))
    colors = {c: CONTROLLER_COLORS.get(c) or next(others) for c, _ in laws}
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 7.5), dpi=100, sharex=True)
    ref_drawn = False
    for controller, s in series:
        label = CONTROLLER_LABELS.get(controller, controller)
        color = colors[controller]
        if not ref_drawn:
            axes[0].plot(s["time"], s["reference"], "k--", lw=0.8, label="reference")
            ref_drawn = True
        fell = results[f"{plant}-{controller}"].get("fall_time_s")
        s = until(s, fell)
        failed = results[f"{plant}-{controller}"].get("status") != "ok"
        for ax, key, lw in ((axes[0], "position", 1.2), (axes[1], "angle", 1.0), (axes[2], "voltage", 0.8)):
            ax.plot(s["time"], s[key], label=label if fell is None else f"{label} (fell at {fell:.2f} s)", lw=lw,
                    color=color, zorder=1 if failed else 2)
            if fell is not None and len(s["time"]):
                ax.plot(s["time"][-1], s[key][-1], "x", color=color, markersize=7)
    cart = f"{get(plant).carts[0].position.replace('_', ' ')} [m]"
    axes[0].set_ylabel(cart)
    axes[1].set_ylabel("pendulum angle [rad]")
    axes[2].set_ylabel("voltage [V]")
    axes[2].set_xlabel("time [s]")
    axes[0].set_title(f"IP02 {PLANT_LABELS.get(plant, plant)}: controllers compared")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    for controller, row in laws:  # a law of the table without a time series is named, not dropped
        if not row.get("series"):
            axes[0].plot([], [], color=colors[controller], lw=0, marker="s",
                         label=f"{CONTROLLER_LABELS.get(controller, controller)}: no time series "
                               f"({row.get('status') or 'not run'})")
    axes[0].legend(fontsize=8, ncol=3)
    axes[1].set_ylim(-0.4, 0.4)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def until(series: Mapping[str, Sequence[float]], end: float | None) -> dict[str, list[float]]:
    """The samples of ``series`` (``time`` and signals) up to time ``end`` (all of them when None)."""
    n = len(series["time"]) if end is None else sum(1 for t in series["time"] if t <= end)
    return {key: list(values[:n]) for key, values in series.items()}


def table_order(results: Results) -> list[str]:
    """The scenarios of ``results`` in the table's (and the figures') order: the project's
    plant x controller scenarios first, then any other (an LQG, a discrete LQR) by name."""
    return sorted(results, key=lambda s: (SCENARIOS.index(s) if s in SCENARIOS else 99, s))


# --------------------------------------------------------------------------- document


def _table(results: Results, robustness: Mapping[str, Mapping[str, Any]] | None) -> tuple[list[str], list[list[str]]]:
    header = ["plant", "controller", "gains"] + [label for _, label, _ in TABLE_COLUMNS]
    if robustness:
        header.append("robust success (+-20 %)")
    rows = []
    for scenario in table_order(results):
        row = results[scenario]
        plant, controller = split(scenario)
        cells = [PLANT_LABELS.get(plant, plant), CONTROLLER_LABELS.get(controller, controller),
                 str(row.get("gains") or "-")]
        for key, _, digits in TABLE_COLUMNS:
            v = row.get(key)
            if key == "settling_time_s" and v is None and row.get("status") != "error":
                cells.append("not settled")  # docs/metrics.md: a fallen pendulum has not settled either
                continue
            cells.append(fmt(v, digits) if digits else fmt(v))
        if robustness:
            s = robustness.get(scenario)
            if s and s.get("runs"):
                lo, hi = s["success_ci95"]
                cells.append(f"{100 * s['success_rate']:.0f} % ({s['runs']} runs, CI {100 * lo:.0f}-{100 * hi:.0f} %)")
            else:
                cells.append("-")
        rows.append(cells)
    return header, rows


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    def esc(x: str) -> str:
        return str(x).replace("|", "\\|")
    lines = ["| " + " | ".join(map(esc, header)) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(map(esc, r)) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]], classes: Sequence[str] | None = None) -> str:
    out = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        out.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:0.9em}td,th{border:1px solid #bbb;padding:4px 8px;text-align:left}
th{background:#eee}tr.confirmed td:last-child{color:#16702c;font-weight:bold}
tr.not-confirmed td:last-child{color:#b00020;font-weight:bold}tr.not-measured td:last-child{color:#777}
img{max-width:100%}blockquote{margin:0;font-style:italic}code{background:#f4f4f4}"""


def render(results: Results, out_dir: Path, robustness: Mapping[str, Mapping[str, Any]] | None = None,
           robustness_note: str = "", meta: Mapping[str, Any] | None = None,
           claims: Sequence[tuple[str, str, str, Verdict]] = ()) -> dict[str, Path]:
    """Write ``report.md``, ``report.html`` (self-contained) and ``figures/<plant>.png``.

    Parameters
    ----------
    results : mapping
        Scenario name -> flat result row (status, metrics, ``cost``, optional ``series`` with
        ``time``, ``position``, ``reference``, ``angle``, ``voltage`` lists).
    out_dir : Path
        Report folder.
    robustness : mapping, optional
        Scenario name -> ``ipcosim.harness.studies.robustness.summarize`` output.
    robustness_note : str
        How the robustness column was obtained.
    meta : mapping, optional
        Run settings shown in the report (stop time, packages...).
    claims : sequence, optional
        Claims judged on these results, each (quote, source, how it is checked, :class:`Verdict`);
        the report shows them beside the numbers (none: no claims section).

    Returns
    -------
    dict
        ``markdown``, ``html`` and the figure paths by plant.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    figures: dict[str, Path] = {}
    for plant in KINDS:
        path = optional_figure(lambda kind=plant: plot_plant(kind, results, out_dir / "figures" / f"{kind}.png"),
                               "the comparison's figures")
        if path:
            figures[plant] = path
    header, rows = _table(results, robustness)
    meta = dict(meta or {})
    parts = _Report(
        settings=", ".join(f"{k} {v}" for k, v in meta.items() if k != "packages"),
        header=header, rows=rows, robustness_note=robustness_note,
        errors=[(s, r.get("error")) for s, r in results.items() if r.get("status") == "error"],
        figures=figures,
        counts={k: sum(1 for *_, v in claims if v.verdict == k)
                for k in ("confirmed", "not confirmed", "not measured")},
        claim_rows=[[quote, source, test, v.measured, v.verdict] for quote, source, test, v in claims],
        claim_classes=[v.verdict.replace(" ", "-") for *_, v in claims],
        packages=dict(meta.get("packages") or {}))
    md_path = out_dir / "report.md"
    md_path.write_text(_markdown(parts))
    html_path = out_dir / "report.html"
    html_path.write_text(_html_page(parts))
    return {"markdown": md_path, "html": html_path, **{f"figure:{p}": f for p, f in figures.items()}}


INTRO = ("Each scenario moves the motor-driven cart from 0 to 0.05 m with the pendulum upright (the thesis's "
         "task). Success (status ok, docs/metrics.md) = the pendulum stays within 0.35 rad, the cart's mean error "
         "over the final window is within 1 mm and its residual peak-to-peak within its bound; 'fell' = the "
         "pendulum left 0.35 rad; 'unsettled' = upright, mean error beyond 1 mm; 'hunting' = upright, residual "
         "amplitude beyond the bound. "
         "Cost J = ITAE(x - r) + 0.1 ITAE(angle) + 1e-4 ISE(voltage), infinite when the pendulum falls. "
         "Angle reversals count swings of the pendulum larger than 0.005 rad (an oscillation measure). "
         "Gains: the controller parameter set each scenario ran with (thesis = the thesis's values, tuned = "
         "the controller design's retuned values).")
CLAIM_HEADER = ["thesis claim", "source", "checked as", "measured", "verdict"]


@dataclass
class _Report:
    """What both forms of the report show, in order."""

    settings: str
    header: list[str]
    rows: list[list[Any]]
    robustness_note: str
    errors: list[tuple[str, Any]]
    figures: dict[str, Path]
    counts: dict[str, int]
    claim_rows: list[list[Any]]
    claim_classes: list[str]
    packages: dict[str, Any]

    @property
    def tally(self) -> str:
        c = self.counts
        return f"{c['confirmed']} confirmed, {c['not confirmed']} not confirmed, {c['not measured']} not measured."


def _markdown(r: _Report) -> str:
    """``report.md``: intro, settings, metrics table, failed runs, figures, the claims, versions."""
    md = ["# IP02 controller comparison", "", INTRO, ""]
    if r.settings:
        md += [f"Settings: {r.settings}.", ""]
    md += ["## Metrics (plant x controller)", "", _md_table(r.header, r.rows)]
    if r.robustness_note:
        md += [r.robustness_note, ""]
    if r.errors:
        md += ["Failed runs: " + "; ".join(f"{s}: {e}" for s, e in r.errors), ""]
    md += ["## Time series", ""]
    for plant, path in r.figures.items():
        md += [f"![{plant}](figures/{path.name})", ""]
    if r.claim_rows:
        md += ["## The thesis's claims, measured", "", "Judged on the runs above. " + r.tally, "",
               _md_table(CLAIM_HEADER, [[f"\"{c[0]}\"", *c[1:]] for c in r.claim_rows])]
    if r.packages:
        md += ["Package versions: " + ", ".join(f"{k} {v}" for k, v in r.packages.items()), ""]
    return "\n".join(md)


def _html_page(r: _Report) -> str:
    """``report.html``: the same as the Markdown, self-contained (figures inline as base64 PNG)."""
    body = ["<h1>IP02 controller comparison</h1>", f"<p>{html.escape(INTRO)}</p>"]
    if r.settings:
        body.append(f"<p>Settings: {html.escape(r.settings)}.</p>")
    body += ["<h2>Metrics (plant x controller)</h2>", _html_table(r.header, r.rows)]
    if r.robustness_note:
        body.append(f"<p>{html.escape(r.robustness_note)}</p>")
    if r.errors:
        body.append("<p>Failed runs: " + html.escape("; ".join(f"{s}: {e}" for s, e in r.errors)) + "</p>")
    body.append("<h2>Time series</h2>")
    for plant, path in r.figures.items():
        data = base64.b64encode(path.read_bytes()).decode()
        body.append(f'<figure><img alt="{plant}" src="data:image/png;base64,{data}"/>'
                    f"<figcaption>{html.escape(PLANT_LABELS[plant])}</figcaption></figure>")
    if r.claim_rows:
        body += ["<h2>The thesis's claims, measured</h2>", f"<p>Judged on the runs above. {r.tally}</p>",
                 _html_table(CLAIM_HEADER, r.claim_rows, r.claim_classes)]
    if r.packages:
        body.append("<p>Package versions: " + html.escape(", ".join(f"{k} {v}" for k, v in r.packages.items()))
                    + "</p>")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"/><title>IP02 controller comparison"
            f"</title><style>{CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")
