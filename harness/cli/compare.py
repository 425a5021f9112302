"""``ipcosim compare``: run every scenario and write the controller comparison report.

    ipcosim compare [--out DIR] [--robustness [--samples N]] [--scenarios a,b,...] [--stop-time S]
                    [--workers W] [--scheduler ADDR] [--seed S]

FMUs missing from ``build/fmus`` (a fresh checkout) are built first, as ``ipcosim build`` does.
Writes ``DIR/report.md``, ``DIR/report.html`` (self-contained), ``DIR/figures/<plant>.png``,
``DIR/metrics.csv`` / ``metrics.json`` and, with ``--robustness``, one resumable sweep per
scenario under ``DIR/robustness/<scenario>/``.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path
from typing import Any

from ipcosim.harness.cli import add_study_fmus_option


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare", help="run every scenario and write the controller comparison report",
        description="Run every plant x controller scenario and write a Markdown and a self-contained HTML "
                    "report: metrics table, overlaid time series per plant and the thesis's claims beside "
                    "the measured numbers.")
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
    p.add_argument("--thesis-claims", action="store_true",
                   help="instead: judge the thesis's claims with its own gain sets on the ideal and the lab plant "
                        "(20 s, pure loop) and search the conditions under which its double-mass LQR falls; "
                        "writes DIR/claims.md and DIR/claims.json")
    p.set_defaults(func=main)


def thesis_claims(out: Path) -> int:
    """``--thesis-claims``: verdict, evidence and condition per claim (``ipcosim.harness.evidence.claims``)."""
    from ipcosim.harness.evidence.claims import judge, search_lqr_fall
    from ipcosim.harness.evidence.results_page import claims_table, fall_table

    out.mkdir(parents=True, exist_ok=True)
    rows, falls = judge(), search_lqr_fall()
    (out / "claims.json").write_text(json.dumps({"claims": rows, "double_mass_lqr_falls": falls}, indent=2))
    (out / "claims.md").write_text("# The thesis's claims, on its own terms\n\n" + claims_table(rows) +
                                   "\n\n## When the double-mass LQR falls\n\n" + fall_table(falls) + "\n")
    for r in rows:
        print(f"{r['verdict']:34s} {r['form']}")
    print(f"claims: {out / 'claims.md'}, {out / 'claims.json'}")
    return 0


def available_scenarios() -> list[str]:
    """The plant x controller scenarios of the project, in report order, plus any other folder
    that is not one of the generator's variants (swing-up, tap, lab: they pose other tasks)."""
    from ipcosim.harness.paths import SCENARIO_DIR
    from ipcosim.harness.scenario.ssp_gen import VARIANTS
    from ipcosim.harness.studies.report import SCENARIOS

    found = sorted(p.name for p in SCENARIO_DIR.iterdir() if (p / "SystemStructure.ssd").exists()) \
        if SCENARIO_DIR.is_dir() else []
    return [s for s in SCENARIOS if s in found] + [s for s in found if s not in SCENARIOS and s not in VARIANTS]


def plant_kind(scenario: str, spec: Any) -> str:
    """``single-mass`` or ``double-mass`` for a scenario (by name, else by its parameters)."""
    for kind in ("double-mass", "single-mass"):
        if kind in scenario:
            return kind
    return "double-mass" if "plant.K" in spec.parameters else "single-mass"


def _pset(scenario: str, wanted: str | None) -> str | None:
    """``wanted`` if the scenario has that parameter set, else None (its default binding)."""
    if not wanted:
        return None
    try:
        from ipcosim.harness.scenario.ssp import load_scenario

        return wanted if wanted in load_scenario(scenario).parameter_sets else None
    except Exception:  # noqa: BLE001 -- reported when the scenario itself is loaded
        return None


