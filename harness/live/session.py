"""A run's live view: its feed (an observer of the run) in the run's process, its page served by a
process of its own.

The page is served from another process, not a thread of the run's: a thread would share the run's
interpreter lock, and a server thread preempted while it holds it stops the paced loop for as long
as the host gives other work (measured: a viewer made 9-18 % of a 1 kHz HIL run's steps late that
way). So the feed writes its rows and its :class:`~ipcosim.harness.live.feed.Board` into shared
memory, and the serving process (``python -m ipcosim.harness.live.session FOLDER``) reads them, asks
the rig for its status and talks to the browsers; the run's process pays one row copy per sample.

:func:`open_live` starts the serving process and prints the page's address; the feed's first tick
publishes the scene and the shared memory (``FOLDER/config.json``); :meth:`LiveSession.finished`
publishes the run's metrics (``FOLDER/metrics.json``) and :meth:`LiveSession.close` lets a watching
page fetch the end, then ends the serving process.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from multiprocessing import shared_memory
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ipcosim.errors import IpcosimError
from ipcosim.harness.live.feed import Board, LiveFeed, SampleRing
from ipcosim.harness.live.server import MAX_ROWS, LiveServer, finite_rows

#: The rig is asked for its status this often [s] while a page watches (asked in the last WATCHED_S).
RIG_POLL_S = 0.2
WATCHED_S = 2.0
#: A page's first answer waits this long for the rig's first status [s].
RIG_FIRST_S = 2.0
#: After the run, a watching page has this long to fetch its end [s].
LINGER_S = 3.0
#: Environment variables that hand the serving process its page token and the rig's token.
TOKEN_VARIABLE, RIG_TOKEN_VARIABLE = "IPCOSIM_LIVE_TOKEN", "IPCOSIM_RIG_TOKEN"


class LiveViewError(IpcosimError, RuntimeError):
    """The live view's serving process did not start (its message says why)."""


