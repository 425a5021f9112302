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
import math
import sys
from pathlib import Path
from typing import Any

from ipcosim.harness.cli import add_study_fmus_option


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune", help="tune controller gains by differential evolution over parallel runs",
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
    p.add_argument("--spread", type=float, metavar="FRACTION",
                   help="robust objective: run every candidate also with the masses, dampings and spring all "
                        "scaled by 1 - FRACTION and by 1 + FRACTION, and count its worst run (the budget then "
                        "counts candidates)")
    p.add_argument("--quiet", action="store_true", help="no per-generation progress")
    p.set_defaults(func=main)


def _scenario_dir(scenario: str) -> Path | None:
    """The scenario's folder (where its .ssv files live), or None."""
    path = Path(scenario)
    if path.is_dir():
        return path
    if path.suffix == ".ssp" and path.exists():
        return path.parent
    from ipcosim.harness.paths import SCENARIO_DIR

    candidate = SCENARIO_DIR / scenario
    return candidate if candidate.is_dir() else None


def _install_path(args: argparse.Namespace) -> Path:
    """Where ``--install`` puts the tuned set: ``autotuned.ssv`` in the scenario's folder."""
    from ipcosim.errors import UsageError

    folder = _scenario_dir(args.scenario)
    if folder is None or Path(args.scenario).suffix == ".ssp":
        raise UsageError(f"--install: scenario {args.scenario!r} has no folder to install a parameter set into")
    return folder / "autotuned.ssv"


def _parameter_set(args: argparse.Namespace) -> str | None:
    """The parameter set to start from: ``--parameter-set``, else ``thesis`` where the scenario has it."""
    from ipcosim.harness.studies.specs import PURE_SCENARIOS

    if args.parameter_set is None and args.scenario not in PURE_SCENARIOS:
        from ipcosim.harness.scenario.ssp import load_scenario

        if "thesis" in load_scenario(args.scenario).parameter_sets:
            return "thesis"
    return args.parameter_set


def _robustness(args: argparse.Namespace, spec: Any, overrides: dict[str, Any], pset: str | None) -> Any:
    """The robust objective of ``--max-peak-sensitivity``, ``--min-delay-margin``, ``--spread`` (None without)."""
    from ipcosim.errors import UsageError
    from ipcosim.harness.studies import tune as tunemod
    from ipcosim.harness.studies.robustness import DEFAULT_UNCERTAINTY

    limits = (args.max_peak_sensitivity, args.min_delay_margin)
    if all(v is None for v in limits) and args.spread is None:
        return None
    for flag, value in (("--max-peak-sensitivity", args.max_peak_sensitivity),
                        ("--min-delay-margin", args.min_delay_margin), ("--spread", args.spread)):
        if value is not None and not (math.isfinite(value) and value > 0 and (flag != "--spread" or value < 1)):
            raise UsageError(f"{flag} {value}: expected a number > 0" + (" and < 1" if flag == "--spread" else ""))
    names = [n for kind in DEFAULT_UNCERTAINTY.values() for n in kind]
    spread = tunemod.spread_plants(spec.parameters, list(dict.fromkeys(names)), args.spread) if args.spread else ()
    return tunemod.Robustness(args.scenario, pset, {k: float(v) for k, v in overrides.items()},
                              args.max_peak_sensitivity, args.min_delay_margin, spread)