def main(args: argparse.Namespace) -> int:
    """Co-simulate every scenario once (one sweep over the scenarios), optionally a robustness
    sweep of each, then write the report, ``metrics.csv`` and ``metrics.json``."""
    if args.thesis_claims:
        return thesis_claims(Path(args.out))
    from ipcosim.errors import IpcosimError, UsageError
    from ipcosim.harness.studies.executors import open_executor
    from ipcosim.harness.studies.report import render
    from ipcosim.harness.studies.store import package_versions

    names = [s.strip() for s in args.scenarios.split(",") if s.strip()] if args.scenarios else available_scenarios()
    if not names:
        raise UsageError("no scenarios found (ssp/<plant>-<controller>/SystemStructure.ssd); "
                         "pass --scenarios or run 'ipcosim build'")
    if args.samples < 1:
        raise UsageError(f"--samples {args.samples}: need at least 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    results: dict[str, dict[str, Any]] = {}
    specs = _specs(names, args, results)
    executor = open_executor(args.workers, args.scheduler)
    print(f"compare: {len(specs)} scenarios on {executor.description}", file=sys.stderr)
    summaries: dict[str, dict[str, Any]] = {}
    try:
        results.update(_run_all(specs, executor, args))
        if args.robustness:
            summaries = _robustness(specs, executor, args, out)
    except KeyboardInterrupt:
        executor.abort()
        print(f"ipcosim compare: interrupted; robustness runs finished so far are kept under "
              f"{out / 'robustness'} and reused by the same command", file=sys.stderr)
        return 130
    finally:
        executor.close()

    note = ""
    if args.robustness:
        note = (f"Robust success: share of {args.samples} runs per scenario (seed {args.seed}) that stay upright and "
                f"settle in the +-2 % band when the masses, viscous friction and spring stiffness are each drawn "
                f"uniformly within +-20 % of nominal (Wilson 95 % interval); per-run results under robustness/.")
    meta = {"scenarios": len(names), "stop time": f"{args.stop_time:g} s" if args.stop_time else "scenario default",
            "executor": executor.description, "packages": package_versions()}
    files = render(results, out, robustness=summaries or None, robustness_note=note, meta=meta)
    _write_metrics(out, results, summaries)
    print(f"report: {files['markdown']}, {files['html']}")
    ok = sum(1 for r in results.values() if r.get("status") == "ok")
    print(f"{len(results)} scenarios: {ok} succeed, "
          f"{sum(1 for r in results.values() if r.get('status') == 'error')} failed to run")
    if results and all(r.get("status") == "error" for r in results.values()):
        first = next(iter(results.items()))
        raise IpcosimError(f"every scenario failed to run; {first[0]}: {first[1].get('error')}")
    return 0


def _specs(names: list[str], args: argparse.Namespace, results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The run spec of each scenario, by name; a scenario that cannot be loaded gets an error row
    in ``results`` instead. Missing FMUs (a fresh checkout) are built once, as ``ipcosim build`` does."""
    from ipcosim.errors import IpcosimError
    from ipcosim.harness.studies.executors import one_line
    from ipcosim.harness.studies.specs import study_spec

    specs: dict[str, Any] = {}
    for name in names:
        try:  # FMUs not built yet are built on first use (ipcosim.harness.engine.build_missing)
            spec, flavour = study_spec(name, args.fmus, stop_time=args.stop_time, series=True,
                                       parameter_set=_pset(name, args.parameter_set))
            if not args.quiet:
                print(f"compare: {name}: {flavour}", file=sys.stderr)
            specs[name] = spec
        except (IpcosimError, OSError, ValueError) as exc:
            results[name] = {"status": "error", "error": one_line(exc).split(": ", 1)[-1]}
            print(f"compare: {name}: {results[name]['error']}", file=sys.stderr)
    return specs


def _run_all(specs: dict[str, Any], executor: Any, args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """One run of every scenario, as one sweep whose case parameter picks the scenario; each row
    with its ``cost`` (inf for a run that failed) and the controller's ``gains``, by scenario."""
    from ipcosim.harness.studies.cases import SweepCase, case_seed
    from ipcosim.harness.studies.cost import cost
    from ipcosim.harness.studies.runners import SCENARIO_PARAM, MultiSpec
    from ipcosim.harness.studies.specs import for_executor
    from ipcosim.harness.studies.sweep import run_sweep

    if not specs:
        return {}
    names, spec_list = list(specs), list(specs.values())
    multi = for_executor(MultiSpec(specs=spec_list), executor)
    cases = [SweepCase(index=i, params={SCENARIO_PARAM: float(i)}, seed=case_seed(args.seed, i))
             for i in range(len(spec_list))]
    sweep = run_sweep(multi, cases, executor=executor, progress=not args.quiet)
    results: dict[str, dict[str, Any]] = {}
    for row in sweep.rows:
        name = names[row["index"]]
        row = {k: v for k, v in row.items() if k != SCENARIO_PARAM}
        row["cost"] = cost(row) if row["status"] != "error" else math.inf
        row["gains"] = getattr(spec_list[row["index"]], "gains", "") or ""
        results[name] = row
    return results


def _robustness(specs: dict[str, Any], executor: Any, args: argparse.Namespace, out: Path
                ) -> dict[str, dict[str, Any]]:
    """A resumable robustness sweep of each scenario (masses, friction, stiffness within +-20 %) on the
    flavour its comparison run took, under ``out/robustness/<scenario>/``, summarized by scenario."""
    from ipcosim.harness.grammar import parse_all
    from ipcosim.harness.studies import robustness as rob
    from ipcosim.harness.studies.cases import make_cases
    from ipcosim.harness.studies.specs import for_executor, spec_for
    from ipcosim.harness.studies.sweep import run_sweep

    summaries: dict[str, dict[str, Any]] = {}
    for name, spec in specs.items():
        plain = spec_for(name, stop_time=args.stop_time, parameter_set=_pset(name, args.parameter_set),
                         fmus=getattr(spec, "fmus", "python"))
        varies = parse_all(rob.default_vary(plant_kind(name, plain), plain.parameters), plain.parameters)
        cases = make_cases(varies, plain.parameters, samples=args.samples, seed=args.seed)
        if not args.quiet:
            print(f"compare: robustness of {name}, {len(cases)} runs", file=sys.stderr)
        res = run_sweep(for_executor(plain, executor), cases, executor=executor,
                        out=out / "robustness" / name,
                        progress=not args.quiet,
                        extra_metadata={"vary": [v.text for v in varies], "seed": args.seed})
        summaries[name] = rob.summarize(res.rows, plain.metric_names)
    return summaries


def _write_metrics(out: Path, results: dict[str, dict[str, Any]], summaries: dict[str, dict[str, Any]]) -> None:
    """``metrics.csv`` (one row per scenario, every key any row has) and ``metrics.json`` (non-finite
    numbers as null, without the time series)."""
    keys: dict[str, None] = {"scenario": None}
    for row in results.values():
        for k in row:
            if k not in ("series", "params"):
                keys.setdefault(k, None)
    with open(out / "metrics.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(keys))
        for name, row in results.items():
            w.writerow([name if k == "scenario" else ("" if row.get(k) is None else row.get(k)) for k in keys])
    clean = {n: {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                 for k, v in r.items() if k != "series"} for n, r in results.items()}
    (out / "metrics.json").write_text(json.dumps({"results": clean, "robustness": summaries}, indent=2) + "\n")
