"""FMI 3.0 clocks: what the master reads of an FMU's clocks and when they tick, exactly.

A clock (FMI 3.0, section 2.2.8) is read from the FMU's ``modelDescription.xml`` as written, its
``intervalDecimal`` and ``shiftDecimal`` (or ``intervalCounter``/``shiftCounter`` over
``resolution``) as :class:`~fractions.Fraction`: tick ``i`` of a periodic clock is
``t_start + shift + i * interval`` computed in rational arithmetic, so no tick drifts however many
come before it (the floating-point time is the correctly rounded value of the exact one).

The master runs time-based periodic input clocks whose interval the model description gives
(``constant``, and ``fixed`` or ``tunable`` kept at their ``intervalDecimal``) and reads triggered
output clocks in every Event Mode it holds. It refuses by name what it does not run: aperiodic
input clocks (``changing``, ``countdown``: the next interval is asked of the FMU at every event),
triggered input clocks (nothing here triggers them), periodic clocks without ``intervalDecimal``,
and FMUs offering only scheduled execution.
"""
from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from ipcosim.errors import IpcosimError

#: Input clock kinds (``intervalVariability``) the master runs, and those it refuses with the reason.
PERIODIC = ("constant", "fixed", "tunable")
REFUSED = {"changing": "a changing aperiodic clock (its next interval is asked of the FMU at every event)",
           "countdown": "a countdown aperiodic clock (its next interval is asked of the FMU at every event)",
           "triggered": "a triggered input clock (no component here triggers it)"}


class ClockError(IpcosimError, ValueError):
    """A clock the master does not run, or one whose ticks miss the communication points (names both)."""


@dataclass(frozen=True)
class Clock:
    """One clock of an FMU: ``interval`` and ``shift`` in seconds, exact (None: not periodic)."""

    name: str
    vr: int
    causality: str
    kind: str  # intervalVariability
    interval: Fraction | None = None
    shift: Fraction = Fraction(0)

    def tick(self, i: int, start: Fraction = Fraction(0)) -> Fraction:
        """Time of tick ``i`` (from 0) of a periodic clock: ``start + shift + i * interval``, exact."""
        assert self.interval is not None
        return start + self.shift + i * self.interval

    def describe(self) -> str:
        """One line: the clock, its kind and its period."""
        if self.interval is None:
            return f"{self.name} ({self.causality} clock, {self.kind})"
        shift = f", shift {float(self.shift):g} s" if self.shift else ""
        return (f"{self.name} ({self.causality} clock, {self.kind}, every {float(self.interval):g} s = "
                f"{float(1 / self.interval):g} Hz{shift})")


@dataclass(frozen=True)
class Clocking:
    """What the master needs of a clocked FMU: its clocks, and the clocked variables of each
    (value reference -> the clocks' value references), its ``hasEventMode``."""

    clocks: tuple[Clock, ...]
    clocked: dict[int, tuple[int, ...]]
    has_event_mode: bool

    def inputs(self) -> tuple[Clock, ...]:
        return tuple(c for c in self.clocks if c.causality == "input")

    def outputs(self) -> tuple[Clock, ...]:
        return tuple(c for c in self.clocks if c.causality == "output")


def _exact(text: str | None, counter: str | None, resolution: str | None, what: str) -> Fraction | None:
    if counter is not None:
        return Fraction(int(counter), int(resolution or 1))
    if text is None:
        return None
    try:
        value = Fraction(text.strip())
    except ValueError:
        raise ClockError(f"{what} = {text!r} is not a decimal number") from None
    return value


def parse_clocking(xml: bytes, label: str) -> Clocking:
    """The clocks of the FMI 3.0 model description ``xml`` (``label`` names the FMU in errors).

    Raises
    ------
    ClockError
        A clock kind the master does not run (see the module documentation), or a bad interval.
    """
    root = ElementTree.fromstring(xml)
    cs = root.find("CoSimulation")
    clocks, clocked = [], {}
    for var in root.iterfind("ModelVariables/*"):
        if var.get("clocks"):
            clocked[int(var.get("valueReference"))] = tuple(int(x) for x in var.get("clocks").split())
        if var.tag != "Clock":
            continue
        clocks.append(_clock(var, label))
    if clocks and cs is None:
        raise ClockError(f"{label}: clocks in an FMU without co-simulation (scheduled execution is not supported)")
    return Clocking(tuple(clocks), clocked, cs is not None and cs.get("hasEventMode") == "true")


