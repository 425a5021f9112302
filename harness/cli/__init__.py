"""The ``ipcosim`` command line.

Each sub-command lives in its own module of this package exposing
``register(subparsers)`` (adds its parser, with ``func`` set to its entry point) and an
entry point ``main(args) -> int``. A failure is reported as one line on stderr naming what
is wrong and where, with a non-zero exit status; ``--debug`` shows the traceback instead.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

#: Sub-command modules, in the order ``ipcosim --help`` lists them.
COMMAND_MODULES = ("build", "list_", "run", "linearize", "analyze", "rig", "compare", "sweep", "tune")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every available sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="ipcosim",
        description="FMI co-simulation of the Quanser IP02 inverted pendulum (single and double mass).")
    parser.add_argument("--debug", action="store_true", help="show the full traceback on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"ipcosim.harness.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"ipcosim.harness.cli.{name}":
                continue  # command not part of this installation
            raise
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("ipcosim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`ipcosim list | head`): nothing to report
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # noqa: BLE001 -- the CLI's one-line error contract
        if args.debug:
            raise
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"ipcosim {args.command}: error: {message}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
