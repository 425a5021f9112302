"""``ipcosim view``: a finished run (or a sweep's table) in the browser, served until Ctrl-C."""
from __future__ import annotations

import argparse
import sys

#: The one line ``ipcosim --help`` shows for this command.
HELP = "a finished run (or a sweep's table) in the browser"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help=HELP,
                       description="Serve the live page of a finished run (DIR/results.csv and DIR/metrics.json of "
                                   "`ipcosim run --out DIR`), or the table of a sweep (DIR/results.csv of "
                                   "`ipcosim sweep --out DIR`), on localhost until Ctrl-C. The address is printed.")
    p.add_argument("folder", metavar="RUN_DIR|SWEEP_DIR", help="a run's or a sweep's output folder")
    p.add_argument("--host", metavar="ADDRESS", default="127.0.0.1",
                   help="where to listen (default 127.0.0.1; another address needs --token)")
    p.add_argument("--port", metavar="N", default=0, help="port (default 0: any free port)")
    p.add_argument("--token", metavar="TOKEN", help="access token the page asks every request for")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    import signal
    import threading

    from ipcosim.harness.live.server import check_address
    from ipcosim.harness.live.view import view_server

    port = check_address(args.host, args.port, args.token, option="-")
    server = view_server(args.folder, args.host, port, args.token)
    print(f"ipcosim view: {args.folder} at {server.url} (Ctrl-C ends)", file=sys.stderr, flush=True)
    pause, ended = threading.Event(), []
    # nothing runs that a signal could leave half done: Ctrl-C and SIGTERM simply end the serving. The handler
    # only appends to a list: an Event's set() would take the lock its wait holds for an instant on each wake-up
    # (the handler runs on that same thread: a deadlock)
    previous = {s: signal.signal(s, lambda signum, _: ended.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not ended:
            pause.wait(0.2)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        server.close()
    return 0
