"""The live view's web server: one page (plain HTML, inline script, canvas; nothing fetched from
elsewhere) and the JSON it polls, served from a thread of its own.

Endpoints (every one needs the token when the server has one: ``?token=T`` or the header
``X-Ipcosim-Token``)::

    GET  /                 the page
    GET  /boot.js          the scene and the first samples as a script (the page draws them before its load ends)
    GET  /scene            {"scene": what to draw (ipcosim.harness.live.scene), "names": sampled columns}
    GET  /samples?since=N  {"rows": [[time, values...]], "next": M, "more": bool, "state": ..., "pacing": ...,
                            "rig": ..., "metrics": ..., "message": ..., "info": ...}
    POST /stop             ask the run to stop (needs the header ``X-Ipcosim: stop``)

Access: loopback only unless given a token (:func:`check_address`); a request without the
token gets 403. Without a token the server also refuses a ``Host`` header other than a loopback
name (a web page elsewhere cannot reach it through a rebound DNS name), and ``/stop`` needs a
header no cross-site form can send.
"""
from __future__ import annotations

import hmac
import ipaddress
import json
import math
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any, Protocol
from urllib.parse import parse_qs, quote, urlsplit

from ipcosim.errors import UsageError
from ipcosim.harness.support.paths import distribution_version

#: Most rows one ``/samples`` answer carries (a page catching up takes several).
MAX_ROWS = 5000
#: The page asks for new samples this often [ms] (about 30 updates a second).
POLL_MS = 33
#: How long the page's first request waits for a run to start [s].
BOOT_WAIT_S = 5.0
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


class Source(Protocol):
    """What a page shows: a run as it happens, or a finished one."""

    live: bool

    def scene(self) -> dict[str, Any] | None:
        """``{"scene": ..., "names": [...]}``, or None while the run has not started."""

    def samples(self, since: int) -> dict[str, Any]:
        """The rows from number ``since`` on and the run's status (see the module doc)."""

    def stop(self) -> bool:
        """Ask the run to stop; False when there is nothing to stop."""


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is this machine's loopback."""
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_address(host: str, port: Any, token: str | None, option: str = "--live") -> int:
    """The port as a number, after checking the address: any host other than loopback needs a token.

    Raises
    ------
    UsageError
        Naming the option: a non-loopback host without a token, a bad port, an empty token.
    """
    if token is not None and not str(token).strip():
        raise UsageError(f"{option}-token: empty token")
    if not host or not str(host).strip():
        raise UsageError(f"{option}-host: empty address")
    if not is_loopback(str(host)) and not token:
        raise UsageError(f"{option}-host {host}: an address other than loopback needs an access token "
                         f"({option}-token TOKEN)")
    try:
        number = int(port)
    except (TypeError, ValueError):
        raise UsageError(f"{option}-port {port!r}: expected a port number 0..65535") from None
    if not 0 <= number <= 65535:
        raise UsageError(f"{option}-port {port}: expected a port number 0..65535 (0: any free port)")
    return number


