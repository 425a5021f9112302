"""A run's live view: its feed (an observer of the run), its server and what the page is told.

:func:`open_live` is what ``ipcosim run --live`` and ``ipcosim.run(..., live=True)`` do before the
run: it makes the :class:`~ipcosim.harness.live.feed.LiveFeed` the run observes with, serves the
page (:class:`~ipcosim.harness.live.server.LiveServer`) and prints its address. The rig's own
status comes from ``rig_status``, a poll the caller hands in (the HIL room's
:func:`ipcosim.fmus.hil.observer.rig_monitor`); it is called from the server's thread, never from
the run's, and at most every :data:`RIG_POLL_S`.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Any, Callable, Sequence

from ipcosim.harness.live.feed import LiveFeed
from ipcosim.harness.live.server import MAX_ROWS, LiveServer, finite_rows

#: The rig is asked for its status this often [s] while a page watches (asked in the last WATCHED_S).
RIG_POLL_S = 0.2
WATCHED_S = 2.0
#: A page's first answer waits this long for the rig's first status [s].
RIG_FIRST_S = 2.0
#: After the run, a watching page has this long to fetch its end [s].
LINGER_S = 3.0


class LiveSource:
    """A run as it happens (the :class:`~ipcosim.harness.live.server.Source` of a live run).

    Parameters
    ----------
    feed : LiveFeed
        The run's observer.
    make_scene : callable
        ``make_scene(names) -> dict``: the scene for the sampled columns.
    rig_status : callable, optional
        ``rig_status() -> dict``: the rig's status (``watchdog_running``, ``amplifier_enabled``,
        ``limit_tripped``, ``limit_message``, ``motor_voltage``...; ``error`` when it cannot be read).
    """

    live = True

    def __init__(self, feed: LiveFeed, make_scene: Callable[[Sequence[str]], dict[str, Any]],
                 rig_status: Callable[[], dict[str, Any]] | None = None) -> None:
        self.feed = feed
        self.make_scene = make_scene
        self.rig_status = rig_status
        self.metrics: dict[str, Any] | None = None
        self._scene: dict[str, Any] | None = None
        self._rig: dict[str, Any] | None = None
        self._asked = 0.0
        self._poller: threading.Thread | None = None
        self._first = threading.Event()
        self._closed = threading.Event()
        self._lock = threading.Lock()

    def scene(self) -> dict[str, Any] | None:
        if not self.feed.started.is_set():
            return None
        if self._scene is None:
            self._scene = {"scene": self.make_scene(self.feed.names), "names": list(self.feed.names)}
        return self._scene

    def samples(self, since: int) -> dict[str, Any]:
        feed = self.feed
        state = feed.state  # read first: a terminal state means every row is already in the ring
        if feed.ring is None:
            return {"rows": [], "next": 0, "more": False, "state": state, "info": {}}
        rows, nxt, lost = feed.ring.read(since, MAX_ROWS)
        return {"rows": finite_rows(rows), "next": nxt, "more": nxt < feed.ring.count, "lost": lost, "state": state,
                "message": feed.message, "stop_requested": feed.stop_requested, "info": feed.info,
                "pacing": feed.pacing(), "rig": self._poll_rig(), "metrics": self.metrics}

    def _poll_rig(self) -> dict[str, Any] | None:
        """The rig's last status. A thread of its own asks the rig every :data:`RIG_POLL_S` while a page
        watches (a slow rig never holds up a page's answer); the first answer is waited for up to
        :data:`RIG_FIRST_S`."""
        if self.rig_status is None:
            return None
        self._asked = time.monotonic()
        with self._lock:
            if self._poller is None:
                self._poller = threading.Thread(target=self._poll_loop, name="ipcosim-live-rig", daemon=True)
                self._poller.start()
        self._first.wait(RIG_FIRST_S)
        return self._rig

    def _poll_loop(self) -> None:
        while not self._closed.is_set():
            if time.monotonic() - self._asked < WATCHED_S:
                try:
                    self._rig = self.rig_status()
                except Exception as exc:  # noqa: BLE001 -- the page says what went wrong, the run goes on
                    self._rig = {"error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__}
                self._first.set()
            self._closed.wait(RIG_POLL_S)

    def close(self) -> None:
        """Stop asking the rig."""
        self._closed.set()
        if self._poller is not None:
            self._poller.join(timeout=5)

    def stop(self) -> bool:
        if self.feed.state not in ("waiting", "running"):
            return False
        self.feed.request_stop()
        return True


class LiveSession:
    """The feed and the server of one live run; :meth:`close` after the run."""

    def __init__(self, source: LiveSource, server: LiveServer, close_rig: Callable[[], None] | None) -> None:
        self.source, self.server, self._close_rig = source, server, close_rig
        self.feed = source.feed
        self.url = server.url

    def finished(self, metrics: dict[str, Any] | None) -> None:
        """The run's metrics, for the page's last look."""
        self.source.metrics = metrics

    def close(self, linger: float = LINGER_S) -> None:
        """Let a watching page fetch the end (up to ``linger`` seconds), then stop serving."""
        try:
            self.server.close(linger)
        finally:
            self.source.close()
            if self._close_rig is not None:
                self._close_rig()


def open_live(make_scene: Callable[[Sequence[str]], dict[str, Any]], *, host: str = "127.0.0.1", port: int = 0,
              token: str | None = None, rig_status: Any = None, announce: str = "ipcosim run") -> LiveSession:
    """Serve a live view of the run that will observe with the returned session's ``feed``.

    Parameters
    ----------
    make_scene : callable
        ``make_scene(names) -> dict``.
    host, port, token
        Where to serve and the access token (``--live-host``, ``--live-port``, ``--live-token``).
    rig_status : callable, optional
        The rig's status poll; its ``close()`` (when it has one) is called at the end.
    announce : str
        The prefix of the line printed on stderr with the page's address.
    """
    feed = LiveFeed()
    source = LiveSource(feed, make_scene, rig_status)
    server = LiveServer(source, host, port, token)
    print(f"{announce}: live view at {server.url}", file=sys.stderr, flush=True)
    return LiveSession(source, server, getattr(rig_status, "close", None))
