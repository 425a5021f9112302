"""Task metrics and the tuning cost, computed from one run's time series.

The tuning cost (documented in ``docs/studies.md``)::

    J = ITAE(x - r) + w_angle * ITAE(theta) + w_voltage * ISE(u)

    ITAE(e) = integral of t * |e(t)| dt     [m s^2] or [rad s^2]
    ISE(u)  = integral of u(t)^2 dt         [V^2 s]

over the whole run, with ``x`` the motor-driven cart's position, ``r`` the reference,
``theta`` the pendulum angle and ``u`` the controller's voltage; defaults
``w_angle = 0.1 m/rad`` and ``w_voltage = 1e-4 m s/V^2`` (so that for a response that
settles in a few seconds the three terms are of similar size). ``J`` is infinite when the
pendulum falls (|theta| reaches 0.35 rad, the ``upright`` limit) or the run fails; the
optimiser is handed the finite surrogate ``FALL_PENALTY * (2 - t_fall / T)`` instead, which
still ranks an earlier fall as worse.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from ipcosim.fmus.metrics import UPRIGHT_LIMIT_RAD, compute_metrics

#: Default weight of the angle term [m/rad].
W_ANGLE = 0.1
#: Default weight of the voltage term [m s/V^2].
W_VOLTAGE = 1e-4
#: Surrogate cost scale handed to the optimiser for a fallen or failed run.
FALL_PENALTY = 1e3

#: Hysteresis of the oscillation count [rad]: a swing smaller than this is not a reversal.
REVERSAL_HYSTERESIS = 0.005

COST_TERMS = ("itae_position", "itae_angle", "ise_voltage", "fall_time_s", "angle_reversals")


def reversals(signal: np.ndarray, hysteresis: float = REVERSAL_HYSTERESIS) -> int:
    """Number of direction reversals of a signal, ignoring swings smaller than ``hysteresis``
    (an oscillation count: a decaying oscillation of n half-periods above the threshold gives
    about n)."""
    x = np.asarray(signal, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return 0
    count, direction, start = 0, 0, float(x[0])
    extreme = start
    for v in x[1:].tolist():
        if direction == 0:
            if v >= start + hysteresis:
                direction, extreme = 1, v
            elif v <= start - hysteresis:
                direction, extreme = -1, v
        elif direction > 0:
            if v > extreme:
                extreme = v
            elif v < extreme - hysteresis:
                count, direction, extreme = count + 1, -1, v
        else:
            if v < extreme:
                extreme = v
            elif v > extreme + hysteresis:
                count, direction, extreme = count + 1, 1, v
    return int(count)


def _trapezoid(y: np.ndarray, t: np.ndarray) -> float:
    if len(t) < 2:
        return 0.0
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def cost_terms(time: np.ndarray, position: np.ndarray, reference: np.ndarray, angle: np.ndarray,
               voltage: np.ndarray) -> dict[str, float | None]:
    """The integrals the tuning cost is made of, and the angle's oscillation count.

    Parameters
    ----------
    time, position, reference, angle, voltage : numpy.ndarray
        1-D series of equal length, SI units ([s], [m], [m], [rad], [V]).

    Returns
    -------
    dict
        ``itae_position`` [m s^2], ``itae_angle`` [rad s^2], ``ise_voltage`` [V^2 s] and
        ``fall_time_s`` (first time |angle| >= UPRIGHT_LIMIT_RAD, or None), ``angle_reversals``
        (``reversals`` of the angle).
    """
    t = np.asarray(time, dtype=float)
    t_rel = t - t[0]
    e = np.abs(np.asarray(position, dtype=float) - np.asarray(reference, dtype=float))
    th = np.abs(np.asarray(angle, dtype=float))
    u = np.asarray(voltage, dtype=float)
    fallen = np.nonzero(~(th < UPRIGHT_LIMIT_RAD))[0]  # also catches NaN
    return {"itae_position": _trapezoid(t_rel * e, t),
            "itae_angle": _trapezoid(t_rel * th, t),
            "ise_voltage": _trapezoid(u * u, t),
            "fall_time_s": float(t[fallen[0]]) if fallen.size else None,
            "angle_reversals": reversals(np.asarray(angle, dtype=float))}


def cost(metrics: Mapping[str, Any], w_angle: float = W_ANGLE, w_voltage: float = W_VOLTAGE) -> float:
    """The documented tuning cost J of one run (``math.inf`` when it fell or failed)."""
    if metrics.get("upright") is False or metrics.get("fall_time_s") is not None:
        return math.inf
    try:
        value = (float(metrics["itae_position"]) + w_angle * float(metrics["itae_angle"])
                 + w_voltage * float(metrics["ise_voltage"]))
    except (KeyError, TypeError, ValueError):
        return math.inf
    return value if math.isfinite(value) else math.inf


def surrogate_cost(metrics: Mapping[str, Any], stop_time: float, w_angle: float = W_ANGLE,
                   w_voltage: float = W_VOLTAGE) -> float:
    """``cost`` with a finite stand-in for infinity that the optimiser can rank."""
    j = cost(metrics, w_angle, w_voltage)
    if math.isfinite(j):
        return j
    fall = metrics.get("fall_time_s")
    if isinstance(fall, (int, float)) and math.isfinite(fall) and stop_time > 0:
        return FALL_PENALTY * (2.0 - min(max(fall / stop_time, 0.0), 1.0))
    return 2.0 * FALL_PENALTY


def metrics_and_cost_terms(time: np.ndarray, position: np.ndarray, reference: np.ndarray, angle: np.ndarray,
                           voltage: np.ndarray) -> dict[str, Any]:
    """The task metrics (``ipcosim.fmus.metrics.compute_metrics``) plus the cost terms (docs/metrics.md)."""
    metrics = dict(compute_metrics(time, position, reference, angle, voltage))
    metrics.update(cost_terms(time, position, reference, angle, voltage))
    return metrics


def series(time: np.ndarray, position: np.ndarray, reference: np.ndarray, angle: np.ndarray,
           voltage: np.ndarray, max_points: int = 2000) -> dict[str, list[float]]:
    """The signals of a run for plotting, thinned to at most about ``max_points`` samples."""
    n = len(time)
    every = max(1, int(np.ceil(n / max_points)))
    sl = slice(0, n, every)
    return {"time": np.asarray(time, float)[sl].tolist(), "position": np.asarray(position, float)[sl].tolist(),
            "reference": np.asarray(reference, float)[sl].tolist(), "angle": np.asarray(angle, float)[sl].tolist(),
            "voltage": np.asarray(voltage, float)[sl].tolist()}
