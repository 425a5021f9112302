"""Describing functions of the lab bench's nonlinearities: the gain a sinusoid of a given amplitude meets at
each (Slotine & Li, *Applied Nonlinear Control*, ch. 5; Gelb & Vander Velde, *Multiple-Input Describing
Functions*, 1968). A cart's Coulomb friction (a relay on its velocity, with or without a dither), an encoder's
mid-tread quantizer, a law's Coulomb compensation, and the velocity swing a law's dither gives a cart. The
harmonic balance that combines them into a loop's residual cycle is :mod:`ipcosim.harness.analysis.residual_cycle`.
"""
from __future__ import annotations

import math

import numpy as np

#: Quadrature points of a compensation's describing function over a quarter period.
COMPENSATION_POINTS = 64
#: Above this many counts of amplitude a quantizer's describing function is 1 (its dips below 1 shrink as about
#: 0.4 / n^1.5 at n counts: below 1e-6 here).
LINEAR_QUANTIZER_COUNTS = 10_000


def relay_gain(amplitude: float, force: float) -> float:
    """Describing function of Coulomb friction ``force sign(v)`` at a velocity ``amplitude``: ``4 force / (pi A)``."""
    return 4.0 * force / (math.pi * amplitude)


def quantizer_gain(amplitude: float, step: float) -> float:
    """Describing function of a mid-tread quantizer of ``step`` for a sinusoid of ``amplitude`` centred on a level.

    Examples
    --------
    >>> round(quantizer_gain(2 ** -0.5, 1.0), 6)   # its largest value, 4/pi, at A = q / sqrt(2)
    1.27324
    >>> quantizer_gain(0.4, 1.0)                   # below the first threshold: no reading changes
    0.0
    """
    if amplitude <= step / 2:
        return 0.0
    n = math.floor(amplitude / step + 0.5)
    if n > LINEAR_QUANTIZER_COUNTS:   # within 1e-8 of the sum: the encoder reads the swing as it is
        return 1.0
    k = np.arange(1, n + 1)
    total = float(np.sum(np.sqrt(np.maximum(0.0, 1.0 - ((2 * k - 1) * step / (2 * amplitude)) ** 2))))
    return 4.0 * step / (math.pi * amplitude) * total


def reading_peak_to_peak(amplitude: float, step: float) -> float:
    """Peak-to-peak of the encoder's reading of a sinusoid of ``amplitude`` centred on a level (whole counts)."""
    return amplitude * 2.0 if step <= 0 else 2.0 * step * math.floor(amplitude / step + 0.5)


def dithered_relay_gain(amplitude: float, force: float, dither: float) -> float:
    """Describing function of Coulomb friction ``force sign(v)`` under a triangular velocity dither of
    half-width ``dither`` (the cart's velocity under a square-wave voltage): averaged over the dither, whose
    values are uniform on ``[-dither, dither]``, the relay is a saturation of slope ``force / dither``, and
    its describing function is ``force / dither`` up to ``A = dither`` and
    ``(2 force / (pi dither)) (asin(d / A) + (d / A) sqrt(1 - (d / A)^2))`` above (``d`` the dither; Gelb &
    Vander Velde, 1968, ch. 2); without dither, :func:`relay_gain`.

    Examples
    --------
    >>> round(dithered_relay_gain(0.5, 1.0, 1.0), 6)   # inside the dither: the saturation's slope
    1.0
    >>> round(dithered_relay_gain(1e6, 1.0, 1e-3) / relay_gain(1e6, 1.0), 6)   # far outside: the relay's
    1.0
    """
    if dither <= 0.0:
        return relay_gain(amplitude, force)
    if amplitude <= dither:
        return force / dither
    r = dither / amplitude
    return 2.0 * force / (math.pi * dither) * (math.asin(r) + r * math.sqrt(1.0 - r * r))


def compensation_gain(amplitude: float, force: float, threshold: float, dither: float = 0.0) -> float:
    """Describing function of a law's Coulomb compensation ``force w(|v|) sign(v)`` (``w`` 0 up to ``threshold``,
    1 from twice it, linear between: ``ipcosim.controllers.laws.lqg.coulomb_estimate`` without its breakaway
    term) for a velocity of ``amplitude``: its first harmonic over the amplitude, by quadrature. With a
    ``dither`` [m/s], the law's velocity is ``v +- dither`` on alternate samples (a square-wave voltage turns
    the velocity at the sample instants, where the law reads it): the mean of the two compensations."""
    if force <= 0.0 or amplitude + dither <= threshold:
        return 0.0
    theta = (np.arange(COMPENSATION_POINTS) + 0.5) * (math.pi / 2 / COMPENSATION_POINTS)
    v = amplitude * np.sin(theta)
    w = np.mean([np.sign(v + d) * np.clip(np.abs(v + d) / threshold - 1.0, 0.0, 1.0) for d in (dither, -dither)],
                axis=0)
    return float(4.0 / (math.pi * amplitude) * force * np.mean(w * np.sin(theta)) * (math.pi / 2))


def dither_velocity(Ad: np.ndarray, Bd: np.ndarray, velocity: int, amplitude: float) -> float:
    """Velocity half-width [m/s] of a cart (state ``velocity`` of the sampled plant ``Ad``, ``Bd``) under a
    voltage alternating ``+-amplitude`` every sample (a law's dither): the steady swing ``x_k = (-1)^k xbar``
    of ``x_{k+1} = Ad x_k + Bd u_k`` is ``xbar = -(I + Ad)^-1 Bd amplitude``, the velocity's turning points
    (the plant alone: the loop's feedback at half the sample rate is left out)."""
    xbar = np.linalg.solve(np.eye(Ad.shape[0]) + Ad, Bd[:, 0]) * amplitude
    return float(abs(xbar[velocity]))
