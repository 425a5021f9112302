"""Closed loop without the master: the nonlinear plant and a discrete law in one pure loop.

The plant (``ipcosim.fmus.plant.Plant``) advances in steps of ``plant_step`` (1 ms) with the voltage held;
the law runs at its own ``sample_period`` (an integer multiple of ``plant_step``) and its output
is held in between (zero-order hold). At each sample instant the law reads the measured
positions and the reference *at that instant* (zero-delay sampling, the same order the master
uses: setpoint, plant, controller). Time is integer ticks, never accumulated.

This is the project's one pure closed loop: the controllers' tables and friction fit, the thesis's
claims (docs/results.md, through the bench's instruments) and the FMU-free study
stand-in (``ipcosim.harness.studies.runners.PurePlantSpec``, a state feedback that reads the true state and
stops integrating once the pendulum has fallen far) all run it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ipcosim.controllers.laws.base import DiscreteLaw
from ipcosim.errors import IpcosimError
from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT, Instruments
from ipcosim.fmus.metrics import compute_metrics
from ipcosim.fmus.params import PlantParams
from ipcosim.fmus.physics import MEASURED, MOTOR_CART
from ipcosim.fmus.plant import InstrumentedPlant, Plant, PlantStepError


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

    ``voltage[i]`` is the command held over ``[time[i], time[i+1])``; the last one is the law's output at
    the end instant when that is a sample instant (applied to no step), else the one held.
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


#: The IP02's encoders alone (4096 counts/rev: cart 2.275e-5 m/count, pendulum 1.534e-3 rad/count), what
#: ``run_loop(quantize=True)`` puts on the plant.
ENCODERS = Instruments(cart_resolution=CART_M_PER_COUNT, pendulum_resolution=PENDULUM_RAD_PER_COUNT)
#: What a law can be given at its sample instants: the measured positions (the instruments' readings when
#: the plant has instruments), or the plant's whole true state (a state-feedback stand-in).
OBSERVE = ("measured", "state")


def run_loop(law: DiscreteLaw, params: PlantParams, stop_time: float = 10.0, plant_step: float = 1e-3,
             reference: Callable[[float], float] | float = 0.05, x0: Sequence[float] | None = None,
             quantize: bool = False, instruments: Instruments | None = None, observe: str = "measured",
             hold_beyond: float | None = None) -> LoopResult:
    """Simulate the closed loop and compute its metrics (``ipcosim.fmus.metrics``).

    Parameters
    ----------
    law : DiscreteLaw
        A fresh (or reset) control law; it is reset here. Anything with ``sample_period``, ``reset()``
        and ``step(inputs, reference) -> voltage`` will do.
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
        Read the positions in whole encoder counts, as the rig's encoders do: the instruments
        ``ENCODERS`` (not with ``instruments``).
    instruments : Instruments, optional
        The bench's instruments on the plant (``ipcosim.fmus.plant.InstrumentedPlant``: encoder counts,
        noise, end stops, DAC, computation delay, taps); the law reads their readings.
    observe : {'measured', 'state'}
        What the law reads (``OBSERVE``): the measured positions, or the plant's whole true state.
    hold_beyond : float, optional
        Pendulum angle [rad]: once its magnitude exceeds this at a sample, the plant is no longer
        stepped and that sample (state, reference, voltage) is held to the end.

    Raises
    ------
    LoopError
        If ``law.sample_period`` is not an integer multiple of ``plant_step``, ``observe`` is unknown, or
        ``quantize`` comes with ``instruments``.
    """
    n_sub = substeps(law.sample_period, plant_step)
    if quantize:
        if instruments is not None:
            raise LoopError("quantize: the encoders are instruments; give their resolutions in instruments")
        instruments = ENCODERS
    n_steps = int(round(stop_time / plant_step))
    ref = reference if callable(reference) else (lambda t, c=float(reference): c)
    plant = Plant(params, x0=x0) if instruments is None else InstrumentedPlant(params, x0=x0, instruments=instruments)
    sense = _sensor(plant, observe)
    law.reset()
    states, refs, volts, failure = _step_loop(plant, law, ref, sense, n_steps, n_sub, plant_step, hold_beyond)
    time = np.arange(n_steps + 1) * plant_step
    names = plant.state_names
    motor = states[:, MOTOR_CART[plant.kind]]
    angle = states[:, names.index("pendulum_angle")]
    metrics = compute_metrics(time, motor, refs, angle, volts)
    return LoopResult(time=time, states=states, state_names=tuple(names), reference=refs, voltage=volts,
                      metrics=metrics, failure=failure)


def substeps(sample_period: float, plant_step: float) -> int:
    """Plant steps per sample of a law (``sample_period / plant_step``, a whole number).

    Raises
    ------
    LoopError
        If the sample period is not an integer multiple of the plant step.
    """
    ratio = sample_period / plant_step
    n_sub = int(round(ratio))
    if n_sub < 1 or abs(ratio - n_sub) > 1e-9 * max(1.0, ratio):
        raise LoopError(f"sample_period = {sample_period:g} s is not an integer multiple of the plant step "
                        f"{plant_step:g} s")
    return n_sub


def _sensor(plant: Plant, observe: str) -> Callable[[], Sequence[float]]:
    """What the law reads at a sample instant: the true state, the instruments' readings, or the measured
    positions."""
    if observe not in OBSERVE:
        raise LoopError(f"observe = {observe!r}: expected one of {', '.join(OBSERVE)}")
    if observe == "state":
        return lambda: plant.x
    if isinstance(plant, InstrumentedPlant):
        return lambda: plant.readings
    return lambda: np.asarray(plant.measured())


def _step_loop(plant: Plant, law: DiscreteLaw, ref: Callable[[float], float], sense: Callable[[], Sequence[float]],
               n_steps: int, n_sub: int, plant_step: float, hold_beyond: float | None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str | None]:
    """Step the plant ``n_steps`` times, the law every ``n_sub``-th step (its voltage held in
    between); returns the states, references and voltages at every step (NaN after a plant
    failure; the last sample repeated once the angle is beyond ``hold_beyond``) and the failure's
    message (None)."""
    states = np.full((n_steps + 1, len(plant.state_names)), np.nan)
    refs = np.empty(n_steps + 1)
    volts = np.full(n_steps + 1, np.nan)
    u = 0.0
    angle = plant.state_names.index("pendulum_angle")
    for i in range(n_steps + 1):
        t = i * plant_step
        states[i] = plant.x
        refs[i] = ref(t)
        if i % n_sub == 0:
            u = law.step(sense(), refs[i])
        volts[i] = u
        if i == n_steps:
            break
        if hold_beyond is not None and abs(states[i, angle]) > hold_beyond:
            states[i + 1:], refs[i + 1:], volts[i + 1:] = states[i], refs[i], u
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
