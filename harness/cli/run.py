"""``ipcosim run``: co-simulate a scenario; write results.csv, metrics.json (and plot.png)."""
from __future__ import annotations

import argparse
import sys

from ipcosim.harness.cli import EXIT_REALTIME_DEGRADED, add_parameter_file_option

#: How the summary shows a metric that has no value (docs/metrics.md).
NOT_REACHED = {"settling_time_s": "not settled", "recovery_time_s": "not recovered",
               "time_to_upright_s": "not upright at the end"}


def task_verdict(m: dict, bound: float | None) -> str:
    """One line: the success criterion's status of a run and, for a hunting loop, its cycle (docs/metrics.md)."""
    from ipcosim.fmus.metrics import success_status

    status = success_status(m, bound)
    cycle = ""
    if m.get("limit_cycle"):
        freq = m.get("cart_frequency_Hz") or m.get("angle_frequency_Hz") or 0.0
        cycle = (f"; limit cycle at {freq:.2f} Hz: cart {1e3 * (m.get('cart_peak_to_peak_m') or 0):.3g} mm, "
                 f"pendulum {1e3 * (m.get('angle_peak_to_peak_rad') or 0):.3g} mrad peak to peak")
    return status + (f" (amplitude bound {1e3 * bound:.3g} mm)" if bound else "") + cycle


def register(sub: argparse._SubParsersAction) -> None:
    from ipcosim.harness.master.algorithm import ALGORITHMS, GAUSS_SEIDEL
    from ipcosim.harness.master.cloop import LOOPS
    from ipcosim.harness.paths import BUILD_DIR, BUILD_FMU_DIR
    from ipcosim.harness.scenario.flavour import FLAVOURS

    p = sub.add_parser("run", help="co-simulate a scenario (SSP folder or archive)",
                       description="Run an SSP scenario with the fmpy-based master and write DIR/results.csv "
                                   "(time, then component.variable), DIR/metrics.json and, with --plot, DIR/plot.png.")
    p.add_argument("scenario", metavar="SCENARIO|PATH",
                   help="scenario name (see `ipcosim list`), scenario folder, SystemStructure.ssd or .ssp archive")
    p.add_argument("--stop-time", metavar="S", help="simulated time [s] (default: the scenario's, 10 s)")
    p.add_argument("--step", metavar="H", help="communication step [s] (default: the scenario's, 0.001 s)")
    p.add_argument("--set", action="append", default=[], metavar="COMP.VAR=VALUE",
                   help="override a parameter or input start value, e.g. --set plant.Mp=0.2 (repeatable)")
    p.add_argument("--swap", action="append", default=[], metavar="COMPONENT=FMU_OR_ALIAS",
                   help="replace a component by another FMU with compatible connectors, e.g. --swap plant=hil")
    add_parameter_file_option(p)
    p.add_argument("--strict", action="store_true",
                   help="parameters of the scenario that a swapped-in FMU does not have are an error (default: "
                        "ignored, named in one warning line)")
    p.add_argument("--realtime", action="store_true", help="pace the run to wall-clock time")
    p.add_argument("--out", metavar="DIR", help="output folder (default: out/<scenario>)")
    p.add_argument("--plot", action="store_true", help="also write DIR/plot.png")
    p.add_argument("--parameter-set", metavar="NAME",
                   help="bind this parameter set of the scenario (thesis, tuned...) instead of the default")
    p.add_argument("--algorithm", choices=ALGORITHMS, default=GAUSS_SEIDEL,
                   help="co-simulation algorithm (default gauss-seidel, ordered by the FMUs' dependencies)")
    p.add_argument("--record", action="append", default=[], metavar="VAR[,VAR...]",
                   help="columns of results.csv: names or patterns like 'plant.*' (default: every connector)")
    p.add_argument("--fmu-dir", action="append", default=[], metavar="DIR",
                   help=f"extra folder to look for FMUs in (also IPCOSIM_FMU_PATH); the built ones are in "
                        f"{BUILD_FMU_DIR} (build/ of a source checkout, else the per-user cache)")
    p.add_argument("--save-baseline", metavar="FILE",
                   help="also write the recorded columns (see --record) as a baseline CSV for assert_close_to")
    p.add_argument("--fmus", choices=FLAVOURS, default=FLAVOURS[0],
                   help=f"FMU flavour: python (default, in {BUILD_FMU_DIR}) or native (C, from `ipcosim build "
                        f"--native`, in {BUILD_DIR / 'fmus-native'})")
    p.add_argument("--loop", choices=LOOPS, default=LOOPS[0],
                   help="the master's stepping loop: auto (default: compiled C where it can run, else Python), "
                        "c (an error where it cannot run) or python")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.add_argument("--overrun-budget", metavar="FRACTION",
                   help="a real-time run's allowed late steps, as a fraction of its steps (default: "
                        "IPCOSIM_RT_OVERRUN_BUDGET, else 0.01); a run beyond it warns and exits with status "
                        f"{EXIT_REALTIME_DEGRADED}")
    p.add_argument("--live", action="store_true",
                   help="serve a page showing the run as it happens, with a stop button (its address is printed)")
    p.add_argument("--live-host", metavar="ADDRESS", default="127.0.0.1",
                   help="where the live page listens (default 127.0.0.1; another address needs --live-token)")
    p.add_argument("--live-port", metavar="N", default=0, help="the live page's port (default 0: any free port)")
    p.add_argument("--live-token", metavar="TOKEN", help="access token the live page asks every request for")
    p.add_argument("--timeout", metavar="S",
                   help="wall-clock limit [s]: stop the run there with its results so far (exit status 124)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import warnings

    from ipcosim.harness.engine import prepare_with, run_with
    from ipcosim.harness.master import signals
    from ipcosim.harness.master.realtime import budget_warning
    from ipcosim.harness.master.results import json_safe
    from ipcosim.harness.options import RunOptions

    options = RunOptions.from_args(args)
    out = options.out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prepared = prepare_with(options, warn=False)
    with prepared:
        for note in prepared.system.warnings:
            print(f"ipcosim run: warning: {note}", file=sys.stderr)
        if not args.quiet:
            for note in prepared.system.notes:
                print(f"note: {note}")
        signals.keep(f"the rows so far are in {out / 'results.csv'}" if out is not None else None)
        result = run_with(options, prepared)
    if not args.quiet:
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
            print(f"  {'task':24s} {task_verdict(m, meta.get('amplitude_bound_m'))}")
        plotted = args.plot and "plot_skipped" not in result.metadata
        print(f"results: {out / 'results.csv'}, {out / 'metrics.json'}" + (f", {out / 'plot.png'}" if plotted else "")
              + (f", baseline {options.save_baseline}" if options.save_baseline else ""))
    if "plot_skipped" in result.metadata:
        print(f"ipcosim run: warning: plot.png skipped: {result.metadata['plot_skipped']}", file=sys.stderr)
    degraded = budget_warning(result.metrics)
    if degraded:
        print(f"ipcosim run: warning: {degraded}", file=sys.stderr)
        return EXIT_REALTIME_DEGRADED
    return 0
