"""FMI face of the hardware-in-the-loop adapter, shared by ``fmu_ip02_hil_single_mass.py`` and
``fmu_ip02_hil_double_mass.py``.

The adapter stands in for a plant FMU: the same input ``voltage`` [V] and the same
encoder-measured outputs (``ipcosim.fmus.physics.MEASURED``: ``cart_position``,
``pendulum_angle``; or ``active_cart_position``, ``passive_cart_position``,
``pendulum_angle``), so a scenario swaps simulation for hardware by swapping one
component. It drives a data-acquisition card through :mod:`ipcosim.fmus.hil` (a real Q4 with
Quanser's package, or the virtual rig), at volts-and-counts level:

* **start** (leaving initialization): open the card (``card_uri``; ``card_token`` or the
  ``IPCOSIM_RIG_TOKEN`` environment variable for a rig served beyond loopback), refuse a rig
  whose amplifier is latched off by a limit trip or that another client controls, write 0 V,
  set the watchdog's expiration state to 0 V, zero the encoders. The outputs start at 0
  (positions relative to the start, as on the lab rig). A virtual rig over TCP leases its
  session to a client that keeps talking, so that connection is closed again here and
  re-opened (and checked again) by the first step.
* **first step**: start the watchdog (``watchdog_timeout``). Arming it only when stepping
  begins means that however long the other components take to initialize, the watchdog
  cannot expire before the first step, and the card's sample instants are anchored there.
* **every step** ``doStep(t, h)``: reload the watchdog, write ``voltage`` (clipped to
  ``+-voltage_limit``, divided by ``amplifier_gain``) to the analog output, let the card's
  clock run to the sample instant ``t + h`` and read the encoders there (one
  ``Card.step``; on a ``lockstep`` virtual rig this advances the rig by exactly ``h``),
  and convert counts to SI units with the calibrations (a negative calibration reverses a
  direction). Counter wrap-around is unwrapped. A virtual rig answers with the sample instant's
  reading at once; the step returns then, and the next one waits for that instant before it
  sends, if it comes earlier (a host pacing to the wall clock never waits twice for an instant;
  see :meth:`HilFmu._sample_base` for where the instants sit).
* **faults** (a limit trip, a watchdog expiry, a card error, a rig that does not answer
  within ``watchdog_timeout`` of the sample instant -- 5 s for a lockstep virtual rig,
  whose simulated time a stalled host cannot hurt): the message goes to ``last_error`` and to the FMI log, the
  adapter writes 0 V (best effort) and closes the card, and the step fails (fmi2Discard):
  the master stops with that message.
* **terminate, free**: write 0 V, stop the watchdog, close the card.

Status outputs: ``watchdog_expired``, ``limit_tripped`` (Boolean), ``overruns`` (Integer:
steps whose request reached a real-time card after their sample instant), ``last_error``
(String, empty when all is well). What the adapter itself costs a step, as locals (from the
second step on, the start-up step left out): ``step_time_mean`` and ``step_time_p99`` [s] (from
``doStep``'s call to its return, less the wait for the sample instant) and
``round_trips_per_step`` (requests to a card that counts them, e.g. the virtual rig over TCP).
"""
from __future__ import annotations

import math
import time
import weakref
from typing import Any

from ipcosim.fmus.fmi import FmuBase, FmuError, StepFailure
from ipcosim.fmus.physics import MEASURED, STATE_UNITS

#: Default card: the virtual rig of ``ipcosim rig serve`` on its default address.
DEFAULT_CARD_URI = "q4:0@tcpip://127.0.0.1:18920"
CART_M_PER_COUNT = 2.275e-5            # IP02 cart encoder: 4096 counts/rev (the thesis, sec. 3.3)
PENDULUM_RAD_PER_COUNT = 1.534e-3      # pendulum encoder, 2 pi / 4096 rad, counter-clockwise positive
#: How far ahead of the first paced step a real-time card's sample instants are put [periods]: room for the
#: clock's reckoning over TCP (a few tens of microseconds) without aging every reading by much.
ANCHOR_LEAD = 0.05
#: How long to wait for a lockstep virtual rig's answer [s] (a real-time card: watchdog_timeout).
LOCKSTEP_REPLY_TIMEOUT = 5.0

_DOC = {"cart_position": "cart position from its encoder (relative to the start)",
        "active_cart_position": "active (motor) cart position from its encoder (relative to the start)",
        "passive_cart_position": "passive cart position from its encoder (relative to the start)",
        "pendulum_angle": "pendulum angle from its encoder, counter-clockwise positive (relative to the start)"}

