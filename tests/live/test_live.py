"""The live view: the sample ring the run hands its values through, the page's server (loopback or
a token, offline page, stop), a run stopped from the page, ``ipcosim view`` of a run and of a sweep,
and the page in headless chromium during a real-time run and a HIL run (rig in a second process).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

import numpy as np
import pytest

import ipcosim
from ipcosim.errors import UsageError
from ipcosim.fmus.hil.tcpip import TcpipCard
from ipcosim.harness.live.feed import STOP_MESSAGE, SampleRing
from ipcosim.harness.live.scene import scene
from ipcosim.harness.live.server import LiveServer, page
from ipcosim.harness.live.view import Table, sweep_page, view_server
from ipcosim.harness.master.signals import Interrupted

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: The machine is shared: SCHED_FIFO where permitted, and any overrun fraction within budget (the budget's own
#: warning is tests/master/test_realtime.py's).
RT_ENV = {"IPCOSIM_RT_PRIORITY": "20", "IPCOSIM_RT_OVERRUN_BUDGET": "1"}
NO_CHROMIUM = "chromium is not installed (apt install chromium): the page cannot be looked at"


# ---------------------------------------------------------------------------------------- the ring
def test_the_ring_gives_a_reader_every_row_it_holds_and_counts_what_it_lost() -> None:
    ring = SampleRing(width=2, capacity=8)
    for k in range(5):
        ring.append([k, 10 * k])
    rows, nxt, lost = ring.read(0)
    assert rows[:, 0].tolist() == [0, 1, 2, 3, 4] and rows[:, 1].tolist() == [0, 10, 20, 30, 40]
    assert (nxt, lost) == (5, 0)
    for k in range(5, 20):  # 15 more rows into 8 places: rows 5..11 are overwritten before they are read
        ring.append([k, 10 * k])
    rows, nxt, lost = ring.read(nxt)
    assert rows[:, 0].tolist() == list(range(12, 20)) and (nxt, lost) == (20, 7)
    rows, nxt, lost = ring.read(nxt)
    assert rows.shape == (0, 2) and (nxt, lost) == (20, 0)
    rows, nxt, _ = ring.read(12, limit=3)
    assert rows[:, 0].tolist() == [12, 13, 14] and nxt == 15


def test_a_reader_thread_sees_the_rows_in_order_while_the_writer_appends() -> None:
    ring = SampleRing(width=1, capacity=64)
    seen: list[float] = []
    done = threading.Event()

    def reader() -> None:
        nxt = 0
        while not done.is_set() or nxt < ring.count:
            rows, nxt, _ = ring.read(nxt)
            seen.extend(rows[:, 0].tolist())

    t = threading.Thread(target=reader)
    t.start()
    for k in range(20000):
        ring.append([k])
    done.set()
    t.join(10)
    assert seen and all(b > a for a, b in zip(seen, seen[1:])), "rows out of order or repeated"
    assert seen[-1] == 19999


# ---------------------------------------------------------------------------------------- the scene
def test_the_scene_puts_the_pendulum_on_the_cart_that_carries_it() -> None:
    single = scene(["time", "setpoint.reference", "controller.voltage", "plant.cart_position",
                    "plant.pendulum_angle"], "single-mass-lqr", voltage_limit=6.0)
    assert [c["column"] for c in single["carts"]] == ["plant.cart_position"]
    assert single["pendulum"]["cart"] == "plant.cart_position"
    assert single["limits"]["voltage_V"] == 6.0 and single["limits"]["cart_m"] == 0.30
    assert single["limits"]["pendulum_rad"] == pytest.approx(20 * np.pi / 180)
    double = scene(["time", "plant.active_cart_position", "plant.passive_cart_position", "plant.pendulum_angle",
                    "plant.limit_tripped"], "double-mass-hsmc (plant=hil)")
    assert [c["column"] for c in double["carts"]] == ["plant.active_cart_position", "plant.passive_cart_position"]
    assert double["pendulum"]["cart"] == "plant.passive_cart_position"  # the IP02 double mass: on the passive cart
    assert double["status"] == {"limit_tripped": "plant.limit_tripped"}
    other = scene(["time", "a.x", "b.y"], "my-loop")
    assert other["carts"] == [] and other["pendulum"] is None and other["others"] == ["a.x", "b.y"]


# ---------------------------------------------------------------------------------------- the server
def _get(url: str, headers: dict[str, str] | None = None, data: bytes | None = None) -> tuple[int, bytes]:
    req = urllib.request.Request(url, headers=headers or {}, data=data, method="POST" if data is not None else "GET")
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def test_the_page_fetches_nothing_from_elsewhere() -> None:
    for live in (True, False):
        html = page(live)
        assert "<canvas" in html and "<script>" in html
        assert not re.search(r"https?:|//\w|href\s*=|@import|url\(", html), "the page must work offline"
        assert re.findall(r"src\s*=\s*\"([^\"]*)\"", html) == ["boot.js"]  # its own first data, from its server


def test_an_address_other_than_loopback_needs_a_token() -> None:
    with pytest.raises(UsageError, match=r"--live-host 0\.0\.0\.0: an address other than loopback needs"):
        ipcosim.run("single-mass-lqr", stop_time=0.1, live=True, live_host="0.0.0.0")
    with pytest.raises(UsageError, match="only with --live"):
        ipcosim.run("single-mass-lqr", stop_time=0.1, live_token="T")
    with pytest.raises(UsageError, match="--live-port 70000"):
        ipcosim.run("single-mass-lqr", stop_time=0.1, live=True, live_port=70000)
    run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "run", "single-mass-lqr", "--live",
                          "--live-host", "0.0.0.0"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode != 0 and run.stderr.strip().splitlines() == [
        "ipcosim run: error: --live-host 0.0.0.0: an address other than loopback needs an access token "
        "(--live-token TOKEN)"]


def test_with_a_token_every_request_needs_it_and_a_stop_needs_its_header() -> None:
    server = LiveServer(Table(), "0.0.0.0", 0, token="s3cret")
    try:
        base = f"http://127.0.0.1:{server.port}/"
        assert server.url.endswith("?token=s3cret")
        host = urllib.parse.urlsplit(server.url).hostname
        assert host not in ("127.0.0.1", "0.0.0.0", "localhost"), server.url  # served on every interface: an address
        assert _get(server.url)[0] == 200                                     # of this machine others can reach
        assert _get(base)[0] == 403 and _get(base + "samples?since=0")[0] == 403
        assert _get(base + "?token=wrong")[0] == 403
        status, body = _get(base + "?token=s3cret")
        assert status == 200 and b"<canvas" in body
        assert _get(base + "scene", {"X-Ipcosim-Token": "s3cret"})[0] == 200
        assert _get(base + "stop?token=s3cret", data=b"")[0] == 400  # no X-Ipcosim header: a cross-site form
        status, body = _get(base + "stop?token=s3cret", {"X-Ipcosim": "stop"}, data=b"")
        assert status == 200 and json.loads(body) == {"stopping": False}  # a table has nothing to stop
    finally:
        server.close()


def test_a_loopback_page_answers_to_loopback_names_only() -> None:
    server = LiveServer(Table())
    try:
        base = f"http://127.0.0.1:{server.port}/"
        assert _get(base)[0] == 200
        assert _get(base, {"Host": f"localhost:{server.port}"})[0] == 200
        assert _get(base, {"Host": f"attacker.example:{server.port}"})[0] == 403  # a rebound DNS name
    finally:
        server.close()


def _project_version() -> str:
    """The version pyproject.toml gives the distribution (what ``pip install -e .`` installed)."""
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_the_page_names_the_version_that_made_the_run() -> None:
    boot = re.search(r"const BOOT = (\{.*?\});", page(True))
    assert boot and json.loads(boot.group(1))["version"] == _project_version()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _samples(port: int, since: int = 0) -> dict:
    status, body = _get(f"http://127.0.0.1:{port}/samples?since={since}")
    assert status == 200, body
    return json.loads(body)


def test_the_stop_button_ends_a_real_time_run_with_its_results_written(tmp_path: Path) -> None:
    port, seen = _free_port(), {}

    def press_stop() -> None:
        end = time.monotonic() + 60
        while time.monotonic() < end:
            try:
                s = _samples(port)
            except (OSError, AssertionError):
                time.sleep(0.05)
                continue
            if s["state"] == "running" and s["rows"] and s["rows"][-1][0] >= 0.5:
                seen["t"] = s["rows"][-1][0]
                seen["pacing"] = s["pacing"]
                seen["answer"] = json.loads(_get(f"http://127.0.0.1:{port}/stop", {"X-Ipcosim": "stop"}, b"")[1])
                return
            time.sleep(0.05)

    presser = threading.Thread(target=press_stop, daemon=True)
    presser.start()
    with pytest.raises(Interrupted) as caught:
        ipcosim.run("single-mass-lqr", stop_time=20.0, realtime=True, out=tmp_path, live=True, live_port=port,
                    overrun_budget=1)
    presser.join(5)
    assert seen.get("answer") == {"stopping": True}, seen
    assert caught.value.message == STOP_MESSAGE and caught.value.signum == signal.SIGINT
    t = np.loadtxt(tmp_path / "results.csv", delimiter=",", skiprows=1, usecols=0)
    assert seen["t"] <= t[-1] < 10.0, "the run stopped soon after the button, not at its stop time"
    assert json.loads((tmp_path / "metrics.json").read_text())["realtime_steps"] > 0
    assert seen["pacing"]["overrun_budget"] == 1 and seen["pacing"]["steps"] > 0


# ---------------------------------------------------------------------------------------- ipcosim view
def test_view_shows_a_finished_run_from_its_folder(tmp_path: Path) -> None:
    ipcosim.run("single-mass-lqr", stop_time=1.0, out=tmp_path, set={"controller.voltage_limit": 4.5})
    server = view_server(tmp_path)
    try:
        sc = json.loads(_get(f"http://127.0.0.1:{server.port}/scene")[1])
        assert sc["scene"]["kind"] == "single-mass" and sc["scene"]["pendulum"]["cart"] == "plant.cart_position"
        # the run's own voltage limit, recorded in its folder, not the card's range
        assert sc["scene"]["limits"]["voltage_V"] == 4.5 and sc["scene"]["limits"]["voltage_label"] == "voltage limit"
        s = _samples(server.port)
        rows = np.array(s["rows"], dtype=float)
        assert len(rows) == 1001 and rows[-1, 0] == pytest.approx(1.0)  # 1 s at the scenario's 1 ms step
        assert s["state"] == "finished" and s["more"] is False and s["metrics"]["upright"] is True
        x = rows[:, sc["names"].index("plant.cart_position")]
        assert 0.0 < x.max() < 0.1, "the cart moves toward the 0.05 m step"
    finally:
        server.close()


def _installed_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("ipcosim")
    except metadata.PackageNotFoundError:
        return "dev"


def test_view_shows_a_sweep_folder_as_its_table(tmp_path: Path) -> None:
    (tmp_path / "results.csv").write_text("run,plant.Mp,upright,settling_time_s\n0,0.10,True,2.1\n"
                                          "1,0.12,True,2.4\n2,<b>0.14</b>,False,\n")
    (tmp_path / "metadata.json").write_text("{}")
    server = view_server(tmp_path)
    try:
        status, body = _get(f"http://127.0.0.1:{server.port}/")
        html = body.decode()
        assert status == 200 and "3 runs" in html
        assert html.count("<tr>") == 4 and "<th>plant.Mp</th>" in html
        assert "&lt;b&gt;0.14&lt;/b&gt;" in html and "<b>0.14" not in html
        shown = f"shown by ipcosim {_installed_version()}"
        assert f'<p id="made">run by ipcosim (not recorded); {shown}</p>' in html
    finally:
        server.close()
    (tmp_path / "metadata.json").write_text(json.dumps({"scenario": "single-mass-lqr", "runs": 3,
                                                        "started": "2026-12-04T10:00:00+0000",
                                                        "packages": {"ipcosim": "0.9.1", "numpy": "2.1.0"}}))
    assert ('<p id="made">scenario single-mass-lqr, started 2026-12-04T10:00:00+0000; run by ipcosim 0.9.1; '
            f"{shown}</p>") in sweep_page(tmp_path)
    (tmp_path / "metadata.json").write_text("[1, 2")
    assert f'<p id="made">metadata.json not readable (JSONDecodeError): what made these runs is unknown; {shown}' \
        in sweep_page(tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ipcosim.IpcosimError, match="no results.csv"):
        view_server(tmp_path / "empty")
    run = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "view", str(tmp_path / "missing")],
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode == 1 and run.stderr.strip().splitlines() == [
        f"ipcosim view: error: {tmp_path / 'missing'}: not a folder (expected a run's or a sweep's output folder)"]


# ---------------------------------------------------------------------------------------- in chromium
class LiveRun:
    """``ipcosim run ... --live`` in its own process; its page's address from its first stderr line."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "run", *args, "--live", "--quiet"],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                                     env=env or dict(os.environ, **RT_ENV))
        line = self.proc.stderr.readline()
        match = re.search(r"live view at (http://\S+)", line)
        assert match, line + self.proc.stderr.read()
        self.url = match.group(1)
        self.port = int(self.url.rsplit(":", 1)[1].strip("/"))

    def wait_running(self, after: float) -> None:
        end = time.monotonic() + 60
        while time.monotonic() < end:
            s = _samples(self.port)
            if s["rows"] and s["rows"][-1][0] >= after:
                return
            time.sleep(0.1)
        raise AssertionError(f"the run did not reach t = {after} s")

    def stop(self) -> tuple[int, str]:
        if self.proc.poll() is None:
            try:
                _get(self.url + "stop", {"X-Ipcosim": "stop"}, b"")
            except OSError:
                pass
        try:
            _, err = self.proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return self.proc.returncode, err


