"""``ipcosim rig``: serve the virtual IP02 rig over TCP, reset it, or show its status."""
from __future__ import annotations

import argparse
import math
import signal
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rig", help="the virtual IP02 rig (serve, reset, status)",
                       description="The virtual IP02 + Q4 rig for hardware-in-the-loop runs without hardware. "
                                   "See docs/hil.md.")
    rs = p.add_subparsers(dest="rig_command", metavar="ACTION")
    rs.required = True

    s = rs.add_parser("serve", help="serve a virtual rig (Ctrl-C to stop)",
                      description="Serve a virtual rig on HOST:PORT (card id N@tcpip://HOST:PORT). Binds 127.0.0.1 "
                                  "unless told otherwise; one controlling client at a time.")
    s.add_argument("--plant", choices=["single-mass", "double-mass"], default="single-mass")
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
    s.add_argument("--cart-limit", type=float, default=0.30, help="software cart limit [m] (default 0.30)")
    s.add_argument("--pendulum-limit-deg", type=float, default=20.0,
                   help="software pendulum limit [deg] (default 20)")
    s.add_argument("--noise-counts", type=float, default=0.0, help="encoder noise std. deviation [counts]")
    s.add_argument("--latency", type=float, default=0.0, help="one-way transport latency [s]")
    s.add_argument("--seed", type=int, default=0, help="noise seed")
    s.add_argument("--duration", type=float, help="stop serving after this many seconds")
    s.add_argument("--stall-after-steps", type=int, metavar="N",
                   help="fault injection: stop answering a controller after N STEP requests")
    s.set_defaults(func=main)

    for name, helptext in (("reset", "the operator's reset: clear a latched limit trip, re-home the plant"),
                           ("status", "print the rig's safety status and counters")):
        a = rs.add_parser(name, help=helptext, description=helptext)
        a.add_argument("--host", default="127.0.0.1")
        a.add_argument("--port", type=int, default=18920)
        a.set_defaults(func=main)


def _pairs(items: list[str], what: str) -> dict[str, float]:
    from ipcosim.harness.errors import UsageError

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[key.strip()] = float(value)
        except ValueError:
            raise UsageError(f"{what} {item!r}: expected NAME=NUMBER") from None
    return out


def main(args: argparse.Namespace) -> int:
    if args.rig_command == "serve":
        return serve(args)
    from ipcosim.harness.hil.tcpip import TcpipCard

    card = TcpipCard("q4", f"0@tcpip://{args.host}:{args.port}", args.host, args.port, role="monitor",
                     name="ipcosim rig " + args.rig_command)
    try:
        if args.rig_command == "reset":
            card.reset()
            print(f"rig at {args.host}:{args.port}: reset (amplifier enabled, limit latch cleared)")
        st = card.status()
        print(f"rig at {args.host}:{args.port}: time {st.time:.3f} s, amplifier "
              f"{'on' if st.amplifier_enabled else 'OFF'}, watchdog "
              f"{'EXPIRED' if st.watchdog_expired else ('running' if st.watchdog_running else 'stopped')}, "
              f"motor {st.motor_voltage:+.3f} V")
        if st.limit_message:
            print(f"  {st.limit_message}")
        if args.rig_command == "status":
            for k, v in sorted(st.counters.items()):
                print(f"  {k}: {v}")
    finally:
        card.close()
    return 0


def serve(args: argparse.Namespace) -> int:
    from ipcosim.harness.errors import UsageError
    from ipcosim.harness.hil.rig import RigConfig, VirtualRig
    from ipcosim.harness.hil.server import RigServer

    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port}: expected 0..65535")
    try:
        config = RigConfig(plant=args.plant, preset=args.preset, params=_pairs(args.set, "--set"),
                           initial_state=_pairs(args.initial, "--initial"), clock=args.clock, tick=args.tick,
                           cart_limit=args.cart_limit if args.cart_limit > 0 else None,
                           pendulum_limit=(math.radians(args.pendulum_limit_deg)
                                           if args.pendulum_limit_deg > 0 else None),
                           noise_counts=args.noise_counts, latency=args.latency, seed=args.seed).checked()
        rig = VirtualRig(config)
    except (ValueError, KeyError) as exc:
        raise UsageError(str(exc).strip("'\"")) from None

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    sys.setswitchinterval(1e-4)   # hand the GIL over quickly between the connection and ticker threads
    import gc
    gc.collect()
    gc.freeze()                   # start-up objects never again scanned by the collector (shorter pauses)
    server = RigServer(rig, args.host, args.port, stall_after_steps=args.stall_after_steps, log=log).start()
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        log(f"ipcosim rig: warning: listening on {args.host}, reachable from other machines")
    previous = signal.signal(signal.SIGTERM, lambda *_: server.request_stop())
    print(f"ipcosim rig: serving a {config.plant} rig ({config.clock} clock, tick {config.tick_s * 1e3:g} ms) on "
          f"{server.host}:{server.port} -- card id 0@tcpip://{server.host}:{server.port}", flush=True)
    try:
        server.serve(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        signal.signal(signal.SIGTERM, previous)
        log(f"ipcosim rig: stopped; counters: {dict(server.counters) or 'none'}")
    return 0