#: per measured output: (channel parameter, default channel, calibration parameter, default calibration, unit)
_CHANNELS = {"cart_position": ("cart_encoder_channel", 0, "cart_calibration", CART_M_PER_COUNT, "m"),
             "active_cart_position": ("cart_encoder_channel", 0, "cart_calibration", CART_M_PER_COUNT, "m"),
             "pendulum_angle": ("pendulum_encoder_channel", 1, "pendulum_calibration", PENDULUM_RAD_PER_COUNT,
                                "rad"),
             "passive_cart_position": ("passive_cart_encoder_channel", 2, "passive_cart_calibration",
                                       CART_M_PER_COUNT, "m")}


def _valid_uri(value: str) -> str | None:
    from ipcosim.fmus.hil import HILError, parse_card_uri
    try:
        parse_card_uri(value)
    except HILError as exc:
        return exc.message
    return None


def _channel(value: int) -> str | None:
    return None if 0 <= value < 64 else "must be a channel number 0..63"


def _nonzero(value: float) -> str | None:
    return None if value != 0 else "must be non-zero (counts to SI units; negative reverses the direction)"


def _close_quietly(holder: dict[str, Any]) -> None:
    """0 V, watchdog stopped, card closed; never raises (used on free and after faults)."""
    card = holder.pop("card", None)
    if card is None:
        return
    try:
        if hasattr(card, "timeout"):
            card.timeout = min(card.timeout, 0.2)
        card.write_analog([holder["ao"]], [0.0])
    except Exception:  # noqa: BLE001 -- best effort: a dead card/connection is already safe
        pass
    try:
        card.watchdog_stop()
    except Exception:  # noqa: BLE001
        pass
    try:
        card.close()
    except Exception:  # noqa: BLE001
        pass


