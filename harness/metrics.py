"""Step-response metrics of one closed-loop run: the single definition every part of ipcosim uses.

The task (thesis ch. 3 and 4): move the motor-driven cart from its initial position to the
reference (0.05 m) while the pendulum stays upright. Definitions (DESIGN.md, "Metrics"):

``settling_time_s``
    The step is ``r_f - x(t0)``, with ``r_f`` the final reference value and ``x(t0)`` the
    initial cart position. The band is ``r_f +- 2 %`` of ``|step|``. The settling time is the
    time of the *last entry* into the band (the first sample from which the position stays
    inside until the end of the run), measured from the instant the reference last changed
    before that entry (``t0`` for a reference that is already at ``r_f`` at ``t0``). ``None``
    if the position is outside the band at the end of the run, if the step is zero, or if the
    run holds a non-finite sample.
``overshoot_m``
    ``max(0, max over the run of sign(step) (x - r_f))``: how far the cart went past the final
    reference, in metres.
``steady_state_error_m``
    ``|mean(x - r)|`` over the samples in the final 10 % of the run's duration.
``max_abs_angle_rad``
    ``max |angle|``.
``peak_voltage_V``, ``rms_voltage_V``
    ``max |v|`` and ``sqrt(mean(v^2))`` of the controller's voltage command (samples treated with
    equal weight; the recorders sample on a uniform grid).
``upright``
    ``True`` if ``|angle| < 0.35 rad`` at every sample (and every sample is finite).

A run that diverged (NaN/inf samples) gives ``upright = False`` and ``None`` for the metrics that
lose their meaning, never an exception: failed runs must still produce their metrics file.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ipcosim.harness.errors import IpcosimError

#: |angle| limit of the task [rad] (about 20 degrees, the lab software's pendulum limit).
UPRIGHT_LIMIT_RAD = 0.35
#: Half-width of the settling band as a fraction of the step.
SETTLING_BAND = 0.02
#: Fraction of the run (at its end) over which the steady-state error is averaged.
STEADY_STATE_FRACTION = 0.10

METRIC_KEYS = ("settling_time_s", "overshoot_m", "steady_state_error_m", "max_abs_angle_rad",
               "peak_voltage_V", "rms_voltage_V", "upright")


class MetricsError(IpcosimError, ValueError):
    """The signals handed to ``compute_metrics`` do not describe one run (lengths, shape, time order)."""


def _as_1d(name: str, values: Any, n: int | None) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise MetricsError(f"metrics: signal {name} must be 1-D, got shape {arr.shape}")
    if n is not None and arr.size != n:
        raise MetricsError(f"metrics: signal {name} has {arr.size} samples, time has {n}")
    return arr


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def compute_metrics(time: Any, position: Any, reference: Any, angle: Any, voltage: Any) -> dict[str, Any]:
    """Metrics of one run (see the module docstring for the definitions).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s], strictly increasing, n >= 2.
    position : array_like, shape (n,)
        Position of the motor-driven cart [m] (the active cart for the double mass).
    reference : array_like, shape (n,)
        Reference position [m].
    angle : array_like, shape (n,)
        Pendulum angle from upright [rad].
    voltage : array_like, shape (n,)
        Controller voltage command [V].

    Returns
    -------
    dict
        Keys ``METRIC_KEYS``; values are float, ``None`` or (``upright``) bool.

    Raises
    ------
    MetricsError
        If the signals are not 1-D arrays of one length >= 2 or time is not strictly increasing.
    """
    t = _as_1d("time", time, None)
    n = t.size
    if n < 2:
        raise MetricsError(f"metrics: need at least 2 samples, got {n}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise MetricsError("metrics: time must be finite and strictly increasing")
    x = _as_1d("position", position, n)
    r = _as_1d("reference", reference, n)
    th = _as_1d("angle", angle, n)
    v = _as_1d("voltage", voltage, n)

    finite = bool(np.all(np.isfinite(x)) and np.all(np.isfinite(r)) and np.all(np.isfinite(th))
                  and np.all(np.isfinite(v)))
    abs_th = np.abs(th)
    max_angle = float(np.max(abs_th)) if np.all(np.isfinite(th)) else math.inf
    upright = bool(finite and max_angle < UPRIGHT_LIMIT_RAD)
    abs_v = np.abs(v)
    peak_v = float(np.max(abs_v)) if np.all(np.isfinite(v)) else math.inf
    rms_v = float(np.sqrt(np.mean(v * v))) if np.all(np.isfinite(v)) else math.inf

    result: dict[str, Any] = {"settling_time_s": None, "overshoot_m": None, "steady_state_error_m": None,
                              "max_abs_angle_rad": _finite_or_none(max_angle),
                              "peak_voltage_V": _finite_or_none(peak_v),
                              "rms_voltage_V": _finite_or_none(rms_v), "upright": upright}
    if not finite:
        return result

    r_final = float(r[-1])
    step = r_final - float(x[0])
    direction = 1.0 if step >= 0 else -1.0
    result["overshoot_m"] = max(0.0, float(np.max(direction * (x - r_final))))

    t_start = t[-1] - STEADY_STATE_FRACTION * (t[-1] - t[0])
    tail = t >= t_start
    result["steady_state_error_m"] = float(abs(np.mean(x[tail] - r[tail])))

    if step != 0.0:
        band = SETTLING_BAND * abs(step)
        outside = np.abs(x - r_final) > band
        if not outside[-1]:
            idx_out = np.flatnonzero(outside)
            entry = int(idx_out[-1]) + 1 if idx_out.size else 0
            # instant the reference last changed at or before the entry (t0 if never)
            changed = np.flatnonzero(r[1:entry + 1] != r[:entry])
            t_ref = t[int(changed[-1]) + 1] if changed.size else t[0]
            result["settling_time_s"] = float(t[entry] - t_ref)
    return result


def wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi) (upright = 0; a swing-up's angle starts at pi)."""
    return (np.asarray(angle, dtype=float) + math.pi) % (2 * math.pi) - math.pi


