"""``ipcosim run``: co-simulate a scenario; write results.csv, metrics.json (and plot.png)."""
from __future__ import annotations

import argparse
import sys

from ipcosim.harness.cli import EXIT_REALTIME_DEGRADED, collector_on

#: How the summary shows a metric that has no value (docs/metrics.md).
NOT_REACHED = {"settling_time_s": "not settled", "recovery_time_s": "not recovered",
               "time_to_upright_s": "not upright at the end"}


def task_verdict(m: dict, bound: float | None, source: str | None = None) -> str:
    """One line: the success criterion's status of a run, its bound and where the bound came from (``source``:
    ``prediction`` or the fallback's reason) and, for a hunting loop, its cycle (docs/metrics.md)."""
    from ipcosim.fmus.metrics import success_status

    status = success_status(m, bound)
    cycle = ""
    if m.get("limit_cycle"):
        freq = m.get("cart_frequency_Hz") or m.get("angle_frequency_Hz") or 0.0
        cycle = (f"; limit cycle at {freq:.2f} Hz: cart {1e3 * (m.get('cart_peak_to_peak_m') or 0):.3g} mm, "
                 f"pendulum {1e3 * (m.get('angle_peak_to_peak_rad') or 0):.3g} mrad peak to peak")
    origin = "" if not source else (", the predicted cycle + 1 mm" if source == "prediction" else f", {source}")
    return status + (f" (amplitude bound {1e3 * bound:.3g} mm{origin})" if bound else "") + cycle


#: The one line ``ipcosim --help`` shows for this command.
HELP = "co-simulate a scenario (SSP folder or archive)"


def register(sub: argparse._SubParsersAction) -> None:
    from ipcosim.harness.api.options import add_run_arguments

    p = sub.add_parser("run", help=HELP,
                       description="Run an SSP scenario with the fmpy-based master and write DIR/results.csv "
                                   "(time, then component.variable), DIR/metrics.json and, with --plot, DIR/plot.png.")
    add_run_arguments(p)  # every option of a run, from the fields of RunOptions
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import warnings

    from ipcosim.harness.api.engine import prepare_with, run_with
    from ipcosim.harness.api.options import RunOptions
    from ipcosim.harness.master import signals
    from ipcosim.harness.master.realtime import budget_warning
    from ipcosim.harness.master.results import json_safe

    options = RunOptions.from_args(args)
    out = options.out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prepared = prepare_with(options, warn=False)
    with prepared:
        for note in prepared.system.warnings:
            print(f"ipcosim run: warning: {note}", file=sys.stderr)
        if options.progress:
            for note in prepared.system.notes:
                print(f"note: {note}")
        signals.keep(f"the rows so far are in {out / 'results.csv'}" if out is not None else None)
        collector_on()
        result = run_with(options, prepared)
    if options.progress:
        m = json_safe(result.metrics)
        meta = result.metadata
        print(f"{meta['scenario']}: {meta['stop_time'] - meta['start_time']:g} s simulated in "
              f"{m['wall_time_s']:.3f} s ({m['real_time_factor']:.1f}x real time; stepping loop "
              f"{m['loop_real_time_factor'] or 0:.1f}x, {meta['loop']} loop), "
              f"{meta['algorithm']}, step {meta['step']:g} s, order {' -> '.join(meta['order'])}")
        for key, value in m.items():
            if key in ("wall_time_s", "real_time_factor", "loop_real_time_factor"):
                continue
            shown = f"{value:.6g}" if isinstance(value, float) else value
            print(f"  {key:24s} {NOT_REACHED.get(key, 'none') if value is None else shown}")
        if "cart_mean_error_m" in m:
            print(f"  {'task':24s} {task_verdict(m, meta.get('amplitude_bound_m'), meta.get('amplitude_bound_from'))}")
        plotted = options.plot and "plot_skipped" not in result.metadata
        print(f"results: {out / 'results.csv'}, {out / 'metrics.json'}" + (f", {out / 'plot.png'}" if plotted else "")
              + (f", baseline {options.save_baseline}" if options.save_baseline else ""))
    if "plot_skipped" in result.metadata:
        print(f"ipcosim run: warning: plot.png skipped: {result.metadata['plot_skipped']}", file=sys.stderr)
    degraded = budget_warning(result.metrics)
    if degraded:
        print(f"ipcosim run: warning: {degraded}", file=sys.stderr)
        return EXIT_REALTIME_DEGRADED
    return 0