class RigPoller:
    """Asks ``rig_status()`` every :data:`RIG_POLL_S` from a thread of its own while a page watches."""

    def __init__(self, rig_status: Callable[[], dict[str, Any]]) -> None:
        self.rig_status = rig_status
        self.last: dict[str, Any] | None = None
        self._asked = 0.0
        self._thread: threading.Thread | None = None
        self._first, self._closed, self._lock = threading.Event(), threading.Event(), threading.Lock()

    def get(self) -> dict[str, Any] | None:
        """The last status (the first one waited for up to :data:`RIG_FIRST_S`)."""
        self._asked = time.monotonic()
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="ipcosim-live-rig", daemon=True)
                self._thread.start()
        self._first.wait(RIG_FIRST_S)
        return self.last

    def _loop(self) -> None:
        while not self._closed.is_set():
            if time.monotonic() - self._asked < WATCHED_S:
                try:
                    self.last = self.rig_status()
                except Exception as exc:  # noqa: BLE001 -- the page says what went wrong, the run goes on
                    self.last = {"error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__}
                self._first.set()
            self._closed.wait(RIG_POLL_S)

    def close(self) -> None:
        self._closed.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        getattr(self.rig_status, "close", lambda: None)()


class SharedSource:
    """The page's :class:`~ipcosim.harness.live.server.Source` in the serving process: the feed's board and
    rows from shared memory, the scene and the metrics from the session's folder."""

    live = True

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.config: dict[str, Any] | None = None
        self.board: Board | None = None
        self.ring: SampleRing | None = None
        self.rig: RigPoller | None = None
        self._shm: Any = None

    def _attach(self) -> bool:
        if self.board is not None:
            return True
        try:
            self.config = json.loads((self.folder / "config.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        self._shm = shared_memory.SharedMemory(self.config["shm"])
        from multiprocessing import resource_tracker  # the run's process owns it: never unlinked from here

        resource_tracker.unregister(self._shm._name, "shared_memory")  # noqa: SLF001 -- its registered name
        buffer = self._shm.buf
        self.board = Board(buffer[:Board.SIZE])
        self.ring = SampleRing(len(self.config["names"]), buffer=buffer[Board.SIZE:], counter=self.board.counter)
        rig = self.config.get("rig")
        if rig:
            from ipcosim.harness.hil.observer import RigMonitor

            self.rig = RigPoller(RigMonitor(rig["card_type"], rig["card_id"], rig["host"], rig["port"],
                                            os.environ.get(RIG_TOKEN_VARIABLE) or None))
        return True

    def scene(self) -> dict[str, Any] | None:
        if not self._attach():
            return None
        assert self.config is not None
        return {"scene": self.config["scene"], "names": self.config["names"]}

    @property
    def closed(self) -> bool:
        """Whether the run's process published the run's end (its metrics), or ended the session."""
        return (self.board is not None and bool(self.board["closed"])) or (self.folder / "closed").exists()

    def samples(self, since: int) -> dict[str, Any]:
        if not self._attach():
            return {"rows": [], "next": 0, "more": True, "state": "waiting", "info": {}}
        assert self.board is not None and self.ring is not None and self.config is not None
        board = self.board
        closed, state = bool(board["closed"]), board.state  # first: after them, every row is in the ring
        rows, nxt, lost = self.ring.read(since, MAX_ROWS)
        info = self.config["info"]
        pacing = ({"steps": board["steps"], "late_steps": board["late_steps"],
                   "overrun_budget": info["overrun_budget"], "tolerance_s": info["tolerance_s"]}
                  if info.get("paced") else None)
        metrics = None
        if closed:
            try:
                metrics = json.loads((self.folder / "metrics.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):
                metrics = None
        return {"rows": finite_rows(rows), "next": nxt, "more": nxt < self.ring.count or not closed, "lost": lost,
                "state": state, "message": board.message, "stop_requested": bool(board["stop"]), "info": info,
                "pacing": pacing, "rig": None if self.rig is None else (self.rig.last if closed else self.rig.get()),
                "metrics": metrics}

    def stop(self) -> bool:
        if not self._attach() or self.board is None or self.board.state not in ("waiting", "running"):
            return False
        self.board["stop"] = 1
        return True

    def close(self) -> None:
        if self.rig is not None:
            self.rig.close()
        self.board = self.ring = None
        if self._shm is not None:
            try:
                self._shm.close()
            except BufferError:  # a page's answer still holds a view: the process ends anyway
                pass


class LiveSession:
    """The feed of one live run and the process serving its page; :meth:`close` after the run."""

    def __init__(self, folder: Path, proc: subprocess.Popen, url: str,
                 make_scene: Callable[[Sequence[str]], dict[str, Any]], rig: dict[str, Any] | None) -> None:
        self.folder, self.proc, self.url = folder, proc, url
        self.make_scene, self.rig = make_scene, rig
        self._shm: Any = None
        self._config: dict[str, Any] | None = None
        self.feed = LiveFeed(allocate=self._allocate)

    def _allocate(self, names: Sequence[str], info: dict[str, Any], nbytes: int) -> tuple[Any, Callable[[], None]]:
        """The shared memory of the feed's board and rows, and the publication of ``config.json`` saying
        where it is (the feed calls it at its first tick)."""
        self._shm = shared_memory.SharedMemory(create=True, size=nbytes)
        np.frombuffer(self._shm.buf, dtype=np.uint8)[:Board.SIZE] = 0
        config = {"shm": self._shm.name, "names": list(names), "info": info, "scene": self.make_scene(names),
                  "rig": self.rig}
        self._config = config
        return self._shm.buf, self.publish

    def publish(self) -> None:
        """Write ``config.json`` (once): from then on the serving process answers with the run's rows."""
        if self._config is None or (self.folder / "config.json").exists():
            return
        tmp = self.folder / "config.json.tmp"
        tmp.write_text(json.dumps(self._config, allow_nan=False), encoding="utf-8")
        tmp.replace(self.folder / "config.json")

    def finished(self, metrics: dict[str, Any] | None) -> None:
        """Publish the run's metrics: the page's last look."""
        self.publish()  # a run that ended before the feed's first tick
        (self.folder / "metrics.json").write_text(json.dumps(metrics, allow_nan=False), encoding="utf-8")
        board = self.feed.board
        if board.state == "running":  # the run ended before its feed could say how (an error at its start)
            board.state = "failed"
        board["closed"] = 1

    def close(self, linger: float = LINGER_S) -> None:
        """Let a watching page fetch the end (up to ``linger`` seconds), then end the serving process."""
        self.feed.board["closed"] = 1
        (self.folder / "closed").touch()
        try:
            self.proc.wait(timeout=linger + 5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        finally:
            self.feed.board = Board()  # off the shared memory before it goes
            self.feed.ring = None
            if self._shm is not None:
                try:
                    self._shm.close()
                except BufferError:
                    pass
                try:
                    self._shm.unlink()
                except FileNotFoundError:
                    pass
            shutil.rmtree(self.folder, ignore_errors=True)


def open_live(make_scene: Callable[[Sequence[str]], dict[str, Any]], *, host: str = "127.0.0.1", port: int = 0,
              token: str | None = None, rig: dict[str, Any] | None = None, rig_token: str | None = None,
              announce: str = "ipcosim run") -> LiveSession:
    """Start the process serving a live view and print the page's address; the returned session's ``feed``
    is the observer the run hands its samples to.

    Parameters
    ----------
    make_scene : callable
        ``make_scene(names) -> dict``.
    host, port, token
        Where to serve and the access token (``--live-host``, ``--live-port``, ``--live-token``).
    rig : dict, optional
        ``card_type``, ``card_id``, ``host``, ``port`` of the virtual rig whose status the page shows
        (:func:`ipcosim.harness.hil.observer.rig_monitor`); ``rig_token`` its access token.
    announce : str
        The prefix of the line printed on stderr with the page's address.

    Raises
    ------
    LiveViewError
        The serving process did not start (its first line of error, e.g. a port in use).
    """
    folder = Path(tempfile.mkdtemp(prefix="ipcosim-live-"))
    env = {k: v for k, v in os.environ.items() if k not in (TOKEN_VARIABLE, RIG_TOKEN_VARIABLE)}
    env.update({TOKEN_VARIABLE: token} if token else {})
    env.update({RIG_TOKEN_VARIABLE: rig_token} if rig_token else {})
    proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.live.session", str(folder), host, str(port),
                             str(os.getpid())], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    line = proc.stdout.readline().strip()
    if not line.startswith("http"):
        proc.wait(timeout=10)
        shutil.rmtree(folder, ignore_errors=True)
        why = proc.stderr.read().strip().splitlines()
        raise LiveViewError(f"live view: {why[-1] if why else 'its server did not start'}")
    print(f"{announce}: live view at {line}", file=sys.stderr, flush=True)
    return LiveSession(folder, proc, line, make_scene, rig)


def serve(folder: Path, host: str, port: int, parent: int, linger: float = LINGER_S) -> None:
    """The serving process: the page of the run whose feed publishes into ``folder``, until the run's end
    is published (and a watching page has fetched it, or ``linger`` seconds passed) or the run's process
    ``parent`` is gone."""
    source = SharedSource(folder)
    server = LiveServer(source, host, port, os.environ.get(TOKEN_VARIABLE) or None)
    print(server.url, flush=True)
    closed_at = None
    try:
        while True:
            time.sleep(0.05)
            if not source.closed and not _alive(parent):
                break
            if source.closed:
                closed_at = closed_at or time.monotonic()
                if not server.httpd.viewers or server.httpd.served_end.is_set() or \
                        time.monotonic() - closed_at > linger:
                    break
    finally:
        server.close()
        source.close()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


if __name__ == "__main__":
    try:
        serve(Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    except IpcosimError as exc:
        print(str(exc), file=sys.stderr)
        sys.exit(1)
