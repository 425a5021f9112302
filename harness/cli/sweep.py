"""``ipcosim sweep``: Monte Carlo / grid robustness study of one scenario.

    ipcosim sweep SCENARIO --vary plant.Mp=uniform(0.8,1.2)*nominal [--vary ...] --samples N
                  [--workers W] [--seed S] [--scheduler tcp://HOST:PORT] [--out DIR] [--fresh]

Writes ``DIR/results.csv`` (one row per run, appended as runs finish; rerunning the same
command resumes an interrupted sweep), ``DIR/metadata.json``, ``DIR/summary.md`` /
``summary.json`` (success rate, metric distributions) and ``DIR/figures/<metric>.png``.
"""
from __future__ import annotations

import argparse
import sys

from ipcosim.harness.cli import add_parameter_file_option, add_study_fmus_option

#: The one line ``ipcosim --help`` shows for this command.
HELP = "robustness sweep: many runs of a scenario with varied parameters"


def register(sub: argparse._SubParsersAction) -> None:
    from ipcosim.fmus.instruments import REALISM  # the plant kinds' tables: only when sweep's options are built

    p = sub.add_parser(
        "sweep", help=HELP,
        description="Run a scenario many times with parameters drawn or stepped by --vary, in parallel "
                    "(local processes or a Dask cluster), and report the success rate (upright and settled "
                    "within the +-2 % band) and the distribution of every metric.",
        epilog="FORM: uniform(a,b) | normal(mean,std) | grid(start,stop,n) | [v1,v2,...] | number, each "
               "optionally *nominal (relative to the scenario's value). Example: "
               "--vary 'plant.Mp=uniform(0.8,1.2)*nominal' --vary 'plant.K=grid(100,180,5)'")
    p.add_argument("scenario", help="scenario name or path (or pure:single-mass-lqr, an FMU-free stand-in)")
    p.add_argument("--vary", action="append", default=[], metavar="COMP.VAR=FORM", required=True,
                   help="parameter variation (repeatable)")
    p.add_argument("--samples", type=int, default=None,
                   help="runs per grid point (default 100 with a random form, else 1)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU cores)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler address tcp://HOST:PORT")
    p.add_argument("--set", action="append", default=[], metavar="COMP.VAR=VALUE",
                   help="fixed parameter value in every run")
    add_parameter_file_option(p)
    add_study_fmus_option(p)
    p.add_argument("--parameter-set", metavar="NAME", help="bind this parameter set of the scenario (thesis, tuned...)")
    p.add_argument("--stop-time", type=float, help="simulated seconds per run (default: the scenario's)")
    p.add_argument("--step", type=float, help="communication step [s] (default: the scenario's)")
    p.add_argument("--out", help="output folder (default out/sweep/<scenario>)")
    p.add_argument("--fresh", action="store_true", help="discard results already in the output folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--realism", choices=sorted(REALISM), help="run every case on this bench (lab: encoder counts, "
                                                               "stick-slip friction, end stops, DAC, 1 ms delay; "
                                                               "--set wins over its values)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """Run the sweep and write its summary and figures (``ipcosim.harness.studies.robustness.sweep_study``)."""
    from ipcosim.errors import IpcosimError
    from ipcosim.harness.api.grammar import parse_set
    from ipcosim.harness.api.options import with_parameter_file
    from ipcosim.harness.master import signals
    from ipcosim.harness.studies.executors import open_executor
    from ipcosim.harness.studies.robustness import summary_line, sweep_study

    values = with_parameter_file(args.parameter_file, parse_set(args.set, numbers=True))
    study = sweep_study(args.scenario, args.vary, set=values, samples=args.samples, seed=args.seed,
                        fmus=args.fmus, parameter_set=args.parameter_set, stop_time=args.stop_time, step=args.step,
                        out=args.out, fresh=args.fresh, realism=args.realism)
    executor = open_executor(args.workers, args.scheduler)
    print(study.plan_line(executor), file=sys.stderr)
    signals.keep(f"finished runs are kept in {study.out / 'results.csv'}; run the same command again to resume")
    try:
        result = study.run(executor, progress=not args.quiet, extra={"command": "ipcosim " + " ".join(sys.argv[1:])})
    except BaseException:  # a signal or an error: stop the workers now, not after their runs
        executor.abort()
        raise
    finally:
        executor.close()
    signals.keep(f"every run is in {study.out / 'results.csv'}; the summary is incomplete: run the same command "
                 "again to write it")
    if result.resumed:
        print(f"resumed: {result.resumed} runs were already done", file=sys.stderr)
    summary = study.write(result)
    out = study.out
    print(summary_line(summary))
    print(f"results: {out / 'results.csv'}, summary: {out / 'summary.md'}, figures: {out / 'figures'}")
    if result.failure():
        raise IpcosimError(result.failure())
    return 0
