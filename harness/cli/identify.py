"""``ipcosim identify``: the plant's physical parameters from a run's log, with 95 % intervals."""
from __future__ import annotations

import argparse
import json
import sys

#: Exit status of an identification whose fit is not valid (its residual is well above the encoders' counts).
EXIT_NOT_VALID = 4


#: The one line ``ipcosim --help`` shows for this command.
HELP = "estimate the plant's parameters from a run's log (with 95 %% intervals)"


def register(sub: argparse._SubParsersAction) -> None:
    from ipcosim.fmus.params import KINDS

    p = sub.add_parser("identify", help=HELP,
                       description="Replay the logged voltage through the plant model, fit the named parameters to "
                                   "the logged encoder readings (output error, scipy least squares) and report each "
                                   "estimate with its 95 % interval and the fit (1 - NRMSE) per output on the "
                                   "held-out last quarter of the log. A log without the excitation the fit needs is "
                                   "refused before fitting; a fit that leaves the readings more than 3 encoder "
                                   f"counts off is not valid: it says so, writes no identified.ssv and exits "
                                   f"{EXIT_NOT_VALID}. Run `ipcosim run KIND-identify` for a log (docs/identify.md).")
    p.add_argument("source", metavar="RUN_DIR_OR_CSV", help="a run folder (holding results.csv) or a CSV file")
    p.add_argument("--plant", required=True, choices=KINDS, help="plant kind of the log")
    p.add_argument("--fit", metavar="NAME[,NAME...]",
                   help="parameters to estimate (default: single mass Mc,Beq,Bp,b,Kt; double mass "
                        "Ma,Mc,K,Ba,Bf,b1,b2,Kt; options: Mp, Lp, Ra, Kb, amplifier_gain, ...)")
    p.add_argument("--preset", metavar="NAME", help="preset of the parameters held fixed and of the fit's start")
    p.add_argument("--refits", type=int, metavar="N",
                   help="refits of synthetic logs behind the 95 %% intervals (default 8; 0: the sandwich alone, "
                        "faster, but it does not cover where the fit stopped: docs/identify.md)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no line on stderr while fitting (--json has none either)")
    p.add_argument("--out", metavar="DIR",
                   help="write DIR/identified.ssv (for --parameter-file; a valid fit only) and DIR/identified.png")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from ipcosim.harness.master.results import claim_output
    from ipcosim.harness.studies.identify import IdentifyOptions, identify

    if args.out:
        claim_output(args.out, "identify")  # before the fit: a bad --out is one line at once
    options = IdentifyOptions.create(args.source, plant=args.plant, fit=args.fit, preset=args.preset,
                                     out=args.out, refits=args.refits)
    def started() -> None:  # the fit and its refits take seconds: say so once the log is accepted
        if not (args.quiet or args.json):
            print(f"identify: fitting {', '.join(options.fit) or 'the default parameters'} of the {args.plant} "
                  f"plant to {args.source} ...", file=sys.stderr)

    result = identify(options, started)
    if result.replay != "native":
        print(f"ipcosim identify: the log was replayed in Python, 30 to 40 times slower than the native replay: "
              f"{result.replay}", file=sys.stderr)
    status = 0 if result.valid else EXIT_NOT_VALID
    if not result.valid:
        print(f"ipcosim identify: {result.source}: {result.invalid_reason}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.to_json()))
        return status
    print(f"{result.source}: {result.plant} plant, fitted to {result.held_out_from_s:g} s in {result.fit_time_s:.1f} s "
          f"({result.simulations} simulations of the log, {result.refits} refits behind the intervals, computation "
          f"delay {result.input_delay_s * 1e3:g} ms); "
          f"others from "
          f"preset {result.preset}")
    for name, p in result.parameters.items():
        lo, hi = p["ci95"]
        interval = f"95 %: {lo:.6g} .. {hi:.6g}" if result.valid else "no interval: the fit is not valid"
        note = f"; {p['note']}" if "note" in p else ""
        print(f"  {name:4s} = {p['value']:.6g} {p['unit']}  ({interval}{note})")
    print("  held-out fit (1 - NRMSE): " + ", ".join(f"{k} {v:.1%}" for k, v in result.fit.items()))
    print("  largest fitted residual [encoder counts; <= 0.5: every reading explained]: "
          + ", ".join(f"{k} {v:.2f}" for k, v in result.largest_residual_counts.items()))
    for path in result.written:
        print(f"wrote {path}")
    return status
