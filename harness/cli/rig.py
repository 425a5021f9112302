"""``ipcosim rig``: serve the virtual IP02 rig over TCP, reset it, or show its status."""
from __future__ import annotations

import argparse
import sys

#: The one line ``ipcosim --help`` shows for this command.
HELP = "the virtual IP02 rig (serve, reset, status)"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rig", help=HELP,
                       description="The virtual IP02 + Q4 rig for hardware-in-the-loop runs without hardware. "
                                   "See docs/hil.md.")
    rs = p.add_subparsers(dest="rig_command", metavar="ACTION")
    rs.required = True

    s = rs.add_parser("serve", help="serve a virtual rig (Ctrl-C to stop)",
                      description="Serve a virtual rig on HOST:PORT (card id N@tcpip://HOST:PORT). Binds 127.0.0.1 "
                                  "unless told otherwise; one controlling client at a time.")
    from ipcosim.fmus.params import KINDS

    s.add_argument("--plant", choices=KINDS, default=KINDS[0])
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=18920, help="TCP port (default 18920; 0 = any free port)")
    s.add_argument("--clock", choices=["lockstep", "wallclock"], default="wallclock",
                   help="lockstep: the rig advances only when asked (deterministic); wallclock (default): "
                        "with real time")
    s.add_argument("--tick", type=float, help="physics step [s] (default 1e-3 lockstep, 5e-4 wallclock)")
    s.add_argument("--preset", help="physical parameter preset (default: the plant's thesis preset)")
    s.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a physical parameter, e.g. --set Mp=0.2")
    s.add_argument("--initial", action="append", default=[], metavar="STATE=VALUE",
                   help="initial state value, e.g. --initial pendulum_angle=0.01")
    s.add_argument("--cart-limit", default=None, metavar="M|off",
                   help="software cart limit [m], in (0, 0.407] (default 0.30; 'off' disables it)")
    s.add_argument("--pendulum-limit-deg", default=None, metavar="D|off",
                   help="software pendulum limit [deg], in (0, 180] (default 20, off with --experiment identify; "
                        "'off' disables it)")
    s.add_argument("--experiment", metavar="NAME",
                   help="set the rig up for an experiment: identify = pendulum hanging, pendulum limit off, for "
                        "`ipcosim run KIND-identify --swap plant=hil` (docs/identify.md)")
    s.add_argument("--noise-counts", type=float, default=0.0, help="encoder noise std. deviation [counts]")
    s.add_argument("--latency", type=float, default=0.0, help="one-way transport latency [s]")
    s.add_argument("--seed", type=int, default=0, help="noise seed")
    s.add_argument("--duration", type=float, help="stop serving after this many seconds")
    _token_options(s)
    s.add_argument("--idle-timeout", type=float, default=5.0,
                   help="lease [s]: a client that sends no request for this long is dropped (default 5)")
    s.add_argument("--io-timeout", type=float, default=1.0,
                   help="read/write timeout [s] for a frame begun and for a reply (default 1)")
    s.add_argument("--max-connections", type=int, default=8, help="connections served at once (default 8)")
    s.add_argument("--rt-priority", type=int, metavar="P",
                   help="run under SCHED_FIFO at priority P (1..99) where permitted (reported as applied or not)")
    s.add_argument("--cpu", type=int, metavar="K", help="pin the rig to CPU K where permitted")
    s.add_argument("--stall-after-steps", type=int, metavar="N",
                   help="fault injection: stop answering a controller after N STEP requests")
    s.set_defaults(func=main)

    for name, helptext in (("reset", "the operator's reset: clear a latched limit trip, re-home the plant"),
                           ("status", "print the rig's safety status and counters")):
        a = rs.add_parser(name, help=helptext, description=helptext)
        a.add_argument("--host", default="127.0.0.1")
        a.add_argument("--port", type=int, default=18920)
        _token_options(a)
        a.set_defaults(func=main)


def _token_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--token-file", metavar="FILE",
                   help="file holding the rig's shared access token (default: IPCOSIM_RIG_TOKEN, or none)")
    p.add_argument("--token", help="access token on the command line (visible to other local users: prefer "
                                   "--token-file or IPCOSIM_RIG_TOKEN)")


def main(args: argparse.Namespace) -> int:
    """``serve``, or the operator's ``reset``/``status`` of a running rig (``ipcosim.fmus.hil.service``)."""
    from ipcosim.fmus.hil.service import operate, read_token

    if args.rig_command == "serve":
        return serve(args)
    operate(args.host, args.port, args.rig_command, read_token(args.token_file, args.token))
    return 0


def serve(args: argparse.Namespace) -> int:
    """Serve a virtual rig until Ctrl-C, SIGTERM or ``--duration``."""
    from ipcosim.fmus.hil import service
    from ipcosim.harness.api.grammar import parse_numbers
    from ipcosim.harness.master.host_setup import apply_cpu_affinity, apply_sched_fifo, apply_sched_slice, slice_request

    options = service.ServeOptions(
        plant=args.plant, host=args.host, port=args.port, clock=args.clock, tick=args.tick, preset=args.preset,
        initial=parse_numbers("--initial", args.initial, "NAME=NUMBER"),
        params=parse_numbers("--set", args.set, "NAME=NUMBER"), cart_limit=args.cart_limit,
        pendulum_limit_deg=args.pendulum_limit_deg, experiment=args.experiment, noise_counts=args.noise_counts,
        latency=args.latency, seed=args.seed, duration=args.duration,
        token=service.read_token(args.token_file, args.token),
        idle_timeout=args.idle_timeout, io_timeout=args.io_timeout, max_connections=args.max_connections,
        rt_priority=args.rt_priority, cpu=args.cpu, stall_after_steps=args.stall_after_steps)
    rig = options.rig()

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    service.dedicate()
    undo: list = []
    setup = {"cpu": apply_cpu_affinity(args.cpu, undo), "sched_fifo": apply_sched_fifo(args.rt_priority, undo)}
    asked = slice_request()
    slice_outcome = apply_sched_slice(asked, undo)     # said only when asked for: the default is silent
    setup.update({"sched_slice": slice_outcome} if asked is not None else {})
    for what, outcome in setup.items():
        if not outcome.startswith("not requested"):
            log(f"ipcosim rig: {what}: {outcome}")
    server = options.server(rig, log)
    print(service.announcement(server), flush=True)
    service.serve_until_stopped(server, args.duration, log)
    return 0
