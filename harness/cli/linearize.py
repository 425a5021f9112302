"""``ipcosim linearize``: the plant's linear model about the upright equilibrium."""
from __future__ import annotations

import argparse
import json

#: The one line ``ipcosim --help`` shows for this command.
HELP = "linear state-space model of a plant about upright"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("linearize", help=HELP,
                       description="Linearize a plant preset about the upright equilibrium.")
    from ipcosim.fmus.params import KINDS

    p.add_argument("plant", choices=KINDS)
    p.add_argument("--preset", help="parameter preset (default: thesis-ch3 / thesis-ch4)")
    p.add_argument("--no-inductance", action="store_true",
                   help="neglect the motor inductance (current eliminated: 4 or 6 states)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a physical parameter, e.g. --set Mp=0.2")
    p.add_argument("--json", action="store_true", help="print the model as JSON (A, B, C, D, states, poles)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import numpy as np

    from ipcosim.fmus.linearize import linearize
    from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, ParameterError, preset

    name = args.preset or DEFAULT_PRESET[args.plant]
    if name in PRESETS and PRESETS[name][0] != args.plant:
        raise ParameterError(f"preset {name!r} is a {PRESETS[name][0]} preset, not {args.plant}")
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParameterError(f"--set {item!r}: expected NAME=VALUE")
        try:
            overrides[key.strip()] = float(value)
        except ValueError:
            raise ParameterError(f"--set {item!r}: {value!r} is not a number") from None
    model = linearize(preset(name, **overrides), inductance=not args.no_inductance)
    if args.json:
        print(json.dumps(model.to_json_dict()))
        return 0
    with np.printoptions(precision=6, suppress=True, linewidth=160):
        print(f"{args.plant} ({name}), states: {', '.join(model.states)}")
        print("A =", model.A, sep="\n")
        print("B =", model.B.T, sep="\n")
        print("poles:", ", ".join(f"{p.real:.6g}{p.imag:+.6g}j" if p.imag else f"{p.real:.6g}"
                                  for p in model.poles))
    return 0