def chromium(url: str, *, shot: Path | None = None, dom: bool = False, wait_ms: int = 8000) -> str:
    """Load the page in headless chromium (it counts as loaded once its first samples are drawn; at most
    ``wait_ms`` on a loaded host); write a screenshot to ``shot`` or return the DOM."""
    args = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--window-size=1200,900",
            f"--timeout={wait_ms}"]
    args += [f"--screenshot={shot}"] if shot else ["--dump-dom"]
    run = subprocess.run(args + [url], capture_output=True, text=True, timeout=120)
    if shot:
        assert shot.is_file(), run.stderr[-2000:]
    return run.stdout


def _pixels(shot: Path) -> np.ndarray:
    import matplotlib.image

    return matplotlib.image.imread(shot)[..., :3]


#: The plots' area of a 1200 x 900 page (left column, below the animation) and the traces' colours.
PLOTS = (slice(280, 880), slice(90, 870))
TRACES = {"cart": (0x1F, 0x77, 0xB4), "angle": (0x94, 0x67, 0xBD), "voltage": (0x8C, 0x56, 0x4B)}


def _trace_pixels(img: np.ndarray) -> dict[str, int]:
    area = img[PLOTS]
    return {k: int(np.all(np.abs(area - np.array(c) / 255) < 0.06, axis=-1).sum()) for k, c in TRACES.items()}


