"""The IP02 task and its metrics: what a run of the pendulum is judged by.

The master knows nothing of pendulums: ``ipcosim.harness.api.engine`` gives the execution
:func:`streamed_task_metrics` as its ``task_metrics`` plug-in, which it calls on the recorded
rows a chunk at a time; :func:`task_metrics` computes the same on a whole result. Both read the
plant's columns named by :data:`POSITION_COLUMNS`, :data:`ANGLE_COLUMNS`,
:data:`REFERENCE_COLUMNS` and :data:`VOLTAGE_COLUMNS`; a run without them has no task metrics.

The task (thesis ch. 3 and 4): move the motor-driven cart from its initial position to the
reference (0.05 m) while the pendulum stays upright. Definitions (``docs/metrics.md`` for users):

``settling_time_s``
    The step is ``r_f - x(t0)``, with ``r_f`` the final reference value and ``x(t0)`` the
    initial cart position. The band is ``r_f +- 2 %`` of ``|step|``. The settling time is the
    time of the *last entry* into the band (the first sample from which the position stays
    inside until the end of the run), measured from the instant the reference last changed
    before that entry (``t0`` for a reference that is already at ``r_f`` at ``t0``). ``None``
    (not settled) if the position is outside the band at the end of the run, if the step is
    zero, if the run holds a non-finite sample, or if the pendulum fell (``upright`` false).
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

The metrics of a task (:func:`tasks_of`) come only with runs that do it:
``time_to_upright_s`` and ``track_used_m`` with a swing-up (the pendulum starts outside the
upright limit), ``peak_angle_after_tap_rad`` and ``recovery_time_s`` with a tap (a tap impulse
is set) -- :func:`upright_metrics` and :func:`tap_metrics` define them.

A run that diverged (NaN/inf samples) gives ``upright = False`` and ``None`` for the metrics that
lose their meaning, never an exception: failed runs must still produce their metrics file.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.errors import IpcosimError
from ipcosim.fmus.success import (  # noqa: F401 -- the success criterion, importable from here too
    AMPLITUDE_MARGIN_M,
    AMPLITUDE_TOLERANCE_M,
    BOUND_KEYS,
    CYCLE_SOURCES,
    MEAN_ERROR_LIMIT_M,
    SUCCESS_STATUSES,
    amplitude_bound,
    predicted_amplitude_bound,
    success_status,
)

#: Plant outputs that the metrics read, by preference: the motor-driven cart's position.
POSITION_COLUMNS = ("plant.cart_position", "plant.active_cart_position")
ANGLE_COLUMNS = ("plant.pendulum_angle",)
REFERENCE_COLUMNS = ("setpoint.reference", "controller.reference")
VOLTAGE_COLUMNS = ("controller.voltage", "plant.voltage")


#: |angle| limit of the task [rad] (about 20 degrees, the lab software's pendulum limit).
UPRIGHT_LIMIT_RAD = 0.35
#: Half-width of the settling band as a fraction of the step.
SETTLING_BAND = 0.02
#: Fraction of the run (at its end) over which the steady-state error is averaged.
STEADY_STATE_FRACTION = 0.10

#: The residual oscillation over the final window (:func:`residual_metrics`): each measured signal's mean
#: error, peak-to-peak amplitude and dominant frequency, the motor cart's time in the band, and the verdict.
RESIDUAL_KEYS = ("residual_window_s", "cart_mean_error_m", "cart_peak_to_peak_m", "cart_frequency_Hz",
                 "cart_time_in_band", "angle_mean_rad", "angle_peak_to_peak_rad", "angle_frequency_Hz",
                 "limit_cycle")
#: The passive cart's residual keys, present only with a double-mass plant (its ``passive_cart_position``).
PASSIVE_RESIDUAL_KEYS = ("passive_cart_mean_error_m", "passive_cart_peak_to_peak_m", "passive_cart_frequency_Hz")
METRIC_KEYS = ("settling_time_s", "overshoot_m", "steady_state_error_m", "max_abs_angle_rad",
               "peak_voltage_V", "rms_voltage_V", "upright") + RESIDUAL_KEYS
#: The metrics of each task beyond the step (:func:`tasks_of`), present only in runs that do it.
TASK_METRICS = {"swing-up": ("time_to_upright_s", "track_used_m"),
                "tap": ("peak_angle_after_tap_rad", "recovery_time_s")}
#: The passive cart's reading (double mass): its residual oscillation is measured too.
PASSIVE_COLUMNS = ("plant.passive_cart_position",)
#: Longest final window the residual oscillation is measured over [s]; a run shorter than twice it uses its
#: final half.
RESIDUAL_WINDOW_S = 5.0
#: A signal hunts when its residual peak-to-peak amplitude exceeds this many counts of its encoder
#: (``ipcosim.fmus.instruments``: 2.275e-5 m of a cart, 1.534e-3 rad of the pendulum) -- what a lab's
#: encoders resolve, on the ideal plant as on the lab one.
LIMIT_CYCLE_COUNTS = 4
#: Zero-padding of the window's spectrum: to the power of two at or above this many times its length (the
#: dominant frequency's grid is at most 1 / (this x window)).
SPECTRUM_PADDING = 8
#: Plant parameters whose non-zero value makes a run a tap run.
TAP_PARAMETERS = ("tap_force_impulse", "tap_torque_impulse")


def tasks_of(plant_start: Callable[[str], Any]) -> frozenset[str]:
    """The tasks a run does beyond the step (keys of :data:`TASK_METRICS`), from its plant's start values.

    Parameters
    ----------
    plant_start : callable
        ``plant_start(name)`` -> the plant parameter's value in this run (None if it has none).

    Returns
    -------
    frozenset of str
        ``"tap"`` if a tap impulse is set, ``"swing-up"`` if the pendulum starts outside the
        upright limit; empty for a plain step run.
    """
    tasks = set()
    if any(float(plant_start(name) or 0.0) != 0.0 for name in TAP_PARAMETERS):
        tasks.add("tap")
    if abs(float(wrapped(float(plant_start("initial_pendulum_angle") or 0.0)))) >= UPRIGHT_LIMIT_RAD:
        tasks.add("swing-up")
    return frozenset(tasks)


def _of_tasks(metrics: dict[str, Any], tasks: Iterable[str]) -> dict[str, Any]:
    """``metrics`` without the metrics of the tasks not in ``tasks``."""
    keep = {key for task in tasks for key in TASK_METRICS.get(task, ())}
    return {k: v for k, v in metrics.items() if k in keep or not any(k in keys for keys in TASK_METRICS.values())}


class MetricsError(IpcosimError, ValueError):
    """The signals handed to ``compute_metrics`` do not describe one run (lengths, shape, time order)."""


def _as_1d(name: str, values: Any, n: int | None) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise MetricsError(f"metrics: signal {name} must be 1-D, got shape {arr.shape}")
    if n is not None and arr.size != n:
        raise MetricsError(f"metrics: signal {name} has {arr.size} samples, time has {n}")
    return arr


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
    return _step_task(_one_chunk(time=t, x=x, r=r, th=th, v=v), "x", "th", "r", "v")


def settling_time(time: Any, position: Any, reference: Any, band: float = SETTLING_BAND) -> float | None:
    """``settling_time_s`` of the module docstring with a band of ``+- band * |step|``: from the last
    change of the reference before the cart's last entry into the band to that entry [s]; None if
    the run ends outside the band, the step is zero or a sample is not finite."""
    t = _as_1d("time", time, None)
    x, r = _as_1d("position", position, t.size), _as_1d("reference", reference, t.size)
    if t.size < 2 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(r))):
        return None
    rows = _one_chunk(time=t, x=x, r=r)
    return _step_metrics(rows, _ends(t, x, r), "x", "r", band, STEADY_STATE_FRACTION)["settling_time_s"]


def steady_state_start(t0: float, t_end: float, fraction: float = STEADY_STATE_FRACTION) -> float:
    """The time from which on the steady-state error is averaged: the final ``fraction`` of the run."""
    return t_end - fraction * (t_end - t0)


def steady_state_error(time: Any, position: Any, reference: Any, fraction: float = STEADY_STATE_FRACTION) -> float:
    """``steady_state_error_m`` of the module docstring over the final ``fraction`` of the run [m]."""
    t = _as_1d("time", time, None)
    x, r = _as_1d("position", position, t.size), _as_1d("reference", reference, t.size)
    rows = _one_chunk(time=t, x=x, r=r)
    return _step_metrics(rows, _ends(t, x, r), "x", "r", SETTLING_BAND, fraction)["steady_state_error_m"]


def _one_chunk(**columns: np.ndarray) -> Callable[[], list[np.ndarray]]:
    """Arrays of one length as the chunks of one structured array (the streamed passes' input)."""
    rows = np.empty(len(next(iter(columns.values()))), dtype=[(k, "f8") for k in columns])
    for k, v in columns.items():
        rows[k] = v
    return lambda: [rows]


def _ends(t: np.ndarray, x: np.ndarray, r: np.ndarray) -> dict[str, float]:
    return {"t0": float(t[0]), "x0": float(x[0]), "t_end": float(t[-1]), "r_final": float(r[-1])}


def wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi) (upright = 0; a swing-up's angle starts at pi)."""
    return (np.asarray(angle, dtype=float) + math.pi) % (2 * math.pi) - math.pi


def upright_metrics(time: Any, position: Any, angle: Any) -> dict[str, Any]:
    """Metrics of a run that need not start upright (a swing-up): ``time_to_upright_s`` (from which
    on ``|wrapped angle| < UPRIGHT_LIMIT_RAD`` to the end of the run; None if it does not end
    upright) and ``track_used_m`` (largest ``|position|`` of the motor-driven cart), with the
    :func:`tap_metrics`."""
    t = _as_1d("time", time, None)
    return _upright_pass(_one_chunk(time=t, x=_as_1d("position", position, t.size),
                                    th=_as_1d("angle", angle, t.size)), "x", "th")


#: Band the pendulum must re-enter (and stay in) after a tap to count as recovered [rad].
RECOVERY_BAND_RAD = 0.01


def tap_metrics(time: Any, angle: Any) -> dict[str, Any]:
    """``peak_angle_after_tap_rad`` (largest ``|angle|`` from the instant the angle first leaves its
    initial value by more than 1e-6 rad: the tap, for a pendulum at rest upright) and
    ``recovery_time_s`` (from that instant until ``|angle|`` is inside +-RECOVERY_BAND_RAD for
    good; None if it ends outside). Both None when the angle never moves. On a step-task run they
    describe the step's angle excursion instead."""
    t = _as_1d("time", time, None)
    m = _upright_pass(_one_chunk(time=t, x=np.zeros(t.size), th=_as_1d("angle", angle, t.size)), "x", "th")
    return {k: m[k] for k in ("peak_angle_after_tap_rad", "recovery_time_s")}


def residual_window(t0: float, t_end: float) -> float:
    """Length of the final window of a run from ``t0`` to ``t_end`` [s]: ``RESIDUAL_WINDOW_S``, at most half the run."""
    return min(RESIDUAL_WINDOW_S, 0.5 * (t_end - t0))


def _hunting_threshold(what: str) -> float:
    from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT

    return LIMIT_CYCLE_COUNTS * (PENDULUM_RAD_PER_COUNT if what == "angle" else CART_M_PER_COUNT)


def oscillation(time: Any, signal: Any) -> tuple[float, float | None, bool]:
    """The residual oscillation of one signal over a window: ``(peak-to-peak, dominant frequency, persists)``.

    The peak-to-peak amplitude is ``max - min`` over the window; the dominant frequency is the highest peak
    above 0 Hz of the Hann-windowed spectrum of the signal minus its mean (None for a constant signal; a slow
    drift shows as a peak below two periods per window); it *persists* when the second half of the window
    still swings at least half as far as the first half (a decaying transient does not).
    """
    t, y = np.asarray(time, float), np.asarray(signal, float)
    if t.size < 4 or t[-1] <= t[0]:
        return 0.0, None, False
    residual = y - np.mean(y)
    p2p = float(np.max(residual) - np.min(residual))
    half = t.size // 2
    persists = bool(np.ptp(residual[half:]) >= 0.5 * np.ptp(residual[:half]))
    if p2p <= 0.0:
        return 0.0, None, False
    dt = float(t[-1] - t[0]) / (t.size - 1)
    n = 1 << (SPECTRUM_PADDING * t.size - 1).bit_length()  # a power of two: a window of 5001 samples has a
    # prime factor 1667, whose transform took 7 ms a signal (the sweep's metrics, run after run)
    power = np.abs(np.fft.rfft(residual * np.hanning(t.size), n)) ** 2
    return p2p, float((np.argmax(power[1:]) + 1) / (n * dt)), persists


def _hunts(what: str, p2p: float, freq: float | None, persists: bool, window: float) -> bool:
    """A limit cycle of one signal: amplitude above ``LIMIT_CYCLE_COUNTS`` encoder counts, at least two periods
    of its dominant frequency in the window, and not dying out within it."""
    return bool(persists and freq is not None and freq * window >= 2.0 and p2p > _hunting_threshold(what))


def residual_metrics(time: Any, position: Any, reference: Any, angle: Any, passive_position: Any = None,
                     x0: float | None = None) -> dict[str, Any]:
    """The residual oscillation at the end of a run (``docs/metrics.md``, "The residual oscillation").

    Over the final window (:func:`residual_window`): for the motor-driven cart, the passive cart (double
    mass) and the pendulum, the mean error (position minus reference, or the angle), the peak-to-peak amplitude
    and the dominant frequency of :func:`oscillation`; the fraction of the window the motor cart spends in the
    +-2 % settling band; and ``limit_cycle``: True when any of the three hunts (:func:`_hunts`).

    Parameters
    ----------
    time, position, reference, angle : array_like, shape (n,)
        The whole run (the readings as the encoders give them).
    passive_position : array_like, optional
        The passive cart's position (double mass).
    x0 : float, optional
        The initial motor-cart position (default ``position[0]``): the step is ``reference[-1] - x0``.
    """
    t = _as_1d("time", time, None)
    cols = {"time": t, "x": _as_1d("position", position, t.size), "r": _as_1d("reference", reference, t.size),
            "th": _as_1d("angle", angle, t.size)}
    if passive_position is not None:
        cols["x2"] = _as_1d("passive_position", passive_position, t.size)
    ends = {"t0": float(t[0]), "t_end": float(t[-1]), "r_final": float(cols["r"][-1]),
            "x0": float(cols["x"][0] if x0 is None else x0)}
    return _residual_pass(_one_chunk(**cols), ends, "x", "th", "r", "x2" if passive_position is not None else None)


def _residual_pass(chunks: Callable[[], Iterable[np.ndarray]], a: Mapping[str, Any], pos: str, ang: str, ref: str,
                   passive: str | None) -> dict[str, Any]:
    """:func:`residual_metrics` from the rows, once their ends ``a`` are known (one pass, keeping the window)."""
    window = residual_window(a["t0"], a["t_end"])
    names = [("cart", pos), ("angle", ang)] + ([("passive_cart", passive)] if passive else [])
    kept: dict[str, list[np.ndarray]] = {k: [] for k in ("time", pos, ang, ref, *([passive] if passive else []))}
    for c in chunks():
        if not len(c):
            continue
        tail = np.asarray(c["time"], float) >= a["t_end"] - window
        for k in kept:
            kept[k].append(np.asarray(c[k], float)[tail])
    w = {k: np.concatenate(v) if v else np.zeros(0) for k, v in kept.items()}
    out: dict[str, Any] = {"residual_window_s": window}
    hunting = False
    for what, col in names:
        err = w[col] if what == "angle" else w[col] - w[ref]
        p2p, freq, persists = oscillation(w["time"], w[col])
        unit = "rad" if what == "angle" else "m"
        out[f"{what}_mean_{'rad' if what == 'angle' else 'error_m'}"] = float(np.mean(err)) if err.size else None
        out[f"{what}_peak_to_peak_{unit}"] = p2p
        out[f"{what}_frequency_Hz"] = freq
        hunting |= _hunts(what, p2p, freq, persists, window)
    step = a["r_final"] - a["x0"]
    inside = np.abs(w[pos] - a["r_final"]) <= SETTLING_BAND * abs(step)
    out["cart_time_in_band"] = float(np.mean(inside)) if step != 0.0 and inside.size else None
    out["limit_cycle"] = hunting
    return out


def first_column(columns: Sequence[str], candidates: Sequence[str]) -> str | None:
    for c in candidates:
        if c in columns:
            return c
    return None


def task_metrics(data: np.ndarray, tasks: Iterable[str] = ()) -> dict[str, Any]:
    """The metrics of a pendulum run (:func:`compute_metrics`, and the metrics of its ``tasks``,
    :data:`TASK_METRICS`), from the plant's motor-cart position and angle, the reference and the
    controller's voltage; an empty dict when the result lacks those columns or has fewer than two rows."""
    return streamed_task_metrics(lambda: [data], list(data.dtype.names or ()), tasks)


def streamed_task_metrics(chunks: Callable[[], Iterable[np.ndarray]], columns: Sequence[str],
                          tasks: Iterable[str] = ()) -> dict[str, Any]:
    """:func:`task_metrics` computed in two passes over the rows, a chunk at a time, so that
    the metrics of a run of any length need no more memory than one chunk.

    Parameters
    ----------
    chunks : callable
        ``chunks()`` -> iterable of structured arrays (consecutive rows; called twice).
    columns : sequence of str
        The field names.
    tasks : iterable of str
        The run's tasks beyond the step (:func:`tasks_of`): their metrics are included.

    Returns
    -------
    dict
        The same keys and values as :func:`task_metrics` on the whole arrays
        (``compute_metrics`` and ``upright_metrics``; an empty dict when the columns are
        missing or there are < 2 rows).
    """
    pos, ang = first_column(columns, POSITION_COLUMNS), first_column(columns, ANGLE_COLUMNS)
    ref, volt = first_column(columns, REFERENCE_COLUMNS), first_column(columns, VOLTAGE_COLUMNS)
    if None in (pos, ang, ref, volt):
        return {}
    result = _step_task(chunks, pos, ang, ref, volt, first_column(columns, PASSIVE_COLUMNS))
    tasks = set(tasks)
    if result and tasks:  # the task metrics' pass only where they are reported
        result.update(_upright_pass(chunks, pos, ang))
    return _of_tasks(result, tasks)


def _step_task(chunks: Callable[[], Iterable[np.ndarray]], pos: str, ang: str, ref: str, volt: str,
               passive: str | None = None) -> dict[str, Any]:
    """The :data:`METRIC_KEYS` from the rows (empty for fewer than two rows); the one implementation
    behind :func:`compute_metrics`, :func:`task_metrics` and :func:`streamed_task_metrics`."""
    a = _first_pass(chunks, pos, ang, ref, volt)
    if a["n"] < 2:
        return {}
    if not a["t_ok"]:
        raise MetricsError("metrics: time must be finite and strictly increasing")
    result: dict[str, Any] = {
        "settling_time_s": None, "overshoot_m": None, "steady_state_error_m": None,
        "max_abs_angle_rad": a["max_angle"] if a["th_finite"] else None,
        "peak_voltage_V": a["peak_v"] if a["v_finite"] else None,
        "rms_voltage_V": math.sqrt(a["sum_v2"] / a["n"]) if a["v_finite"] else None,
        "upright": bool(a["finite"] and a["max_angle"] < UPRIGHT_LIMIT_RAD)}
    if a["finite"]:
        result.update(_step_metrics(chunks, a, pos, ref, SETTLING_BAND, STEADY_STATE_FRACTION))
    if not result["upright"]:  # a pendulum that fell has not settled, wherever its cart came to rest
        result["settling_time_s"] = None
    if a["finite"] and result["upright"]:
        result.update(_residual_pass(chunks, a, pos, ang, ref, passive))
    else:  # a fallen or diverged loop has no residual oscillation to speak of
        result.update({k: None for k in RESIDUAL_KEYS + (PASSIVE_RESIDUAL_KEYS if passive else ())})
    return result


def _first_pass(chunks: Callable[[], Iterable[np.ndarray]], pos: str, ang: str, ref: str, volt: str) -> dict[str, Any]:
    """Counts, finiteness, extremes, the first and last samples."""
    a: dict[str, Any] = {"n": 0, "t_ok": True, "th_finite": True, "v_finite": True, "finite": True,
                         "max_angle": 0.0, "peak_v": 0.0, "sum_v2": 0.0, "t_prev": None}
    for c in chunks():
        if not len(c):
            continue
        t, x, r, th, v = (np.asarray(c[k], float) for k in ("time", pos, ref, ang, volt))
        if a["n"] == 0:
            a["t0"], a["x0"] = float(t[0]), float(x[0])
        prev = a["t_prev"]
        a["t_ok"] &= bool(np.all(np.isfinite(t)) and np.all(np.diff(t) > 0) and (prev is None or t[0] > prev))
        a["t_prev"], a["t_end"], a["r_final"] = float(t[-1]), float(t[-1]), float(r[-1])
        a["th_finite"] &= bool(np.all(np.isfinite(th)))
        a["v_finite"] &= bool(np.all(np.isfinite(v)))
        a["finite"] &= bool(np.all(np.isfinite(x)) and np.all(np.isfinite(r)))
        if a["th_finite"]:
            a["max_angle"] = max(a["max_angle"], float(np.max(np.abs(th))))
        if a["v_finite"]:
            a["peak_v"] = max(a["peak_v"], float(np.max(np.abs(v))))
            a["sum_v2"] += float(np.sum(v * v))
        a["n"] += len(c)
    a["finite"] = a["finite"] and a["th_finite"] and a["v_finite"]
    if not a["th_finite"]:
        a["max_angle"] = math.inf
    return a


def _step_metrics(chunks: Callable[[], Iterable[np.ndarray]], a: dict[str, Any], pos: str, ref: str,
                  band_fraction: float, tail_fraction: float) -> dict[str, Any]:
    """Overshoot, steady-state error and settling time of finite rows, once their ends ``a`` are known
    (``t0``, ``x0``, ``t_end``, ``r_final``)."""
    r_final, step = a["r_final"], a["r_final"] - a["x0"]
    direction = 1.0 if step >= 0 else -1.0
    band = band_fraction * abs(step)
    t_start = steady_state_start(a["t0"], a["t_end"], tail_fraction)
    over, tail_sum, tail_n = -math.inf, 0.0, 0
    last_out, last_outside = -1, False      # index of the last sample outside the band
    last_change_t = a["t0"]                 # time of the last reference change seen so far
    t_ref_at_entry = a["t0"]                # time of the last change at or before the entry
    first, r_prev = 0, None
    for c in chunks():
        if not len(c):
            continue
        t, x, r = (np.asarray(c[k], float) for k in ("time", pos, ref))
        over = max(over, float(np.max(direction * (x - r_final))))
        tail = t >= t_start
        tail_sum += float(np.sum(x[tail] - r[tail]))
        tail_n += int(tail.sum())
        prev = np.concatenate(([r[0] if r_prev is None else r_prev], r[:-1]))
        changes = np.flatnonzero(r != prev)
        outside = np.abs(x - r_final) > band
        out_idx = np.flatnonzero(outside)
        if out_idx.size:  # entry candidate: the sample after the last outside one
            last_out = first + int(out_idx[-1])
            entry_local = int(out_idx[-1]) + 1
            before = changes[changes <= entry_local]
            t_ref_at_entry = float(t[before[-1]]) if before.size else last_change_t
            if entry_local == len(c):  # the entry sample is in the next chunk: its change counts too
                t_ref_at_entry = None
        elif t_ref_at_entry is None:  # entry was the first sample of this chunk
            t_ref_at_entry = float(t[0]) if changes.size and changes[0] == 0 else last_change_t
        if changes.size:
            last_change_t = float(t[changes[-1]])
        last_outside = bool(outside[-1])
        r_prev = float(r[-1])
        first += len(c)
    out: dict[str, Any] = {"overshoot_m": max(0.0, over), "steady_state_error_m": abs(tail_sum / tail_n)}
    if step != 0.0 and not last_outside:
        entry_t = _time_of_row(chunks, last_out + 1)
        out["settling_time_s"] = float(entry_t - (t_ref_at_entry if t_ref_at_entry is not None else last_change_t))
    else:
        out["settling_time_s"] = None
    return out


class _LastRow:
    """The last row (absolute number) where a condition held, and the time of the row after it."""

    def __init__(self) -> None:
        self.row, self.t_after, self.pending = -1, None, False

    def see(self, first: int, t: np.ndarray, mask: np.ndarray) -> None:
        if self.pending and len(t):
            self.t_after, self.pending = float(t[0]), False
        hits = np.flatnonzero(mask)
        if hits.size:
            k = int(hits[-1])
            self.row = first + k
            self.pending = k + 1 == len(t)
            self.t_after = None if self.pending else float(t[k + 1])


def _upright_pass(chunks: Callable[[], Iterable[np.ndarray]], pos: str, ang: str) -> dict[str, Any]:
    """:func:`upright_metrics` (time to upright, track used, the tap
    metrics) in one pass over the rows."""
    down, outside = _LastRow(), _LastRow()   # |angle| not below the limit; outside the recovery band
    n, t0, th0, k0, t_k0 = 0, None, None, None, None
    x_finite, th_finite, track, peak = True, True, 0.0, 0.0
    for c in chunks():
        if not len(c):
            continue
        t, x = np.asarray(c["time"], float), np.asarray(c[pos], float)
        th = wrapped(np.asarray(c[ang], float))
        if t0 is None:
            t0, th0 = float(t[0]), float(th[0])
        x_finite &= bool(np.all(np.isfinite(x)))
        th_finite &= bool(np.all(np.isfinite(th)))
        if x_finite:
            track = max(track, float(np.max(np.abs(x))))
        down.see(n, t, ~(np.abs(th) < UPRIGHT_LIMIT_RAD))
        start = 0
        if k0 is None:
            moved = np.flatnonzero(np.abs(th - th0) > 1e-6)
            if moved.size:
                start = int(moved[0])
                k0, t_k0 = n + start, float(t[start])
        if k0 is not None and th_finite:
            rest = np.abs(th[start:])
            peak = max(peak, float(np.max(rest)))
            outside.see(n + start, t[start:], rest >= RECOVERY_BAND_RAD)
        n += len(c)
    t_up = t0 if down.row < 0 else (None if down.row == n - 1 else down.t_after)
    out: dict[str, Any] = {"time_to_upright_s": t_up, "track_used_m": track if x_finite else None}
    if k0 is None or not th_finite:
        out.update(peak_angle_after_tap_rad=None, recovery_time_s=None)
        return out
    rec = 0.0 if outside.row < 0 else (None if outside.row == n - 1 else outside.t_after - t_k0)
    out.update(peak_angle_after_tap_rad=peak, recovery_time_s=rec)
    return out


def _time_of_row(chunks: Callable[[], Iterable[np.ndarray]], row: int) -> float:
    first = 0
    for c in chunks():
        if row < first + len(c):
            return float(c["time"][row - first])
        first += len(c)
    raise IndexError(row)
