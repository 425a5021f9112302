"""What stands between the plant's motion and a controller on the bench: encoders, noise, end stops.

Options of the one plant model (``ipcosim.fmus.plant.Plant``), shared by the plant FMUs and the
virtual rig (``ipcosim.fmus.hil.rig``), so that simulation and the rig behave alike. Plain
Python floats and the standard library only (this module runs inside the plant FMUs).

* **Encoder quantization**: a reading is ``floor(x / resolution + phase) * resolution``, the
  count a quadrature counter holds (``phase = 0.5``: count edges half a count either side of the
  zero, so a reading is the nearest count). Resolution 0 = exact readings.
* **Measurement noise**: Gaussian, standard deviation in counts (or in SI units when the
  resolution is 0), from a generator seeded by ``noise_seed``: the same seed gives the same run.
* **Track end stops**: a cart that reaches ``+-end_stop`` stops dead there (inelastic: its
  outward velocity is set to zero). 0 = no end stops.
* **D/A quantization**: the voltage the amplifier receives is a whole code of the card's DAC,
  ``quantize(v, voltage_resolution)`` (the nearest code). 0 = exact.
* **Computation delay**: the voltage reaches the amplifier ``input_delay`` later, in whole plant
  steps (:func:`delay_line`): the rig writes the voltage computed from one sample's readings at the
  next sample.

The amplifier's saturation is the plant parameter ``voltage_limit``; Coulomb and viscous friction
per cart are the plant parameters ``b``/``b1``/``b2`` and ``Beq``/``Ba``/``Bc``/``Bp``.

Two option sets (``REALISM``): ``ideal`` (everything off: exact, noise-free readings, no end
stops, no Coulomb friction, an amplifier that does not saturate within +-1 kV) and ``lab`` (the IP02
on its track, values and sources in ``LAB_SOURCES``).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, fields
from typing import Iterator, Mapping, Sequence

from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus import kinds

#: IP02 encoders: 4096 counts/rev; cart through the 1.48 cm position pinion, pendulum direct.
CART_M_PER_COUNT = 2.275e-5
PENDULUM_RAD_PER_COUNT = 2 * math.pi / 4096
#: Half the 0.814 m track: where a cart hits the end of the rack.
END_STOP_M = 0.407
#: The lab's software limits on the encoder readings (the virtual rig's defaults, ``ipcosim rig serve
#: --cart-limit``, ``--pendulum-limit-deg``): each cart +-0.30 m, the pendulum +-20 deg from upright.
CART_LIMIT_M = 0.30
PENDULUM_LIMIT_RAD = math.radians(20.0)
#: Q4 analog output: 12-bit DAC over +-10 V (the Q4 card of the thesis, sec. 3.3; ``ipcosim.fmus.hil.rig``).
DAC_BITS = 12
DAC_RANGE_V = 10.0
DAC_V_PER_CODE = 2 * DAC_RANGE_V / (1 << DAC_BITS)
#: The lab's controller sample period [s]: the one-sample computation delay of the rig.
LAB_SAMPLE_PERIOD = 1e-3


class InstrumentError(IpcosimError, ValueError):
    """An instrument option that is not finite or out of range (names the option)."""


@dataclass(frozen=True)
class Instruments:
    """Encoders, noise and end stops of a plant (all off by default: the ideal plant).

    Parameters
    ----------
    cart_resolution : float
        Cart encoder resolution [m/count]; 0 = exact readings.
    pendulum_resolution : float
        Pendulum encoder resolution [rad/count]; 0 = exact readings.
    noise_counts : float
        Standard deviation of Gaussian noise on every reading [counts] (the resolution's unit;
        SI units where the resolution is 0); 0 = none.
    noise_seed : int
        Seed of the noise generator.
    end_stop : float
        Track end stops at +-end_stop [m] for every cart; 0 = none.
    input_delay : float
        Transport delay of the voltage [s] (a computation delay), rounded to whole plant steps; 0 = none.
    voltage_resolution : float
        D/A converter resolution [V/code]: the voltage is the nearest code; 0 = exact.
    tap_time : float
        When the taps act [s] (the step that starts at or just before it).
    tap_force_impulse : float
        Impulse of a force tap on the cart carrying the pendulum [N s]; 0 = none.
    tap_torque_impulse : float
        Impulse of a torque tap on the pendulum [N m s], counter-clockwise positive; 0 = none.
    """

    cart_resolution: float = 0.0
    pendulum_resolution: float = 0.0
    noise_counts: float = 0.0
    noise_seed: int = 0
    end_stop: float = 0.0
    input_delay: float = 0.0
    tap_time: float = 0.0
    tap_force_impulse: float = 0.0
    tap_torque_impulse: float = 0.0
    voltage_resolution: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InstrumentError(f"instrument option {f.name} = {v!r} must be a finite number >= 0")

    @property
    def ideal(self) -> bool:
        """True when every option is off."""
        return not (self.cart_resolution or self.pendulum_resolution or self.noise_counts or self.end_stop
                    or self.input_delay or self.tap_force_impulse or self.tap_torque_impulse
                    or self.voltage_resolution)


def tap_velocity_change(mass_matrix: tuple[float, float, float], force_impulse: float,
                        torque_impulse: float) -> tuple[float, float]:
    """(cart, pendulum) velocity jumps from impulses on the generalized momenta: ``M dv = (P_F, P_tau)``
    with ``M = [[m11, m12], [m12, m22]]`` the cart-pendulum mass matrix at the current angle."""
    m11, m12, m22 = mass_matrix
    det = m11 * m22 - m12 * m12
    return ((m22 * force_impulse - m12 * torque_impulse) / det, (m11 * torque_impulse - m12 * force_impulse) / det)


def quantize(x: float, resolution: float, phase: float = 0.5) -> float:
    """The reading of a counter of ``resolution`` per count at position ``x`` (exact if 0)."""
    if not resolution:
        return x
    return math.floor(x / resolution + phase) * resolution


class Readout:
    """Turns true positions into readings: quantization, then seeded noise.

    Parameters
    ----------
    instruments : Instruments
    resolutions : sequence of float
        Resolution of each measured channel (``Instruments.cart_resolution`` or
        ``pendulum_resolution``, in the plant's ``MEASURED`` order).
    """

    def __init__(self, instruments: Instruments, resolutions: Sequence[float]) -> None:
        self.instruments = instruments
        self.resolutions = tuple(float(r) for r in resolutions)
        self._rng = random.Random(int(instruments.noise_seed))

    def read(self, positions: Sequence[float]) -> tuple[float, ...]:
        """Readings of the true ``positions`` (one noise draw per channel and call)."""
        sigma = self.instruments.noise_counts
        out = []
        for x, res in zip(positions, self.resolutions):
            y = quantize(x, res)
            if sigma:
                y += self._rng.gauss(0.0, sigma) * (res or 1.0)
                y = quantize(y, res)
            out.append(y)
        return tuple(out)


def delay_steps(delay: float, h: float) -> float:
    """A transport delay of ``delay`` [s] in whole steps of ``h`` [s] (the nearest whole number, as a float)."""
    return math.floor(delay / h + 0.5)


def delay_line(buffer: Sequence[float], v: float, n: float) -> tuple[float, list[float]]:
    """One step of a delay of ``n`` whole steps: ``(the input of n steps ago, the new buffer)``.

    ``buffer[k]`` holds the input of ``k + 1`` steps ago (zeros before the start); ``n`` = 0 passes
    ``v`` through. The buffer must hold at least ``n`` values.
    """
    out = v
    for k, past in enumerate(buffer):
        if n == k + 1:
            out = past
            break
    return out, [v, *buffer[:-1]]


def stop_carts(x: Sequence[float], carts: Sequence[tuple[int, int]], stop: float) -> tuple[list[float], float]:
    """``(state, number of carts stopped)`` after the end stops at ``+-stop`` (``carts``: (position, velocity)
    indices; 0 = no end stops). Plain arithmetic and comparisons (the native plant traces it)."""
    out = list(x)
    hits = 0.0
    for ip, iv in carts:
        if stop and abs(out[ip]) > stop:
            side = 1.0 if out[ip] > 0.0 else -1.0
            out[ip] = side * stop
            if out[iv] * side > 0.0:
                out[iv] = 0.0
            hits = hits + 1.0
    return out, hits


def end_stop_state(x: Sequence[float], carts: Sequence[tuple[int, int]], stop: float) -> list[float] | None:
    """The state after the end stops at ``+-stop`` (``carts``: (position, velocity) indices), or
    None if no cart is beyond them."""
    out, hits = stop_carts(x, carts, stop)
    return out if hits else None


class Bench(Mapping[str, object]):
    """One option set: ``["instruments"]`` its instrument options, ``[kind]`` its plant-parameter overrides for
    plant ``kind`` (every cart's Coulomb force ``coulomb`` [N], then ``voltage_limit`` [V])."""

    def __init__(self, instruments: Instruments, coulomb: float, voltage_limit: float) -> None:
        self.instruments, self.coulomb, self.voltage_limit = instruments, coulomb, voltage_limit

    def __getitem__(self, key: str) -> object:
        if key == "instruments":
            return self.instruments
        carts = kinds.get(key).carts
        return {**{cart.coulomb: self.coulomb for cart in carts}, "voltage_limit": self.voltage_limit}

    def __iter__(self) -> Iterator[str]:
        return iter(("instruments", *kinds.names()))

    def __len__(self) -> int:
        return 1 + len(kinds.names())


#: The two option sets (instrument options and plant-parameter overrides per plant kind).
REALISM: dict[str, Bench] = {
    "ideal": Bench(Instruments(), coulomb=0.0, voltage_limit=1000.0),
    "lab": Bench(Instruments(cart_resolution=CART_M_PER_COUNT, pendulum_resolution=PENDULUM_RAD_PER_COUNT,
                             noise_counts=0.0, end_stop=END_STOP_M, input_delay=LAB_SAMPLE_PERIOD,
                             voltage_resolution=DAC_V_PER_CODE), coulomb=0.1047, voltage_limit=10.0),
}

LAB_SOURCES = {
    "cart_resolution": "IP02: 4096 counts/rev encoder on the 1.48 cm position pinion (2.275e-5 m/count)",
    "pendulum_resolution": "IP02: 4096 counts/rev pendulum encoder (1.534e-3 rad/count)",
    "noise_counts": "0: optical quadrature encoders have no analog noise; their error is the count itself",
    "end_stop": "IP02: 0.814 m track, end stops at +-0.407 m",
    "voltage_limit": "Q4 analog output range +-10 V, amplifier gain 1",
    "voltage_resolution": "Q4 12-bit DAC over +-10 V: 20 V / 4096 = 4.883 mV per code",
    "input_delay": "one sample (1 ms at the rig's 1 kHz): the voltage computed from a sample's readings is written "
                   "at the next sample",
    "b, b1, b2": "FITTED, not measured: 0.1047 N is the passive-cart Coulomb force that reproduces the thesis's "
                 "5.575 mm double-mass HSMC error (docs/plant.md); assumed the same for every "
                 "cart; "
                 "stick-slip (Karnopp 1985, ipcosim.fmus.physics): below this force a cart does not move",
}


def realism(name: str, kind: str) -> tuple[Instruments, dict[str, float]]:
    """``(instruments, plant-parameter overrides)`` of the option set ``name`` for plant ``kind``."""
    if name not in REALISM:
        raise InstrumentError(f"unknown realism preset {name!r}; {closest(name, REALISM)}")
    entry = REALISM[name]
    return entry["instruments"], dict(entry[kind])  # type: ignore[return-value,arg-type]
