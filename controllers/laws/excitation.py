"""Excitation for identification experiments: a seeded multisine voltage plus a weak position hold.

Pure Python (standard library only; runs inside the excitation FMUs).

The signal is a random-phase multisine, periodic in ``period``::

    u(t) = a * sum_k sin(2 pi f_k t + phi_k),   f_k = k / period,  band_low <= f_k <= band_high

with the phases ``phi_k`` drawn from ``random.Random(seed)`` and ``a`` chosen so that the peak of
``u`` over one period (on the sample grid) is exactly ``amplitude``. Every line of the band carries
the same power, so each mode of the plant in the band (the cart's mechanical time constant,
about 3 Hz; the hanging pendulum, about 1 Hz; the double mass's spring, about 2.5 Hz) is excited
with the same weight; the default band 0.2 .. 10 Hz covers all three. A multisine rather than a
PRBS: its spectrum stops at ``band_high``, so the 1 kHz encoders see no energy the model's
unmodelled dynamics would have to explain, and the cart velocity reverses smoothly, which
exposes the Coulomb force at every reversal.

The motor-driven cart is held near the reference by a weak proportional hold::

    v = u(t) - hold_gain * (x_motor - reference)

weak in the sense that its bandwidth (hold_gain * 0.089 m/(V s), 1.8 rad/s for the default
20 V/m) sits at the bottom of the band: it keeps the cart within about +-0.2 m of the centre for
a 3 V excitation without shaping the response in the band.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from ipcosim.controllers.laws.base import DiscreteLaw, LawEntry, LawParameterError, ParamSpec


@dataclass(frozen=True)
class ExcitationGains:
    """Parameters of the excitation (see the module docstring)."""

    amplitude: float = 3.0      # V
    seed: float = 1.0
    band_low: float = 0.2       # Hz
    band_high: float = 10.0     # Hz
    period: float = 20.0        # s
    hold_gain: float = 20.0     # V/m

    UNITS = {"amplitude": "V", "seed": "1", "band_low": "Hz", "band_high": "Hz", "period": "s", "hold_gain": "V/m"}
    DOCS = {"amplitude": "peak of the multisine voltage",
            "seed": "seed of the multisine's random phases (a whole number; the same seed gives the same signal)",
            "band_low": "lowest frequency of the multisine (rounded up to a multiple of 1/period)",
            "band_high": "highest frequency of the multisine (rounded down to a multiple of 1/period)",
            "period": "period of the multisine: its lines are the multiples of 1/period in the band",
            "hold_gain": "weak proportional hold of the motor-driven cart on the reference"}


def multisine(gains: ExcitationGains, sample_period: float) -> list[float]:
    """One period of the multisine on the sample grid ``k * sample_period`` (peak = ``amplitude``).

    Raises
    ------
    LawParameterError
        If the band holds no line of ``1/period`` or lies above the Nyquist frequency.
    """
    n = round(gains.period / sample_period)
    if n < 2 or abs(n * sample_period - gains.period) > 1e-9 * gains.period:
        raise LawParameterError("period", f"parameter period = {gains.period} s must be a whole number (>= 2) of "
                                          f"sample periods ({sample_period} s)")
    if not 0 < gains.band_low <= gains.band_high < 0.5 / sample_period:
        raise LawParameterError("band_high", f"parameters band_low = {gains.band_low} Hz, band_high = "
                                             f"{gains.band_high} Hz: need 0 < band_low <= band_high < "
                                             f"{0.5 / sample_period:g} Hz (half the sample rate)")
    lines = range(math.ceil(gains.band_low * gains.period - 1e-9),
                  math.floor(gains.band_high * gains.period + 1e-9) + 1)
    if not lines:
        raise LawParameterError("band_low", f"the band {gains.band_low} .. {gains.band_high} Hz holds no multiple "
                                            f"of 1/period = {1 / gains.period:g} Hz")
    rng = random.Random(int(gains.seed))
    phases = [rng.uniform(0.0, 2 * math.pi) for _ in lines]
    w = [2 * math.pi * k / n for k in lines]
    table = [sum(math.sin(wk * i + ph) for wk, ph in zip(w, phases)) for i in range(n)]
    scale = gains.amplitude / max(map(abs, table))
    return [scale * u for u in table]


class Excitation(DiscreteLaw):
    """The identification experiment's voltage: multisine plus weak hold (``ExcitationGains``).

    Parameters
    ----------
    kind : {'single-mass', 'double-mass'}
    gains : ExcitationGains
    sample_period, voltage_limit : float
        [s], [V].
    """

    def __init__(self, kind: str, gains: ExcitationGains, sample_period: float = 1e-3,
                 voltage_limit: float = 10.0) -> None:
        super().__init__(kind, sample_period, voltage_limit)
        for name in ("amplitude", "hold_gain", "seed"):
            if not (math.isfinite(getattr(gains, name)) and getattr(gains, name) >= 0):
                raise LawParameterError(name, f"parameter {name} = {getattr(gains, name)} must be a number >= 0")
        if gains.seed != int(gains.seed):
            raise LawParameterError("seed", f"parameter seed = {gains.seed} must be a whole number")
        self.gains = gains
        self.table = multisine(gains, self.sample_period)

    def signal(self, ticks: int) -> float:
        """The multisine at sample instant ``ticks`` [V]."""
        return self.table[ticks % len(self.table)]

    def _compute(self, y: Sequence[float], r: float) -> float:
        return self.signal(self.ticks) - self.gains.hold_gain * (self._motor_cart(y) - r)


def _excitation_specs(kind: str) -> list[ParamSpec]:
    g = ExcitationGains()
    return [ParamSpec(f, getattr(g, f), ExcitationGains.UNITS[f], ExcitationGains.DOCS[f],
                      "positive" if f in ("band_low", "band_high", "period") else "nonnegative")
            for f in ExcitationGains.UNITS]


def _excitation_values(kind: str, parameter_set: str) -> dict[str, Any]:
    g = ExcitationGains()
    return {f: getattr(g, f) for f in ExcitationGains.UNITS}


def _build_excitation(kind: str, v: Mapping[str, Any], backend: str) -> Excitation:
    return Excitation(kind, ExcitationGains(**{f: float(v[f]) for f in ExcitationGains.UNITS}),
                      float(v["sample_period"]), float(v["voltage_limit"]))


# not a control law: the identification experiments' multisine and weak hold. No native flavour: it looks its
# multisine up in a table indexed by the sample count, which the C generator's tracer cannot follow.
EXCITATION_LAW = LawEntry("Excitation", {"single-mass": ("identify",), "double-mass": ("identify",)},
                          _excitation_specs, _excitation_values, _build_excitation, classes=(Excitation,),
                          feedback=False, native=False)