def upright_metrics(time: Any, position: Any, angle: Any) -> dict[str, Any]:
    """Metrics of a run that need not start upright (a swing-up): ``time_to_upright_s`` (from which
    on ``|wrapped angle| < UPRIGHT_LIMIT_RAD`` to the end of the run; None if it does not end
    upright) and ``track_used_m`` (largest ``|position|`` of the motor-driven cart)."""
    t = _as_1d("time", time, None)
    th = np.abs(wrapped(_as_1d("angle", angle, t.size)))
    x = _as_1d("position", position, t.size)
    down = np.nonzero(~(th < UPRIGHT_LIMIT_RAD))[0]
    if down.size == 0:
        t_up: float | None = float(t[0])
    elif down[-1] == t.size - 1:
        t_up = None
    else:
        t_up = float(t[down[-1] + 1])
    out = {"time_to_upright_s": t_up, "track_used_m": _finite_or_none(float(np.max(np.abs(x))))}
    out.update(tap_metrics(t, angle))
    return out


#: Band the pendulum must re-enter (and stay in) after a tap to count as recovered [rad].
RECOVERY_BAND_RAD = 0.01


def tap_metrics(time: Any, angle: Any) -> dict[str, Any]:
    """``peak_angle_after_tap_rad`` (largest ``|angle|`` from the instant the angle first leaves its
    initial value by more than 1e-6 rad: the tap, for a pendulum at rest upright) and
    ``recovery_time_s`` (from that instant until ``|angle|`` is inside +-RECOVERY_BAND_RAD for
    good; None if it ends outside). Both None when the angle never moves. On a step-task run they
    describe the step's angle excursion instead."""
    t = _as_1d("time", time, None)
    th = wrapped(_as_1d("angle", angle, t.size))
    moved = np.nonzero(np.abs(th - th[0]) > 1e-6)[0]
    if moved.size == 0 or not np.all(np.isfinite(th)):
        return {"peak_angle_after_tap_rad": None, "recovery_time_s": None}
    k0 = int(moved[0])
    outside = np.nonzero(np.abs(th[k0:]) >= RECOVERY_BAND_RAD)[0]
    if outside.size == 0:
        rec: float | None = 0.0
    elif k0 + outside[-1] == t.size - 1:
        rec = None
    else:
        rec = float(t[k0 + outside[-1] + 1] - t[k0])
    return {"peak_angle_after_tap_rad": float(np.max(np.abs(th[k0:]))), "recovery_time_s": rec}