class HilFmu(FmuBase):
    """HIL adapter: the plant's connectors on a data-acquisition card (see the module docstring)."""

    #: 'single-mass' or 'double-mass' (set by the FMU classes).
    kind: str = ""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._outputs = list(MEASURED[self.kind])
        self._pos = [0.0] * len(self._outputs)
        self.add_input("voltage", start=0.0, unit="V",
                       description="amplifier command to the motor (written to the card's analog output)")
        for k, name in enumerate(self._outputs):
            self.add_output(name, unit=STATE_UNITS[name], description=_DOC[name], getter=(lambda k=k: self._pos[k]),
                            depends_on=(), initial_depends_on=())
        self.add_output("watchdog_expired", start=False, type_=bool, depends_on=(), initial_depends_on=(),
                        description="the card's watchdog expired (outputs forced to 0 V)")
        self.add_output("limit_tripped", start=False, type_=bool, depends_on=(), initial_depends_on=(),
                        description="a safety limit latched the amplifier off")
        self.add_output("overruns", start=0, type_=int, depends_on=(), initial_depends_on=(),
                        description="steps whose request reached the card after their sample instant")
        self.add_output("last_error", start="", type_=str, depends_on=(), initial_depends_on=(),
                        description="the fault that stopped the adapter (empty when all is well)")
        self._declare_costs()
        self.add_parameter("card_uri", start=DEFAULT_CARD_URI, type_=str, check=_valid_uri,
                           description="card as [TYPE:]ID: q4:0 (Quanser package), "
                                       "q4:0@tcpip://HOST:PORT (virtual rig), q4:0@inproc://NAME")
        self.add_parameter("card_token", start="", type_=str,
                           description="shared access token of a virtual rig served beyond loopback "
                                       "(empty: the IPCOSIM_RIG_TOKEN environment variable)")
        self.add_parameter("analog_channel", start=0, type_=int, check=_channel,
                           description="analog output channel driving the amplifier")
        seen = set()
        for name in self._outputs:
            ch_param, ch_default, cal_param, cal_default, unit = _CHANNELS[name]
            if ch_param in seen:
                continue
            seen.add(ch_param)
            self.add_parameter(ch_param, start=ch_default, type_=int, check=_channel,
                               description=f"encoder channel of {name}")
            self.add_parameter(cal_param, start=cal_default, unit=f"{unit}", check=_nonzero,
                               description=f"{name} per encoder count [{unit}/count]")
        self.add_parameter("amplifier_gain", start=1.0, unit="1", check=lambda v: None if v > 0 else "must be > 0",
                           description="power amplifier gain: motor volts per DAC volt")
        self.add_parameter("voltage_limit", start=10.0, unit="V",
                           check=lambda v: None if 0 < v <= 10.0 else "must be in (0, 10] V (the DAC range)",
                           description="the command is clipped to +-voltage_limit before the DAC")
        self.add_parameter("watchdog_timeout", start=0.1, unit="s",
                           check=lambda v: None if 0 < v <= 10.0 else "must be in (0, 10] s",
                           description="card watchdog timeout; also how long to wait for a rig's answer")
        self.watchdog_expired = False
        self.limit_tripped = False
        self.overruns = 0
        self.last_error = ""
        self._holder: dict[str, Any] = {}
        self._finalizer = weakref.finalize(self, _close_quietly, self._holder)
        self._base_ns: int | None = None
        self._paced_base = False
        self._armed = False
        self._raw: list[int] = []
        self._unwrapped: list[int] = []
        self._times_ns: list[int] = []
        self._requests = [0, 0]      # the card's request count after the first step, and now

    def _declare_costs(self) -> None:
        """The locals that say what the adapter costs a step (see the module docstring)."""
        self.add_local("step_time_mean", unit="s", getter=lambda: self._step_time(0.0),
                       description="time the adapter takes a step, less the wait for the sample instant: mean")
        self.add_local("step_time_p99", unit="s", getter=lambda: self._step_time(0.99),
                       description="time the adapter takes a step, less the wait for the sample instant: p99")
        self.add_local("round_trips_per_step", unit="1", getter=self._round_trips,
                       description="requests to the card per step (a card that counts them; else 0)")

    # --- lifecycle ---------------------------------------------------------------------------------

    def setup(self) -> None:
        """Leaving initialization: open the card and check it (the watchdog is armed by the first step)."""
        self._enc = [int(getattr(self, _CHANNELS[n][0])) for n in self._outputs]
        self._cal = [float(getattr(self, _CHANNELS[n][2])) for n in self._outputs]
        if len(set(self._enc)) != len(self._enc):
            raise FmuError(f"parameter encoder channels {self._enc}: each measured output needs its own channel")
        card = self._open_checked()
        if getattr(card, "leased", False):
            # A rig that leases its session drops a silent client; the other components' initialization
            # may take seconds, so the connection is opened again by the first step.
            _close_quietly(self._holder)
        self._armed = False
        self._times_ns = []
        self._unwrapped = [0] * len(self._enc)
        self._pos = [0.0] * len(self._enc)
        self._base_ns = None
        self._paced_base = False

    def _open_checked(self) -> Any:
        """Open the card, check it (plant kind, amplifier not latched off), 0 V, expiration state, encoders 0."""
        from ipcosim.fmus.hil import HILError, open_uri

        where = f"card {self.card_uri}"
        try:
            card = open_uri(self.card_uri, timeout=self.watchdog_timeout, plant=self.kind,
                            name=f"{self.modelName} {self.instance_name}", token=self.card_token or None)
        except HILError as exc:
            raise FmuError(f"{where}: {exc.message}") from None
        self._holder.update(card=card, ao=int(self.analog_channel))
        if getattr(card.info, "clock", "") == "lockstep" and hasattr(card, "timeout"):
            # simulated time: a host that stalls harms nothing, so wait longer for an answer
            card.timeout = max(self.watchdog_timeout, LOCKSTEP_REPLY_TIMEOUT)
        try:
            rig_kind = getattr(card.info, "plant", "")
            if rig_kind and rig_kind != self.kind:
                raise FmuError(f"{where} is a {rig_kind} rig, but {self.modelName} is the {self.kind} adapter")
            status = card.status()
            if status.limit_tripped:
                raise FmuError(f"{where}: {status.limit_message or 'a safety limit latched the amplifier off'}; "
                               f"reset the rig first (ipcosim rig reset)")
            ao = int(self.analog_channel)
            card.write_analog([ao], [0.0])
            card.watchdog_set_analog_expiration_state([ao], [0.0])
            card.set_encoder_counts(self._enc, [0] * len(self._enc))
        except HILError as exc:
            _close_quietly(self._holder)
            raise FmuError(f"{where}: {exc.message}") from None
        except FmuError:
            _close_quietly(self._holder)
            raise
        return card

    def _arm(self) -> Any:
        """The first step: (re)open the card if needed and start its watchdog -- stepping begins now."""
        from ipcosim.fmus.hil import HILError

        try:
            card = self._holder.get("card") or self._open_checked()
            if hasattr(card, "defer_wait"):   # the next doStep waits for this one's sample instant
                card.defer_wait = True
            card.watchdog_start(self.watchdog_timeout)
            self._raw = [int(c) for c in card.read_encoder(self._enc)]
        except FmuError as exc:
            self._fault(str(exc))
        except HILError as exc:
            self._fault(f"card {self.card_uri}: {exc.message}")
        self._armed = True
        return card

    def _step_time(self, quantile: float) -> float:
        """The mean (``quantile`` 0) or a quantile of the steps' own times [s]."""
        times = self._times_ns
        if not times:
            return 0.0
        if not quantile:
            return sum(times) / len(times) / 1e9
        ordered = sorted(times)
        return ordered[min(len(ordered) - 1, math.ceil(quantile * len(ordered)) - 1)] / 1e9

    def _round_trips(self) -> float:
        steps = len(self._times_ns)
        return (self._requests[1] - self._requests[0]) / steps if steps else 0.0

    def step(self, t: float, h: float) -> None:
        began = time.monotonic_ns()
        first = not self._armed
        self._card_step(t, h, began)
        card = self._holder.get("card")
        requests = getattr(card, "requests", 0)
        if first:
            self._requests[0] = self._requests[1] = requests
        else:
            self._times_ns.append(time.monotonic_ns() - began - getattr(card, "last_wait_ns", 0))
            self._requests[1] = requests

    def _card_step(self, t: float, h: float, began_ns: int) -> None:
        from ipcosim.fmus.hil import ErrorCode, HILError, count_difference

        card = self._arm() if not self._armed else self._holder.get("card")
        if card is None:
            raise StepFailure(f"the card is closed after an earlier fault: {self.last_error or 'unknown'}")
        v = float(self.voltage)
        if not math.isfinite(v):
            self._fault(f"input voltage = {v} at t = {t:.6g} s is not finite")
        v = max(-self.voltage_limit, min(self.voltage_limit, v)) / self.amplifier_gain
        try:
            base = self._sample_base(card, t, h, began_ns)
            self._base_ns = self._base_ns if base is None else base
            until = (self._base_ns + int(round((t + h) * 1e9))) / 1e9
            res = card.step([int(self.analog_channel)], [v], self._enc, until, reload=True)
        except HILError as exc:
            if exc.code == ErrorCode.WATCHDOG_EXPIRED:
                self.watchdog_expired = True
            self._fault(exc.message)
        if res.late > 0:
            self.overruns += 1
        for k, raw in enumerate(res.counts):
            raw = int(raw)
            self._unwrapped[k] += count_difference(raw, self._raw[k])
            self._raw[k] = raw
            self._pos[k] = self._unwrapped[k] * self._cal[k]
        st = res.status
        if not res.reloaded or (st is not None and st.watchdog_expired):
            self.watchdog_expired = True
            self._fault(f"the card's watchdog expired (no reload within {self.watchdog_timeout:g} s); "
                        f"outputs were forced to 0 V")
        if st is not None and st.limit_tripped:
            self.limit_tripped = True
            try:
                message = card.status().limit_message
            except HILError:
                message = ""
            self._fault(message or "a safety limit latched the amplifier off")

    def _sample_base(self, card: Any, t: float, h: float, began_ns: int) -> int | None:
        """The card time [ns] of the run's time 0 (the sample instant ending the step from ``t`` is
        ``base + t + h``), or None to keep the one in use.

        The start-up step (the first) puts it at the card's time after arming, on the card's tick grid:
        a lockstep card keeps it. On a real-time card a later step puts it :data:`ANCHOR_LEAD` of a
        period before that step began on the card's clock (the host's time since then taken off): the
        first paced step always, a later one when it began earlier than that schedule says, by less than
        half a period (the host paces on an earlier schedule: a stall of the first paced step, say).
        So a host pacing to the wall clock starts each step after the last sample instant, with a
        reading of that instant (a little older than the step), and waits for none; a host that does
        not pace comes about a period early and is held back by the card instead.
        """
        if self._base_ns is None:
            now_ns = int(round(card.time() * 1e9))
            tick = int(round(getattr(card.info, "tick", 0.0) * 1e9))
            base = now_ns - int(round(t * 1e9))
            return (base // tick) * tick if tick > 0 else base
        if getattr(card.info, "clock", "") == "lockstep":
            return None
        # a card that reckons its clock locally is not asked (no extra round trip)
        now_ns = card.rig_now_ns() if hasattr(card, "rig_now_ns") else int(round(card.time() * 1e9))
        h_ns = int(round(h * 1e9))
        base = now_ns - (time.monotonic_ns() - began_ns) - int(round(t * 1e9)) - int(round(h_ns * ANCHOR_LEAD))
        if not self._paced_base:
            self._paced_base = True
            return base
        return base if 0 < self._base_ns - base < h_ns // 2 else None

    def _fault(self, message: str) -> None:
        """Record, make safe (0 V, close), and fail the step."""
        self.last_error = message
        _close_quietly(self._holder)
        raise StepFailure(message)

    def teardown(self) -> None:
        _close_quietly(self._holder)
