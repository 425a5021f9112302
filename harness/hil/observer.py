"""What a run learns from its cards: the observer the run engine adds when a component drives a
card (a HIL adapter, recognised by its ``limit_tripped`` and ``last_error`` outputs).

A run's failure that comes from a card (a limit trip, a watchdog expiry, a rig that stopped
answering or went away) is recorded in metrics.json as ``rig_fault`` (the message) with
``upright`` false, whatever the last recorded sample says: the step that tripped is never
recorded. In a paced run it also records ``card_overruns``: the sum of the ``overruns``
outputs of the components that have one (steps whose request reached the card after their
sample instant), read after the last step, and what the adapter costs a step, from its
locals: ``adapter_step_mean_us`` and ``adapter_step_p99_us`` (from its ``doStep``'s call to
its return, less the wait for the sample instant, in microseconds) and
``card_round_trips_per_step`` (requests to the card per step, for a card that counts them).

:class:`CardObserver` is a master observer
(:class:`ipcosim.harness.master.observers.Observer`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ipcosim.harness.master.observers import Observer

if TYPE_CHECKING:
    from ipcosim.harness.master.execution import Execution


class CardObserver(Observer):
    """Records a card's fault (``rig_fault``, ``upright: false``) and, with ``overruns``, the
    cards' ``card_overruns`` after the last step."""

    def __init__(self, overruns: bool = False) -> None:
        self.overruns = overruns
        self.fault: str | None = None
        self._last_tick: int | None = None
        self._card_overruns: int | None = None
        self._adapter: dict[str, float] = {}

    def start(self, execution: Execution) -> None:
        """Note the run's last tick (the overruns are read there)."""
        self._last_tick = execution.n_ticks if self.overruns else None

    def next_tick(self, n: int) -> int | None:
        """Only the last tick, and only when counting overruns."""
        return self._last_tick if self._last_tick is not None and n < self._last_tick else None

    def step(self, execution: Execution, n: int) -> None:
        """After the last step: the sum of the ``overruns`` outputs."""
        total = None
        for inst, slave in zip(execution.instances, execution.slaves):
            var = inst.model.variables.get("overruns")
            if var is None or var.causality != "output":
                continue
            try:
                total = (total or 0) + int(slave.get_values([var])[0])
            except Exception:  # noqa: BLE001 -- statistics must not fail a run
                pass
            self._adapter = adapter_costs(inst, slave)
        self._card_overruns = total

    def finish(self, execution: Execution, error: BaseException | None) -> None:
        """Keep the failure's message if it came from a card."""
        self.fault = card_fault(execution, error)

    def metrics(self) -> dict[str, Any]:
        """``card_overruns`` (when read) and, after a card's fault, ``upright`` and ``rig_fault``."""
        out: dict[str, Any] = {}
        if self._card_overruns is not None:
            out["card_overruns"] = self._card_overruns
        out.update(self._adapter)
        if self.fault is not None:
            out["upright"] = False
            out["rig_fault"] = self.fault
        return out


#: The adapter's locals of what it costs a step -> (metrics.json key, scale).
ADAPTER_COSTS = {"step_time_mean": ("adapter_step_mean_us", 1e6), "step_time_p99": ("adapter_step_p99_us", 1e6),
                 "round_trips_per_step": ("card_round_trips_per_step", 1.0)}


def adapter_costs(inst: Any, slave: Any) -> dict[str, float]:
    """What a card-driving component (a HIL adapter) says it costs a step: the metrics of
    ``ADAPTER_COSTS`` that it has (none when it has not, or cannot be asked)."""
    out = {}
    for name, (key, scale) in ADAPTER_COSTS.items():
        var = inst.model.variables.get(name)
        if var is None:
            continue
        try:
            out[key] = round(float(slave.get_values([var])[0]) * scale, 3)
        except Exception:  # noqa: BLE001 -- statistics must not fail a run
            pass
    return out


def card_fault(execution: Execution, error: BaseException | None) -> str | None:
    """The message of a run's failure if it came from a component driving a card (a HIL adapter), else None.

    An adapter is recognised by its ``limit_tripped`` and ``last_error`` outputs.
    """
    if error is None:
        return None
    text = str(error).strip()
    first = text.splitlines()[0] if text else type(error).__name__
    for inst in execution.instances:
        names = inst.model.variables
        if "limit_tripped" in names and "last_error" in names and f"component {inst.name} " in first:
            return first
    return None


class RigMonitor:
    """The status of the virtual rig a run drives, asked over a monitor session of its own (the
    session ``ipcosim rig status`` opens): for a live view, from the view's thread, never the run's.

    Calling it returns ``watchdog_running``, ``watchdog_expired``, ``amplifier_enabled``,
    ``limit_tripped``, ``limit_message``, ``motor_voltage`` [V] and ``time`` (the rig's clock [s]);
    a failed question closes the session (the next call opens another) and raises HILError.
    """

    def __init__(self, card_type: str, card_id: str, host: str, port: int, token: str | None) -> None:
        self.card_type, self.card_id, self.host, self.port, self.token = card_type, card_id, host, port, token
        self._card: Any = None

    def __call__(self) -> dict[str, Any]:
        from ipcosim.fmus.hil.api import HILError
        from ipcosim.fmus.hil.tcpip import TcpipCard

        try:
            if self._card is None:
                self._card = TcpipCard(self.card_type, self.card_id, self.host, self.port, role="monitor",
                                       name="ipcosim live view", token=self.token or "", timeout=2.0)
            st = self._card.status()
        except HILError:
            self.close()
            raise
        return {"watchdog_running": st.watchdog_running, "watchdog_expired": st.watchdog_expired,
                "amplifier_enabled": st.amplifier_enabled, "limit_tripped": st.limit_tripped,
                "limit_message": st.limit_message, "motor_voltage": st.motor_voltage, "time": st.time}

    def close(self) -> None:
        """End the monitor session (idempotent)."""
        card, self._card = self._card, None
        if card is not None:
            try:
                card.close()
            except Exception:  # noqa: BLE001 -- a monitor's goodbye must not fail anything
                pass


def rig_monitor(instances: Any, start: Any) -> RigMonitor | None:
    """A :class:`RigMonitor` of the virtual rig (``N@tcpip://HOST:PORT``) the run's first card-driving
    component (a HIL adapter: ``limit_tripped``, ``last_error``, ``card_uri``) is given, or None (no
    adapter, a real card, an in-process rig).

    Parameters
    ----------
    instances : iterable
        The run's component instances (``name``, ``model.variables``).
    start : callable
        ``start(component, variable)``: the value the run gives a parameter.
    """
    import os
    import urllib.parse

    from ipcosim.fmus.hil import HILError, parse_card_uri
    from ipcosim.fmus.hil.protocol import TOKEN_ENV

    for inst in instances:
        names = inst.model.variables
        if not all(n in names for n in ("limit_tripped", "last_error", "card_uri")):
            continue
        try:
            card_type, card_id = parse_card_uri(str(start(inst.name, "card_uri") or ""))
        except HILError:
            return None
        _, _, rest = card_id.partition("@")
        if not rest.startswith("tcpip://"):
            return None
        where = urllib.parse.urlsplit(f"tcp://{rest[len('tcpip://'):]}")
        try:
            port = where.port
        except ValueError:
            return None
        if not where.hostname or port is None:
            return None
        token = str(start(inst.name, "card_token") or "") or os.environ.get(TOKEN_ENV) or None
        return RigMonitor(card_type, card_id, where.hostname, port, token)
    return None