@pytest.mark.integration
@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
def test_the_live_page_draws_a_real_time_run_and_its_traces_move(tmp_path: Path) -> None:
    run = LiveRun(["single-mass-lqr", "--realtime", "--stop-time", "30", "--out", str(tmp_path / "out")])
    try:
        run.wait_running(0.5)
        chromium(run.url, shot=tmp_path / "first.png")
        time.sleep(1.5)
        chromium(run.url, shot=tmp_path / "second.png")
    finally:
        status, err = run.stop()
    first, second = _pixels(tmp_path / "first.png"), _pixels(tmp_path / "second.png")
    drawn = _trace_pixels(first), _trace_pixels(second)
    for counts in drawn:
        assert all(n > 30 for n in counts.values()), f"a trace is not drawn: {drawn}"
    assert drawn[1]["cart"] > drawn[0]["cart"], f"the traces did not grow with the run: {drawn}"
    changed = np.any(np.abs(first[PLOTS] - second[PLOTS]) > 0.1, axis=-1).sum()
    assert changed > 500, f"only {changed} pixels of the plots changed between the two screenshots"
    assert status == 128 + signal.SIGINT and STOP_MESSAGE in err, err  # the page's stop, as Ctrl-C
    assert (tmp_path / "out" / "metrics.json").is_file() and (tmp_path / "out" / "results.csv").is_file()


