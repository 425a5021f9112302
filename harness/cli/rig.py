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
    s.add_argument("--cart-limit", default="0.30", metavar="M|off",
                   help="software cart limit [m], in (0, 0.407] (default 0.30; 'off' disables it)")
    s.add_argument("--pendulum-limit-deg", default="20", metavar="D|off",
                   help="software pendulum limit [deg], in (0, 180] (default 20; 'off' disables it)")
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


def _token(args: argparse.Namespace) -> str | None:
    """The access token from --token-file, --token or IPCOSIM_RIG_TOKEN (in that order), or None."""
    import os

    from ipcosim.errors import UsageError
    from ipcosim.fmus.hil.protocol import MAX_TOKEN, TOKEN_ENV

    if args.token_file:
        try:
            with open(args.token_file, encoding="utf-8") as fh:
                token = fh.read().strip()
        except (OSError, UnicodeDecodeError) as exc:
            raise UsageError(f"--token-file {args.token_file}: cannot read it ({exc})") from None
        if not token:
            raise UsageError(f"--token-file {args.token_file}: the file is empty")
    else:
        token = (getattr(args, "token", None) or os.environ.get(TOKEN_ENV, "")).strip()
    if len(token.encode("utf-8")) > MAX_TOKEN:
        raise UsageError(f"access token: longer than {MAX_TOKEN} bytes")
    return token or None


def main(args: argparse.Namespace) -> int:
    if args.rig_command == "serve":
        return serve(args)
    from ipcosim.fmus.hil.tcpip import TcpipCard

    card = TcpipCard("q4", f"0@tcpip://{args.host}:{args.port}", args.host, args.port, role="monitor",
                     name="ipcosim rig " + args.rig_command, token=_token(args) or "")
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


def _limit(text: str, option: str, hi: float) -> float | None:
    """A software limit: a finite number in (0, hi], or None for the explicit word 'off'."""
    from ipcosim.errors import UsageError

    if text.strip().lower() == "off":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (0 < value <= hi):   # NaN fails too
        raise UsageError(f"{option} {text}: expected a number in (0, {hi:g}] or 'off'")
    return value


def _check_numbers(args: argparse.Namespace) -> None:
    from ipcosim.errors import UsageError

    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port}: expected 0..65535")
    for option, value, lo, hi in (("--tick", args.tick, 1e-5, 0.01), ("--latency", args.latency, 0.0, 1.0),
                                  ("--noise-counts", args.noise_counts, 0.0, 1000.0),
                                  ("--duration", args.duration, 1e-3, 1e7),
                                  ("--idle-timeout", args.idle_timeout, 0.05, 3600.0),
                                  ("--io-timeout", args.io_timeout, 0.01, 60.0)):
        if value is not None and not (lo <= value <= hi):   # NaN fails too
            raise UsageError(f"{option} {value}: expected a number in [{lo:g}, {hi:g}]")
    if not 1 <= args.max_connections <= 1024:
        raise UsageError(f"--max-connections {args.max_connections}: expected 1..1024")
    if args.rt_priority is not None and not 1 <= args.rt_priority <= 99:
        raise UsageError(f"--rt-priority {args.rt_priority}: expected 1..99")
    if args.cpu is not None and not 0 <= args.cpu <= 4095:
        raise UsageError(f"--cpu {args.cpu}: expected a CPU number")


def serve(args: argparse.Namespace) -> int:
    from ipcosim.errors import UsageError
    from ipcosim.fmus.hil.rig import END_STOP_M, RigConfig, VirtualRig
    from ipcosim.fmus.hil.server import RigServer, escape
    from ipcosim.harness.grammar import parse_numbers

    _check_numbers(args)
    params = parse_numbers("--set", args.set, "NAME=NUMBER")
    initial = parse_numbers("--initial", args.initial, "NAME=NUMBER")
    cart_limit = _limit(args.cart_limit, "--cart-limit", END_STOP_M)
    pend_limit = _limit(args.pendulum_limit_deg, "--pendulum-limit-deg", 180.0)
    try:
        config = RigConfig(plant=args.plant, preset=args.preset, params=params,
                           initial_state=initial, clock=args.clock, tick=args.tick,
                           cart_limit=cart_limit,
                           pendulum_limit=None if pend_limit is None else math.radians(pend_limit),
                           noise_counts=args.noise_counts, latency=args.latency, seed=args.seed).checked()
        rig = VirtualRig(config)
    except (ValueError, KeyError) as exc:
        raise UsageError(str(exc).strip("'\"")) from None

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    sys.setswitchinterval(1e-4)   # hand the GIL over quickly between the connection and ticker threads
    import gc
    gc.collect()
    gc.freeze()                   # start-up objects never again scanned by the collector
    gc.disable()                  # no collection pauses while a controller steps; the server collects
    #                               between sessions (RigServer._release)
    from ipcosim.harness.master.realtime import apply_cpu_affinity, apply_sched_fifo
    undo: list = []
    setup = {"cpu": apply_cpu_affinity(args.cpu, undo), "sched_fifo": apply_sched_fifo(args.rt_priority, undo)}
    for what, outcome in setup.items():
        if not outcome.startswith("not requested"):
            log(f"ipcosim rig: {what}: {outcome}")
    try:
        server = RigServer(rig, args.host, args.port, stall_after_steps=args.stall_after_steps, log=log,
                           token=_token(args), idle_timeout=args.idle_timeout, io_timeout=args.io_timeout,
                           max_connections=args.max_connections).start()
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    previous = {sig: signal.signal(sig, lambda *_: server.request_stop()) for sig in (signal.SIGTERM, signal.SIGINT)}
    access = "token required" if server.token else "loopback only, no token"
    print(f"ipcosim rig: serving a {config.plant} rig ({config.clock} clock, tick {config.tick_s * 1e3:g} ms) on "
          f"{server.host}:{server.port} ({access}) -- card id 0@tcpip://{server.host}:{server.port}", flush=True)
    try:
        server.serve(args.duration)
    finally:
        server.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        counters = ", ".join(f"{escape(k)} {v}" for k, v in sorted(server.counters.items())) or "none"
        log(f"ipcosim rig: stopped; motor at {rig.motor_voltage():+.3f} V; counters: {counters}")
    return 0
