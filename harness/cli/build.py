"""``ipcosim build``: the FMUs into ``OUT/fmus`` and, when available, the SSP archives into ``OUT/ssp``."""
from __future__ import annotations

import argparse
from pathlib import Path

#: The one line ``ipcosim --help`` shows for this command.
HELP = "build the FMUs (and SSP archives) into build/"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("build", help=HELP,
                       description="Build every FMU script (fmus/fmu_*.py, controllers/fmu_*.py) into OUT/fmus/ "
                                   "and pack the SSP scenarios into OUT/ssp/. Unchanged FMUs are not rebuilt.")
    from ipcosim.harness.support.paths import BUILD_DIR

    p.add_argument("--out", default=BUILD_DIR, type=Path,
                   help=f"output folder (default: {BUILD_DIR})")
    p.add_argument("--native", action="store_true",
                   help="also build the native (C source-code) FMUs into OUT/fmus-native/")
    p.add_argument("--fmi", choices=("2", "3"), default="2",
                   help="with --native: the FMI version of the native FMUs, 2 (into OUT/fmus-native/, default) or 3 "
                        "(FMI 3.0, into OUT/fmus-native-fmi3/, and the clocked controllers into OUT/fmus-clocked/)")
    p.add_argument("--force", action="store_true", help="rebuild every FMU even if its sources are unchanged")
    from ipcosim.harness.scenario.ssp_pack import SSP_VERSIONS

    p.add_argument("--ssp-version", choices=SSP_VERSIONS, default="1.0",
                   help="the SSP version the archives in OUT/ssp/ declare: 1.0 (default) or 2.0 (checked against "
                        "the SSP 2.0 schema; OMSimulator 3 writes 2.0)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from ipcosim.fmus.pybuild import build_all
    from ipcosim.harness.scenario.ssp_pack import pack_all

    out: Path = args.out
    if args.fmi != "2" and not args.native:
        from ipcosim.errors import UsageError
        raise UsageError(f"--fmi {args.fmi}: only the native FMUs have an FMI {args.fmi}.0 variant (add --native)")
    for result in build_all(out / "fmus", force=args.force):
        print(f"{'built' if result.built else 'up to date'}: {result.fmu}")
    for archive in pack_all(out, ssp_version=args.ssp_version):
        print(f"packed: {archive}")
    if getattr(args, "native", False):
        from ipcosim.harness.native.cbuild import OUT_DIRS, build_native

        for native in build_native(out / "fmus", out / OUT_DIRS[args.fmi], fmi=args.fmi):
            binaries = " + ".join(native.platforms) if native.binary else "sources only"
            print(f"built (native FMI {args.fmi}.0, {binaries}): {native.fmu}")
        if args.fmi == "3":
            from ipcosim.harness.native.clocked import OUT_DIR, build_clocked
            for clocked in build_clocked(out / "fmus", out / OUT_DIR):
                print(f"built (native FMI 3.0, clocked, {' + '.join(clocked.platforms) or 'sources only'}): "
                      f"{clocked.fmu}")
    return 0