@pytest.mark.integration
@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
def test_the_view_of_a_run_names_the_version_that_made_it(tmp_path: Path) -> None:
    ipcosim.run("single-mass-lqr", stop_time=0.2, out=tmp_path)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["ipcosim_version"] == _project_version()
    server = view_server(tmp_path)
    try:
        dom = chromium(server.url, dom=True)
    finally:
        server.close()
    assert f'<span id="version">ipcosim {_project_version()}</span>' in dom
    (tmp_path / "metrics.json").write_text(json.dumps({**metrics, "ipcosim_version": "0.0.1"}))  # an older run's
    server = view_server(tmp_path)
    try:
        dom = chromium(server.url, dom=True)
    finally:
        server.close()
    assert f'<span id="version">ipcosim 0.0.1 (shown by ipcosim {_project_version()})</span>' in dom


@pytest.mark.integration
@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
def test_the_live_page_of_a_hil_run_shows_the_rigs_status(tmp_path: Path) -> None:
    # limits off and a generous watchdog: on a loaded shared host the pendulum may fall through the pacing,
    # and this test is about what the page shows of a rig that is running, not about the balance
    rig = subprocess.Popen([sys.executable, "-m", "ipcosim.harness.cli", "rig", "serve", "--port", "0",
                            "--duration", "120", "--pendulum-limit-deg", "off", "--cart-limit", "off",
                            "--rt-priority", RT_ENV["IPCOSIM_RT_PRIORITY"]],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        line = rig.stdout.readline()
        assert "card id" in line, line + rig.stderr.read()
        uri = "q4:" + line.rsplit("card id", 1)[1].strip()
        run = LiveRun(["single-mass-lqr", "--swap", "plant=hil", "--set", "plant.watchdog_timeout=2",
                       "--stop-time", "30", "--out", str(tmp_path / "out")],
                      env=dict(os.environ, IPCOSIM_HIL_URI=uri, **RT_ENV))
        try:
            run.wait_running(0.5)
            dom = chromium(run.url, dom=True)
            s = _samples(run.port)
        finally:
            status, err = run.stop()
        monitor = TcpipCard("q4", uri.split(":", 1)[1], "127.0.0.1", int(uri.rsplit(":", 1)[1]), role="monitor")
        after = monitor.status()
        monitor.close()
    finally:
        rig.send_signal(signal.SIGTERM)
        rig.communicate(timeout=30)
    rows = {m.group(1): m.group(2) for m in re.finditer(r"<tr><td>([^<]*)</td><td[^>]*>([^<]*)</td></tr>", dom)}
    assert f'<span id="version">ipcosim {_project_version()}</span>' in dom
    assert rows.get("watchdog") == "armed" and rows.get("amplifier") == "enabled", (sorted(rows.items()), s.get("rig"))
    assert rows.get("limits") == "not tripped"
    assert "late steps" in rows and "overrun budget" in rows
    assert s["rig"]["watchdog_running"] is True
    assert status == 128 + signal.SIGINT and STOP_MESSAGE in err, err
    assert after.motor_voltage == 0.0 and not after.watchdog_running  # the stopped run left the motor at 0 V
