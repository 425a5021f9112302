"""``ipcosim tune``: find controller gains that minimise the documented cost.

    ipcosim tune SCENARIO --params controller.c1,controller.lambda1 [--budget N]
                 [--bounds controller.c1=1:10 ...] [--workers W] [--scheduler ADDR] [--seed S]

Starts from the scenario's ``thesis`` parameter set when it has one (the thesis's gains; else
its default binding, or ``--parameter-set``). ``--budget N`` makes exactly N runs. Everything
goes into ``--out`` (default ``out/tune/<scenario>``): ``autotuned.ssv`` (the complete controller
set with the tuned values), ``tune.md`` (before/after table) and ``evaluations.csv`` (every run).
``--install`` also copies the set beside the scenario (``ssp/<scenario>/autotuned.ssv``), so that
``ipcosim run SCENARIO --parameter-set autotuned`` runs it.
"""
from __future__ import annotations

import argparse
import sys

from ipcosim.harness.cli import add_study_fmus_option

#: The one line ``ipcosim --help`` shows for this command.
HELP = "tune controller gains by differential evolution over parallel runs"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune", help=HELP,
        description="Minimise J = ITAE(cart position error) + w_angle ITAE(angle) + w_voltage ISE(voltage) "
                    "(infinite when the pendulum falls) over the given parameters with scipy's differential "
                    "evolution; each generation runs in parallel on the sweep engine.")
    p.add_argument("scenario", help="scenario name or path (or pure:single-mass-lqr)")
    p.add_argument("--params", required=True, metavar="COMP.VAR,...", help="parameters to tune, comma-separated")
    p.add_argument("--bounds", action="append", default=[], metavar="COMP.VAR=LOW:HIGH",
                   help="search range (default: nominal/2 .. nominal*2)")
    p.add_argument("--budget", type=int, default=200,
                   help="number of runs, exactly, the scenario's own values included (default 200)")
    p.add_argument("--seed", type=int, default=0, help="optimiser seed (default 0)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU cores)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler address tcp://HOST:PORT")
    p.add_argument("--set", action="append", default=[], metavar="COMP.VAR=VALUE",
                   help="fixed parameter value in every run")
    p.add_argument("--stop-time", type=float, help="simulated seconds per run (default: the scenario's)")
    p.add_argument("--step", type=float, help="communication step [s] (default: the scenario's)")
    p.add_argument("--w-angle", type=float, default=None, help="weight of ITAE(angle) [m/rad] (default 0.1)")
    p.add_argument("--w-voltage", type=float, default=None, help="weight of ISE(voltage) [m s/V^2] (default 1e-4)")
    add_study_fmus_option(p)
    p.add_argument("--parameter-set", metavar="NAME",
                   help="start from this parameter set of the scenario (default: thesis when it exists)")
    p.add_argument("--ssv", help="where to write the tuned parameter set (default: OUT/autotuned.ssv)")
    p.add_argument("--install", action="store_true",
                   help="also copy the tuned parameter set beside the scenario (autotuned.ssv in its folder), "
                        "so that `ipcosim run SCENARIO --parameter-set autotuned` runs it")
    p.add_argument("--out", help="output folder: everything tuning writes goes there (default out/tune/<scenario>)")
    p.add_argument("--max-peak-sensitivity", type=float, metavar="MS",
                   help="robust objective: a candidate's peak |S| at the plant input (ipcosim analyze) must stay "
                        "at most MS, on the nominal plant and the spread; others are not run")
    p.add_argument("--min-delay-margin", type=float, metavar="SECONDS",
                   help="robust objective: a candidate's delay margin (ipcosim analyze) must be at least this")
    p.add_argument("--min-phase-margin", type=float, metavar="DEGREES",
                   help="robust objective: a candidate's phase margin (ipcosim analyze; its magnitude at the "
                        "crossover nearest -180 deg) must be at least this")
    p.add_argument("--spread", type=float, metavar="FRACTION",
                   help="robust objective: run every candidate also with the masses, dampings and spring all "
                        "scaled by 1 - FRACTION and by 1 + FRACTION, and count its worst run (the budget then "
                        "counts candidates)")
    p.add_argument("--quiet", action="store_true", help="no per-generation progress")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """Tune the named parameters of a scenario (differential evolution on the cost J over a run
    budget), then write the evaluations, the tuned parameter set and the report
    (``ipcosim.harness.studies.tune.tune_study``)."""
    from ipcosim.harness.api.grammar import parse_set
    from ipcosim.harness.master import signals
    from ipcosim.harness.studies.executors import open_executor
    from ipcosim.harness.studies.tune import tune_study

    study = tune_study(args.scenario, args.params, bounds=args.bounds, set=parse_set(args.set, numbers=True),
                       budget=args.budget, seed=args.seed, stop_time=args.stop_time, step=args.step,
                       w_angle=args.w_angle, w_voltage=args.w_voltage, fmus=args.fmus,
                       parameter_set=args.parameter_set, out=args.out, ssv=args.ssv, install=args.install,
                       max_peak_sensitivity=args.max_peak_sensitivity, min_delay_margin=args.min_delay_margin,
                       spread=args.spread, min_phase_margin=args.min_phase_margin)
    executor = open_executor(args.workers, args.scheduler)
    print(study.plan_line(executor), file=sys.stderr)
    signals.keep("no parameter set written")
    try:
        result = study.run(executor, progress=not args.quiet)
    except BaseException:  # a signal or an error: stop the workers now, not after their runs
        executor.abort()
        raise
    finally:
        executor.close()
    signals.keep(None)
    files = study.write(result)
    print(files.table, end="")
    print(f"tuned parameter set: {files.ssv}" + (f" (installed: {files.installed})" if files.installed else "")
          + f"\nreport: {files.report}, runs: {files.evaluations}")
    return 0
