"""Reference signals of the ``Setpoint`` FMU and the pure loop (one definition for both)."""
from __future__ import annotations

import math

from ipcosim.controllers.errors import ControllerParameterError

#: ``waveform`` codes of the Setpoint FMU.
STEP, RAMP, SQUARE = 0, 1, 2
WAVEFORMS = {STEP: "step", RAMP: "ramp", SQUARE: "square"}


def check_reference(waveform: int, amplitude: float, step_time: float, offset: float, ramp_rate: float,
                    period: float) -> None:
    """Raise ControllerParameterError naming the first bad reference parameter."""
    if int(waveform) not in WAVEFORMS:
        raise ControllerParameterError("waveform", f"parameter waveform = {waveform}: must be 0 (step), 1 (ramp) "
                                                   "or 2 (square)")
    for name, value in (("amplitude", amplitude), ("step_time", step_time), ("offset", offset),
                        ("ramp_rate", ramp_rate), ("period", period)):
        if not math.isfinite(value):
            raise ControllerParameterError(name, f"parameter {name} = {value}: not a finite number")
    if int(waveform) == RAMP and ramp_rate <= 0:
        raise ControllerParameterError("ramp_rate", f"parameter ramp_rate = {ramp_rate} m/s: must be > 0 for a ramp")
    if int(waveform) == SQUARE and period <= 0:
        raise ControllerParameterError("period", f"parameter period = {period} s: must be > 0 for a square wave")


def reference_at(t: float, waveform: int = STEP, amplitude: float = 0.05, step_time: float = 0.0,
                 offset: float = 0.0, ramp_rate: float = 0.05, period: float = 4.0) -> float:
    """Reference position [m] at time ``t`` [s].

    * step: ``offset`` before ``step_time``, ``offset + amplitude`` from it on;
    * ramp: from ``step_time`` moves towards ``offset + amplitude`` at ``ramp_rate`` [m/s], then holds;
    * square: from ``step_time``, ``offset + amplitude`` for the first half of each ``period``
      and ``offset`` for the second half.
    """
    tau = t - step_time
    if tau < -1e-12:
        return offset
    if waveform == RAMP:
        return offset + math.copysign(min(abs(amplitude), ramp_rate * max(tau, 0.0)), amplitude)
    if waveform == SQUARE:
        phase = math.fmod(max(tau, 0.0), period)
        return offset + (amplitude if phase < 0.5 * period - 1e-12 else 0.0)
    return offset + amplitude