def _clock(var: ElementTree.Element, label: str) -> Clock:
    name, causality = var.get("name", "?"), var.get("causality", "local")
    kind = var.get("intervalVariability", "")
    what = f"{label}: clock {name}"
    if causality == "output" or causality == "local":
        return Clock(name, int(var.get("valueReference")), causality, kind or "triggered")
    if kind in REFUSED:
        raise ClockError(f"{what} is {REFUSED[kind]}: not supported by this master")
    if kind not in PERIODIC:
        raise ClockError(f"{what}: intervalVariability {kind!r} is not an FMI 3.0 clock kind")
    interval = _exact(var.get("intervalDecimal"), var.get("intervalCounter"), var.get("resolution"),
                      f"{what} intervalDecimal")
    if interval is None:
        raise ClockError(f"{what} ({kind}) gives no intervalDecimal: a periodic clock whose interval is asked of "
                         "the FMU (fmi3GetInterval) is not supported by this master")
    if interval <= 0:
        raise ClockError(f"{what}: interval {float(interval):g} s must be > 0")
    shift = _exact(var.get("shiftDecimal"), var.get("shiftCounter"), var.get("resolution"), f"{what} shiftDecimal")
    if shift is not None and shift < 0:
        raise ClockError(f"{what}: shift {float(shift):g} s must be >= 0")
    return Clock(name, int(var.get("valueReference")), causality, kind, interval, shift or Fraction(0))


@lru_cache(maxsize=256)
def _clocking_of(path: str, mtime: float, label: str) -> Clocking:
    del mtime  # part of the cache key
    with zipfile.ZipFile(path) as z:
        return parse_clocking(z.read("modelDescription.xml"), label)


def clocking(path: Path | None, fmi_version: str, label: str) -> Clocking | None:
    """The clocks of the FMU file ``path`` (None for an FMI 2.0 FMU or one without clocks)."""
    if path is None or not str(fmi_version).startswith("3"):
        return None
    p = Path(path)
    found = _clocking_of(str(p.resolve()), p.stat().st_mtime, label)
    return found if found.clocks else None


def exact_seconds(x: float, ns: int | None = None) -> Fraction:
    """A time or step of the master as an exact number: its whole nanoseconds when it has them
    (the master's time base), else the shortest decimal that reads back as ``x``."""
    return Fraction(ns, 10 ** 9) if ns is not None else Fraction(repr(float(x)))


def tick_multiple(clock: Clock, step: Fraction, label: str) -> tuple[int, int]:
    """``(first, every)``: the clock ticks at the master's communication points ``first + i * every``.

    Raises
    ------
    ClockError
        If the clock's interval or shift is not a whole number of steps ``step``.
    """
    assert clock.interval is not None
    every, first = clock.interval / step, clock.shift / step
    if every.denominator != 1 or first.denominator != 1:
        raise ClockError(f"{label}: clock {clock.name} (every {float(clock.interval):g} s, shift "
                         f"{float(clock.shift):g} s) ticks between the communication points of step "
                         f"{float(step):g} s: choose --step so that it divides the clock's interval and shift")
    return int(first), int(every)


def clock_multiple(clocks: tuple[Clock, ...], step: Fraction, label: str) -> int:
    """The step multiple of a component whose input clocks are ``clocks``: every tick of each is
    the end of one of its steps (the greatest common divisor of their intervals and shifts, in steps)."""
    g = 0
    for clock in clocks:
        first, every = tick_multiple(clock, step, label)
        g = math.gcd(g, every, first)
    return g or 1


def clock_multiples(system: Any, timebase: Any) -> dict[str, int]:
    """The step multiple of every component with input clocks (:func:`clock_multiple`), which
    replaces the one its ``sample_period`` would give: each of its doSteps ends on the next tick.

    Raises
    ------
    ClockError
        A clock the master does not run, or one that ticks between communication points.
    """
    step = exact_seconds(timebase.step, timebase.step_ns)
    out = {}
    for inst in system.instances:
        found = clocking(inst.model.path, inst.model.fmi_version, inst.name)
        if found is None or not found.inputs():
            continue
        if not found.has_event_mode:
            raise ClockError(f"{inst.name}: clocks in an FMU without Event Mode (hasEventMode is not true)")
        out[inst.name] = clock_multiple(found.inputs(), step, inst.name)
    return out