def reachable_address() -> str:
    """This machine's address on its default route (where another host reaches a page served on every
    interface), else its host name."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("192.0.2.1", 9))  # a documentation address: nothing is sent, the route picks the source
            return probe.getsockname()[0]
    except OSError:
        return socket.gethostname()


def page(live: bool, token: str | None = None) -> str:
    """The page, told whether it shows a live run (a stop button, polling until the run ends) and the
    version of the ipcosim serving it (the page names the version that made the run: a finished run's
    ``metrics.json`` says which); its first data come from ``boot.js`` (with the token the page was asked
    for with), loaded before the page counts as loaded."""
    text = resources.files("ipcosim.harness.live").joinpath("page.html").read_text(encoding="utf-8")
    boot = json.dumps({"live": live, "interval_ms": POLL_MS, "version": distribution_version()})
    return (text.replace("/*BOOT*/{}/*END*/", boot)
            .replace("/*BOOTJS*/boot.js", "boot.js" + (f"?token={quote(token)}" if token else "")))


def finite_rows(rows: Any) -> list[list[float | None]]:
    """Rows as JSON-ready lists (NaN and infinities as null; JSON has no such numbers)."""
    return [[v if math.isfinite(v) else None for v in row] for row in rows.tolist()]


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: tuple[str, int], source: Source, token: str | None, html: str | None) -> None:
        self.source, self.token, self.html = source, token, html
        self.viewers = 0          # /samples answers given
        self.served_end = threading.Event()
        super().__init__(address, _Handler)


class _Handler(BaseHTTPRequestHandler):
    server: _HTTPServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 -- the base class's name
        """Quiet: a run's terminal is for the run."""

    def _allowed(self) -> bool:
        token = self.server.token
        if token:
            given = self.headers.get("X-Ipcosim-Token") or parse_qs(urlsplit(self.path).query).get("token", [""])[0]
            if not hmac.compare_digest(given.encode(), token.encode()):
                self._send(403, "text/plain", b"forbidden: this live view needs its token (?token=...)\n")
                return False
            return True
        host = (self.headers.get("Host") or "").rsplit(":", 1)[0].strip("[]")
        if host and not is_loopback(host):
            self._send(403, "text/plain", b"forbidden: a loopback live view answers to loopback names only\n")
            return False
        return True

    def _send(self, code: int, kind: str, body: bytes) -> None:
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, value: Any) -> None:
        self._send(200, "application/json", json.dumps(value, allow_nan=False).encode())

    def do_GET(self) -> None:  # noqa: N802 -- http.server's name
        if not self._allowed():
            return
        url = urlsplit(self.path)
        try:
            if url.path in ("/", "/index.html"):
                html = (self.server.html if self.server.html is not None
                        else page(self.server.source.live, self.server.token))
                self._send(200, "text/html; charset=utf-8", html.encode())
            elif url.path == "/boot.js":
                self._send(200, "text/javascript; charset=utf-8", self._boot().encode())
            elif url.path == "/scene":
                self._json(self.server.source.scene() or {"scene": None})
            elif url.path == "/samples":
                since = int(parse_qs(url.query).get("since", ["0"])[0])
                answer = self.server.source.samples(max(since, 0))
                self.server.viewers += 1
                if answer.get("state") not in ("running", "waiting") and not answer.get("more"):
                    self.server.served_end.set()
                self._json(answer)
            else:
                self._send(404, "text/plain", b"not found\n")
        except ValueError as exc:
            self._send(400, "text/plain", f"bad request: {exc}\n".encode())

    def _boot(self) -> str:
        """``window.BOOT_DATA``: the scene and the first samples (waiting up to :data:`BOOT_WAIT_S` for a
        run to start), so that the page draws before it counts as loaded."""
        source, end = self.server.source, time.monotonic() + BOOT_WAIT_S
        first = source.scene()
        while first is None and source.live and time.monotonic() < end:
            time.sleep(0.05)
            first = source.scene()
        if first is None or first.get("scene") is None:
            return "window.BOOT_DATA = null;\n"
        data = {**first, "samples": source.samples(0)}
        self.server.viewers += 1
        return f"window.BOOT_DATA = {json.dumps(data, allow_nan=False)};\n"

    def do_POST(self) -> None:  # noqa: N802
        if not self._allowed():
            return
        if urlsplit(self.path).path != "/stop":
            self._send(404, "text/plain", b"not found\n")
        elif self.headers.get("X-Ipcosim") != "stop":
            self._send(400, "text/plain", b"a stop needs the header X-Ipcosim: stop\n")
        else:
            self._json({"stopping": self.server.source.stop()})


class LiveServer:
    """The page and its JSON for ``source``, served from a daemon thread until :meth:`close`.

    Parameters
    ----------
    source : Source
        What the page shows.
    host, port : str, int
        Where to listen (port 0: any free port); see :func:`check_address`.
    token : str, optional
        Access token every request must carry.
    html : str, optional
        A page of its own instead of the live page (a sweep's table).
    """

    def __init__(self, source: Source, host: str = "127.0.0.1", port: int = 0, token: str | None = None,
                 html: str | None = None) -> None:
        check_address(host, port, token)
        try:
            self.httpd = _HTTPServer((host, port), source, token, html)
        except OSError as exc:
            raise UsageError(f"live view: cannot listen on {host}:{port} ({exc.strerror or exc})") from None
        self.host, self.port = host, self.httpd.server_address[1]
        self.token = token
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.1},
                                       name="ipcosim-live", daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        """The page's address (with the token when there is one); served on every interface, the machine's
        address that other hosts reach (:func:`reachable_address`)."""
        name = reachable_address() if self.host in ("0.0.0.0", "", "::") else self.host  # noqa: S104 -- a test
        name = f"[{name}]" if ":" in name else name
        return f"http://{name}:{self.port}/" + (f"?token={quote(self.token)}" if self.token else "")

    def close(self, linger: float = 0.0) -> None:
        """Stop serving; with ``linger``, first give a page that is watching that long to fetch the end."""
        if linger > 0 and self.httpd.viewers:
            self.httpd.served_end.wait(linger)
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=5)

