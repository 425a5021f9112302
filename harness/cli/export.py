"""``ipcosim export``: a scenario's whole closed loop as one FMI 2.0 or 3.0 co-simulation FMU."""
from __future__ import annotations

import argparse
from pathlib import Path

#: The one line ``ipcosim --help`` shows for this command.
HELP = "write a scenario's closed loop as one FMU"


def register(sub: argparse._SubParsersAction) -> None:
    from ipcosim.harness.support.paths import BUILD_DIR

    p = sub.add_parser("export", help=HELP,
                       description="Write the whole closed loop of a scenario (setpoint, controller, plant) as one "
                                   "FMI 2.0 (or, with --fmi 3, FMI 3.0) co-simulation FMU built from the native "
                                   "components (`ipcosim build --native` first): input `reference` (added to the "
                                   "setpoint's output), outputs "
                                   "`<component>.<output>`, parameters `<component>.<name>`. Its results equal "
                                   "`ipcosim run SCENARIO --fmus native`'s.")
    p.add_argument("scenario", metavar="SCENARIO", help="scenario name (see `ipcosim list`) or scenario folder")
    p.add_argument("--out", required=True, type=Path, metavar="FILE.fmu", help="the FMU file to write")
    p.add_argument("--parameter-set", metavar="NAME",
                   help="bind this parameter set of the scenario (thesis, tuned...) instead of the default")
    p.add_argument("--model-identifier", metavar="NAME",
                   help="the FMU's model identifier (default: from the scenario's name, e.g. SingleMassLqrLoop)")
    p.add_argument("--set", action="append", default=[], metavar="COMP.VAR=VALUE",
                   help="a parameter's value in the FMU (its start value), as `ipcosim run --set`, e.g. "
                        "--set controller.sample_period=0.002 (repeatable)")
    p.add_argument("--fmu-dir", action="append", default=[], type=Path, metavar="DIR",
                   help=f"extra folder to look for the native FMUs in (built ones: {BUILD_DIR / 'fmus-native'}, "
                        "build/ of a source checkout, else the per-user cache)")
    p.add_argument("--fmi", choices=("2", "3"), default="2",
                   help="FMI version of the FMU: 2 (FMI 2.0, default) or 3 (FMI 3.0, same variables and results)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from ipcosim.harness.api.export import ExportOptions, export
    from ipcosim.harness.api.options import RunOptions

    values = RunOptions.create(args.scenario, set=args.set).set  # the --set grammar of `ipcosim run`
    out = export(ExportOptions(args.scenario, args.out, args.parameter_set, args.model_identifier,
                               tuple(args.fmu_dir), values, args.fmi))
    print(f"exported: {out}")
    return 0
