"""``ipcosim compare``: run every scenario and write the controller comparison report.

    ipcosim compare [--out DIR] [--robustness [--samples N]] [--scenarios a,b,...] [--stop-time S]
                    [--workers W] [--scheduler ADDR] [--seed S]

FMUs missing from the build folder (``build/fmus`` of a source checkout, else the per-user cache:
``ipcosim.harness.support.paths``) are built first, as ``ipcosim build`` does.
Writes ``DIR/report.md``, ``DIR/report.html`` (self-contained), ``DIR/figures/<plant>.png``,
``DIR/metrics.csv`` / ``metrics.json`` and, with ``--robustness``, one resumable sweep per
scenario under ``DIR/robustness/<scenario>/``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.harness.cli import add_study_fmus_option

#: The one line ``ipcosim --help`` shows for this command.
HELP = "run every scenario and write the controller comparison report"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare", help=HELP,
        description="Run every plant x controller scenario and write a Markdown and a self-contained HTML "
                    "report: metrics table and overlaid time series per plant.")
    p.add_argument("--out", default="out/compare", help="report folder (default out/compare)")
    p.add_argument("--scenarios", help="comma-separated scenario names (default: every scenario in ssp/)")
    p.add_argument("--robustness", action="store_true",
                   help="add a robustness column: success rate under +-20 %% uniform uncertainty of the masses, "
                        "friction (viscous damping) and spring stiffness")
    p.add_argument("--samples", type=int, default=20, help="robustness runs per scenario (default 20)")
    p.add_argument("--seed", type=int, default=0, help="robustness seed (default 0)")
    add_study_fmus_option(p)
    p.add_argument("--parameter-set", metavar="NAME",
                   help="bind this parameter set in every scenario that has it, e.g. thesis (default: each "
                        "scenario's own binding)")
    p.add_argument("--stop-time", type=float, help="simulated seconds per run (default: the scenarios')")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU cores)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler address tcp://HOST:PORT")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def main(args: argparse.Namespace, claims: Callable[[Any], Sequence[Any]] | None = None) -> int:
    """Co-simulate every scenario once (one sweep over the scenarios), optionally a robustness
    sweep of each, then write the report, ``metrics.csv`` and ``metrics.json``
    (``ipcosim.harness.studies.compare``); ``claims`` judges claims on the results for the report."""
    from ipcosim.harness.master import signals

    # said before the studies load (a second or more on a loaded machine), so a signal then says it too
    signals.keep(f"robustness runs finished so far are kept under {Path(args.out) / 'robustness'} and reused by "
                 f"the same command" if args.robustness else "no report written")
    from ipcosim.errors import IpcosimError
    from ipcosim.harness.master.results import claim_output
    from ipcosim.harness.studies.compare import comparison
    from ipcosim.harness.studies.executors import open_executor

    claim_output(args.out, "compare")  # before any run
    names = [s.strip() for s in args.scenarios.split(",") if s.strip()] if args.scenarios else None
    study = comparison(names, args.out, fmus=args.fmus, parameter_set=args.parameter_set, stop_time=args.stop_time,
                       robustness=args.robustness, samples=args.samples, seed=args.seed, progress=not args.quiet)
    executor = open_executor(args.workers, args.scheduler)
    print(f"compare: {len(study.specs)} scenarios on {executor.description}", file=sys.stderr)
    try:
        study.run(executor, progress=not args.quiet)
    except BaseException:  # a signal or an error: stop the workers now, not after their runs
        executor.abort()
        raise
    finally:
        executor.close()
    signals.keep(f"the report in {study.out} is incomplete; run the same command again")
    files = study.write(claims)
    print(f"report: {files['markdown']}, {files['html']}")
    ok, failed = study.counts()
    print(f"{len(study.results)} scenarios: {ok} succeed, {failed} failed to run")
    if study.failure():
        raise IpcosimError(study.failure())
    return 0