def main(args: argparse.Namespace) -> int:
    """Tune the named parameters of a scenario (differential evolution on the cost J over a run
    budget), then write the evaluations, the tuned parameter set and the report."""
    from ipcosim.harness.cli.sweep import default_out
    from ipcosim.harness.grammar import parse_set
    from ipcosim.harness.studies import cost as costmod
    from ipcosim.harness.studies import tune as tunemod
    from ipcosim.harness.studies.executors import open_executor
    from ipcosim.harness.studies.specs import for_executor, study_spec

    overrides = parse_set(args.set, numbers=True)
    pset = _parameter_set(args)
    spec, flavour = study_spec(args.scenario, args.fmus, names=list(overrides),
                               check=lambda s: tunemod.parse_bounds(
                                   args.bounds, tunemod.parse_params(args.params, s.parameters), s.parameters),
                               stop_time=args.stop_time, step=args.step, overrides=overrides, parameter_set=pset)
    names = tunemod.parse_params(args.params, spec.parameters)
    bounds = tunemod.parse_bounds(args.bounds, names, spec.parameters)
    w_angle = costmod.W_ANGLE if args.w_angle is None else args.w_angle
    w_voltage = costmod.W_VOLTAGE if args.w_voltage is None else args.w_voltage
    tunemod.plan_population(args.budget, len(names))  # checks the budget before starting workers
    out = Path(args.out) if args.out else default_out(args.scenario, "tune")
    out.mkdir(parents=True, exist_ok=True)
    ssv_path = Path(args.ssv) if args.ssv else out / "autotuned.ssv"
    install = _install_path(args) if args.install else None

    robust = _robustness(args, spec, overrides, pset)  # checks its options before starting workers
    executor = open_executor(args.workers, args.scheduler)
    print(f"tune {spec.name}: {', '.join(names)} within "
          f"{', '.join(f'[{lo:g}, {hi:g}]' for lo, hi in bounds)}, budget {args.budget} runs on "
          f"{executor.description}, {flavour}", file=sys.stderr)
    try:
        res = tunemod.tune(for_executor(spec, executor), names, bounds, budget=args.budget, executor=executor,
                           seed=args.seed, w_angle=w_angle, w_voltage=w_voltage, progress=not args.quiet,
                           robust=robust)
    except KeyboardInterrupt:
        executor.abort()
        print("ipcosim tune: interrupted; nothing written", file=sys.stderr)
        return 130
    finally:
        executor.close()

    tunemod.write_evaluations(out / "evaluations.csv", res.evaluations, names)
    table = _write_tuned(args, spec, res, pset, out, ssv_path, install, w_angle, w_voltage)
    print(table, end="")
    print(f"tuned parameter set: {ssv_path}" + (f" (installed: {install})" if install is not None else "")
          + f"\nreport: {out / 'tune.md'}, runs: {out / 'evaluations.csv'}")
    return 0


def _write_tuned(args: argparse.Namespace, spec: Any, res: Any, pset: str | None, out: Path, ssv_path: Path,
                 install: Path | None, w_angle: float, w_voltage: float) -> str:
    """Write the tuned parameter set (``ssv_path``, and ``install`` when given) and ``out/tune.md``;
    returns the report's before/after table."""
    from ipcosim.harness.scenario.ssp_gen import ssv_text
    from ipcosim.harness.studies import tune as tunemod

    scenario_hash = getattr(spec, "scenario_hash", "") or spec.key
    description = (f"ipcosim tune {spec.name} (scenario hash {scenario_hash}): J = {res.best_cost:.6g} "
                   f"(scenario gains: {res.nominal_cost:.6g}), {len(res.evaluations)} runs, seed {args.seed}, "
                   f"w_angle {w_angle:g}, w_voltage {w_voltage:g}")
    values, component = tunemod.tuned_parameter_set(args.scenario, res.best, pset)
    ssv_path.parent.mkdir(parents=True, exist_ok=True)
    text = ssv_text(values, "autotuned", description)
    ssv_path.write_text(text)
    if install is not None:
        install.write_text(text)
    if component is not None:
        usage = (f"It is the complete `{component}` parameter set ({pset or 'default'} with the tuned values)"
                 + (f", installed as `{install}`: `ipcosim run {args.scenario} --parameter-set autotuned` runs it."
                    if install is not None else
                    "; copy it beside the scenario (or tune with --install) to run it with "
                    "`--parameter-set autotuned`."))
    else:
        usage = "It holds the tuned values as component.variable (apply them with --set)."
    table = tunemod.before_after_markdown(res, f"{pset} gains" if pset else "scenario gains")
    improved = res.best_cost < res.nominal_cost
    report = (f"# Tuning {spec.name}\n\n{description}.\n\n"
              f"Cost J = ITAE(x - r) + {w_angle:g} ITAE(theta) + {w_voltage:g} ISE(u); infinite when the "
              f"pendulum falls.\n\n{table}\n"
              + ("" if improved else "The optimiser found nothing better than the scenario's gains; "
                                     "the written set repeats them.\n")
              + f"\nTuned parameter set: `{ssv_path}`. {usage}\n")
    (out / "tune.md").write_text(report)
    return table
