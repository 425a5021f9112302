"""The virtual rig as a service (``ipcosim rig``): serve one from its options, read the access token, and ask a
running one for its status or reset it.

:class:`ServeOptions` holds what ``ipcosim rig serve`` is asked, checks it (each message names the option) and
builds the rig (:meth:`ServeOptions.rig`) and its server (:meth:`ServeOptions.server`); :func:`dedicate` tunes
the interpreter for a process that only serves, and :func:`serve_until_stopped` serves until a signal or the
duration ends. :func:`operate` is the operator's side: ``reset`` and ``status`` as text lines.
"""
from __future__ import annotations

import math
import os
import signal
import sys
from dataclasses import dataclass, field, fields
from typing import Callable, Mapping

from ipcosim.errors import IpcosimError, UsageError, closest
from ipcosim.fmus.hil.protocol import MAX_TOKEN, TOKEN_ENV
from ipcosim.fmus.hil.rig import VirtualRig
from ipcosim.fmus.hil.rig_config import END_STOP_M, RigConfig, experiment_config
from ipcosim.fmus.hil.server import (
    DEFAULT_HOST,
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_IO_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    DEFAULT_PORT,
    RigServer,
)
from ipcosim.fmus.hil.server_log import escape
from ipcosim.fmus.params import PLANT_KINDS
from ipcosim.fmus.physics import state_names

#: Ranges the options of ``ipcosim rig serve`` are held to: (option, attribute, low, high).
RANGES = (("--tick", "tick", 1e-5, 0.01), ("--latency", "latency", 0.0, 1.0),
          ("--noise-counts", "noise_counts", 0.0, 1000.0), ("--duration", "duration", 1e-3, 1e7),
          ("--idle-timeout", "idle_timeout", 0.05, 3600.0), ("--io-timeout", "io_timeout", 0.01, 60.0))


def read_token(token_file: str | None = None, token: str | None = None) -> str | None:
    """The access token from ``token_file``, ``token`` or ``IPCOSIM_RIG_TOKEN`` (in that order), or None.

    Raises
    ------
    UsageError
        The file cannot be read or is empty, or the token is longer than ``MAX_TOKEN`` bytes.
    """
    if token_file:
        try:
            with open(token_file, encoding="utf-8") as fh:
                text = fh.read().strip()
        except (OSError, UnicodeDecodeError) as exc:
            raise UsageError(f"--token-file {token_file}: cannot read it ({exc})") from None
        if not text:
            raise UsageError(f"--token-file {token_file}: the file is empty")
    else:
        text = (token or os.environ.get(TOKEN_ENV, "")).strip()
    if len(text.encode("utf-8")) > MAX_TOKEN:
        raise UsageError(f"access token: longer than {MAX_TOKEN} bytes")
    return text or None


def parse_limit(text: str, option: str, hi: float) -> float | None:
    """A software limit: a finite number in (0, hi], or None for the explicit word 'off'."""
    if text.strip().lower() == "off":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (0 < value <= hi):   # NaN fails too
        raise UsageError(f"{option} {text}: expected a number in (0, {hi:g}] or 'off'")
    return value


class RigModelError(IpcosimError, ValueError):
    """A value the rig's plant model refuses (a negative mass, say): the work cannot be done (exit 1)."""


