"""Closed loop without the master: the nonlinear plant and a discrete law in one pure loop.

The plant (``ipcosim.fmus.plant.Plant``) advances in steps of ``plant_step`` (1 ms) with the voltage held;
the law runs at its own ``sample_period`` (an integer multiple of ``plant_step``) and its output
is held in between (zero-order hold). At each sample instant the law reads the measured
positions and the reference *at that instant* (zero-delay sampling, the same order the master
uses: setpoint, plant, controller). Time is integer ticks, never accumulated.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ipcosim.controllers.laws import DiscreteLaw
from ipcosim.errors import IpcosimError
from ipcosim.fmus.metrics import compute_metrics
from ipcosim.fmus.params import PlantParams
from ipcosim.fmus.physics import MEASURED, MOTOR_CART
from ipcosim.fmus.plant import Plant, PlantStepError


class LoopError(IpcosimError, ValueError):
    """The loop's timing does not fit (sample period not a multiple of the plant step...)."""


def step_reference(amplitude: float = 0.05, step_time: float = 0.0) -> Callable[[float], float]:
    """``r(t) = amplitude`` for ``t >= step_time``, else 0 (the thesis's task: 0.05 m at t = 0)."""
    def r(t: float) -> float:
        return amplitude if t >= step_time - 1e-12 else 0.0
    return r


@dataclass
class LoopResult:
    """Recorded signals (one sample per plant step, including t = 0) and the run's metrics.

    ``voltage[i]`` is the command held over ``[time[i], time[i+1])`` (the last one repeats).
    ``failure`` is the plant's error message if the state diverged (the rest is NaN).
    """

    time: np.ndarray
    states: np.ndarray        # (n_samples, n_states) in ipcosim.fmus.physics order
    state_names: tuple[str, ...]
    reference: np.ndarray
    voltage: np.ndarray
    metrics: dict
    failure: str | None = None

    def signal(self, name: str) -> np.ndarray:
        """A state by name."""
        return self.states[:, self.state_names.index(name)]


#: Encoder resolutions of the IP02 (4096 counts/rev): cart 2.275e-5 m/count, pendulum 1.534e-3 rad/count.
ENCODER_RESOLUTION = {"cart_position": 2.275e-5, "active_cart_position": 2.275e-5,
                      "passive_cart_position": 2.275e-5, "pendulum_angle": 2 * 3.141592653589793 / 4096}


def run_loop(law: DiscreteLaw, params: PlantParams, stop_time: float = 10.0, plant_step: float = 1e-3,
             reference: Callable[[float], float] | float = 0.05, x0: Sequence[float] | None = None,
             quantize: bool = False) -> LoopResult:
    """Simulate the closed loop and compute its metrics (``ipcosim.fmus.metrics``).

    Parameters
    ----------
    law : DiscreteLaw
        A fresh (or reset) control law; it is reset here.
    params : PlantParams
        Plant parameters (the "true" plant; the law may have been designed for another).
    stop_time : float
        [s].
    plant_step : float
        Plant integration step and recording interval [s].
    reference : callable or float
        ``r(t)`` [m], or a constant.
    x0 : sequence of float, optional
        Initial plant state (``ipcosim.fmus.physics`` order); upright at rest at 0 by default.
    quantize : bool
        Round the measurements to whole encoder counts (``ENCODER_RESOLUTION``) before the law,
        as the rig's encoders do.

    Raises
    ------
    LoopError
        If ``law.sample_period`` is not an integer multiple of ``plant_step``.
    """
    ratio = law.sample_period / plant_step
    n_sub = int(round(ratio))
    if n_sub < 1 or abs(ratio - n_sub) > 1e-9 * max(1.0, ratio):
        raise LoopError(f"sample_period = {law.sample_period:g} s is not an integer multiple of the plant step "
                        f"{plant_step:g} s")
    n_steps = int(round(stop_time / plant_step))
    ref = reference if callable(reference) else (lambda t, c=float(reference): c)
    plant = Plant(params, x0=x0)
    law.reset()
    states, refs, volts, failure = _step_loop(plant, law, ref, n_steps, n_sub, plant_step, quantize)
    time = np.arange(n_steps + 1) * plant_step
    names = plant.state_names
    motor = states[:, MOTOR_CART[plant.kind]]
    angle = states[:, names.index("pendulum_angle")]
    metrics = compute_metrics(time, motor, refs, angle, volts)
    return LoopResult(time=time, states=states, state_names=tuple(names), reference=refs, voltage=volts,
                      metrics=metrics, failure=failure)


def _step_loop(plant: Plant, law: DiscreteLaw, ref: Callable[[float], float], n_steps: int, n_sub: int,
               plant_step: float, quantize: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, str | None]:
    """Step the plant ``n_steps`` times, the law every ``n_sub``-th step (its voltage held in
    between); returns the states, references and voltages at every step (NaN after a plant
    failure) and the failure's message (None)."""
    states = np.full((n_steps + 1, len(plant.state_names)), np.nan)
    refs = np.empty(n_steps + 1)
    volts = np.full(n_steps + 1, np.nan)
    u = 0.0
    res = np.array([ENCODER_RESOLUTION[n] for n in MEASURED[plant.kind]])
    for i in range(n_steps + 1):
        t = i * plant_step
        states[i] = plant.x
        refs[i] = ref(t)
        if i % n_sub == 0:
            y = np.asarray(plant.measured())
            u = law.step(np.round(y / res) * res if quantize else y, refs[i])
        volts[i] = u
        if i == n_steps:
            break
        try:
            plant.do_step(t, plant_step, u)
        except PlantStepError as exc:
            refs[i + 1:] = [ref((j) * plant_step) for j in range(i + 1, n_steps + 1)]
            return states, refs, volts, str(exc)
    return states, refs, volts, None


def measured_names(kind: str) -> tuple[str, ...]:
    """The plant's measured outputs, in the order laws expect them."""
    return MEASURED[kind]


def is_finite_run(result: LoopResult) -> bool:
    """True if every recorded sample is finite."""
    return result.failure is None and bool(np.all(np.isfinite(result.states)))


__all__ = ["LoopError", "LoopResult", "run_loop", "step_reference", "measured_names", "is_finite_run"]
