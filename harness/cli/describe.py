"""``ipcosim describe``: a scenario's components and the variables ``--set`` may change."""
from __future__ import annotations

import argparse

#: The one line ``ipcosim --help`` shows for this command.
HELP = "a scenario's components, variables, units and start values"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("describe", help=HELP,
                       description="List the components of a scenario, their FMUs in each flavour and every "
                                   "variable with causality, type, unit, start value (after the scenario's "
                                   "parameter sets), description, and the flavours in which --set may change it.")
    p.add_argument("scenario", metavar="SCENARIO|PATH",
                   help="scenario name (see `ipcosim list`), scenario folder, SystemStructure.ssd or .ssp archive")
    p.add_argument("--parameter-set", metavar="NAME", help="bind this parameter set instead of the default")
    p.add_argument("--json", action="store_true", help="print the description as JSON")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import json

    from ipcosim.harness.api.describe import describe, describe_text
    from ipcosim.harness.master.results import json_safe

    info = describe(args.scenario, parameter_set=args.parameter_set)
    print(json.dumps(json_safe(info), indent=1) if args.json else describe_text(info))
    return 0