@dataclass
class ServeOptions:
    """What ``ipcosim rig serve`` is asked (its options by name; ``params`` is ``--set``, ``initial`` is
    ``--initial``, both already numbers; the limits are texts, a number or ``off``)."""

    plant: str = "single-mass"
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    clock: str = "wallclock"
    tick: float | None = None
    preset: str | None = None
    params: Mapping[str, float] = field(default_factory=dict)
    initial: Mapping[str, float] = field(default_factory=dict)
    cart_limit: str | None = None
    pendulum_limit_deg: str | None = None
    experiment: str | None = None
    noise_counts: float = 0.0
    latency: float = 0.0
    seed: int = 0
    duration: float | None = None
    token: str | None = None
    idle_timeout: float = DEFAULT_IDLE_TIMEOUT
    io_timeout: float = DEFAULT_IO_TIMEOUT
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    rt_priority: int | None = None
    cpu: int | None = None
    stall_after_steps: int | None = None

    def checked(self) -> ServeOptions:
        """The options' ranges (``RANGES``, the port, connections, priority, CPU); raises UsageError naming one."""
        if not 0 <= self.port <= 65535:
            raise UsageError(f"--port {self.port}: expected 0..65535")
        for option, name, lo, hi in RANGES:
            value = getattr(self, name)
            if value is not None and not (lo <= value <= hi):   # NaN fails too
                raise UsageError(f"{option} {value}: expected a number in [{lo:g}, {hi:g}]")
        if not 1 <= self.max_connections <= 1024:
            raise UsageError(f"--max-connections {self.max_connections}: expected 1..1024")
        if self.rt_priority is not None and not 1 <= self.rt_priority <= 99:
            raise UsageError(f"--rt-priority {self.rt_priority}: expected 1..99")
        if self.cpu is not None and not 0 <= self.cpu <= 4095:
            raise UsageError(f"--cpu {self.cpu}: expected a CPU number")
        self._check_names()
        return self

    def _check_names(self) -> None:
        """The ``--initial`` states and ``--set`` parameters name the plant's (an unknown name is a usage
        error, exit 2, with the closest names; a value the model refuses is the rig's, exit 1)."""
        if self.plant not in PLANT_KINDS:
            return  # the rig's configuration names the plant kinds (``config``)
        states = state_names(self.plant)
        for key in self.initial:
            if key not in states:
                raise UsageError(f"--initial {key}: the {self.plant} rig has no state {key!r}; {closest(key, states)}")
        names = [f.name for f in fields(PLANT_KINDS[self.plant])]
        for key in self.params:
            if key not in names:
                raise UsageError(f"--set {key}: the {self.plant} plant has no parameter {key!r}; {closest(key, names)}")

    def config(self) -> RigConfig:
        """The rig's configuration: the experiment's set-up (``experiment_config``) under the options given."""
        given: dict = {"initial_state": dict(self.initial)}
        if self.cart_limit is not None:
            given["cart_limit"] = parse_limit(self.cart_limit, "--cart-limit", END_STOP_M)
        if self.pendulum_limit_deg is not None:
            limit = parse_limit(self.pendulum_limit_deg, "--pendulum-limit-deg", 180.0)
            given["pendulum_limit"] = None if limit is None else math.radians(limit)
        try:
            return RigConfig(plant=self.plant, preset=self.preset, params=dict(self.params), clock=self.clock,
                             tick=self.tick, noise_counts=self.noise_counts, latency=self.latency, seed=self.seed,
                             **experiment_config(self.experiment, given)).checked()
        except (ValueError, KeyError) as exc:
            raise UsageError(str(exc).strip("'\"")) from None

    def rig(self) -> VirtualRig:
        """The options checked, then the rig they describe (UsageError naming an option that does not fit;
        RigModelError for a value the plant model refuses, such as a negative mass: exit 1, as ``run``)."""
        self.checked()
        config = self.config()
        try:
            return VirtualRig(config)
        except (ValueError, KeyError) as exc:
            raise RigModelError(str(exc).strip("'\"")) from None

    def server(self, rig: VirtualRig, log: Callable[[str], None]) -> RigServer:
        """The started server of ``rig`` on the options' address (UsageError if it cannot serve there)."""
        try:
            return RigServer(rig, self.host, self.port, stall_after_steps=self.stall_after_steps, log=log,
                             token=self.token, idle_timeout=self.idle_timeout, io_timeout=self.io_timeout,
                             max_connections=self.max_connections).start()
        except ValueError as exc:
            raise UsageError(str(exc)) from None


def dedicate() -> None:
    """Tune the interpreter for a process that only serves a rig: the GIL handed over quickly between its
    threads (the connection's and the housekeeping ones), start-up objects frozen, and no collection pauses
    while a controller steps (the server collects between sessions, ``RigServer._release``)."""
    import gc

    sys.setswitchinterval(1e-4)
    gc.collect()
    gc.freeze()
    gc.disable()


def announcement(server: RigServer) -> str:
    """The line that says where the rig serves and how it is reached."""
    config = server.rig.config
    access = "token required" if server.token else "loopback only, no token"
    return (f"ipcosim rig: serving a {config.plant} rig ({config.clock} clock, tick {config.tick_s * 1e3:g} ms) on "
            f"{server.host}:{server.port} ({access}) -- card id 0@tcpip://{server.host}:{server.port}")


def serve_until_stopped(server: RigServer, duration: float | None, log: Callable[[str], None]) -> None:
    """Serve until SIGTERM/SIGINT or ``duration`` seconds, then close the server (motor at 0 V) and log the
    motor voltage and the counters; the previous signal handlers are restored."""
    previous = {sig: signal.signal(sig, lambda *_: server.request_stop()) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        server.serve(duration)
    finally:
        server.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        counters = ", ".join(f"{escape(k)} {v}" for k, v in sorted(server.counters.items())) or "none"
        log(f"ipcosim rig: stopped; motor at {server.rig.motor_voltage():+.3f} V; counters: {counters}")


def operate(host: str, port: int, action: str, token: str | None = None,
            emit: Callable[[str], None] = print) -> None:
    """The operator's ``reset`` (clear a latched limit trip, re-home) or ``status`` of a running rig: each line
    to show goes to ``emit`` as soon as it is known (what was done, the safety status and, for ``status``,
    every counter)."""
    from ipcosim.fmus.hil.tcpip import TcpipCard

    card = TcpipCard("q4", f"0@tcpip://{host}:{port}", host, port, role="monitor", name="ipcosim rig " + action,
                     token=token or "")
    try:
        if action == "reset":
            card.reset()
            emit(f"rig at {host}:{port}: reset (amplifier enabled, limit latch cleared)")
        st = card.status()
        watchdog = "EXPIRED" if st.watchdog_expired else ("running" if st.watchdog_running else "stopped")
        emit(f"rig at {host}:{port}: time {st.time:.3f} s, amplifier {'on' if st.amplifier_enabled else 'OFF'}, "
             f"watchdog {watchdog}, motor {st.motor_voltage:+.3f} V")
        if st.limit_message:
            emit(f"  {st.limit_message}")
        if action == "status":
            for k, v in sorted(st.counters.items()):
                emit(f"  {k}: {v}")
    finally:
        card.close()
