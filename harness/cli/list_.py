"""``ipcosim list``: the project's scenarios, one line each."""
from __future__ import annotations

import argparse

#: The one line ``ipcosim --help`` shows for this command.
HELP = "list the scenarios"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("list", help=HELP, description="List the SSP scenarios of ssp/, one line each.")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from ipcosim.harness.scenario.errors import ScenarioError
    from ipcosim.harness.scenario.locations import scenario_names
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.support.paths import SCENARIO_DIR

    names = scenario_names()
    if not names:
        print(f"no scenarios in {SCENARIO_DIR}")
        return 0
    width = max(len(n) for n in names)
    for name in names:
        try:
            sc = load_scenario(name)
        except ScenarioError as exc:
            print(f"{name:{width}s}  (broken: {exc})")
            continue
        sets = ", ".join(sorted(sc.parameter_sets)) or "-"
        exp = sc.experiment
        print(f"{name:{width}s}  {sc.description}  [{exp.stop_time:g} s at {exp.step_size:g} s; sets: {sets}]")
    return 0
