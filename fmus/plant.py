"""Stateful plant model: the one stepping object behind the plant FMUs and the virtual rig."""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable, Sequence

from ipcosim.errors import IpcosimError
from ipcosim.fmus import kinds
from ipcosim.fmus.instruments import (
    Instruments,
    Readout,
    delay_line,
    delay_steps,
    quantize,
    stop_carts,
    tap_velocity_change,
)
from ipcosim.fmus.integrator import FastETDRK4, shared_etdrk4
from ipcosim.fmus.params import PlantParams, validate
from ipcosim.fmus.physics import MEASURED


class PlantStepError(IpcosimError, FloatingPointError):
    """The plant state became non-finite during a step (reported with time and state)."""


#: (position, velocity) state indices of each cart, per plant kind (``ipcosim.fmus.kinds``).
CARTS = kinds.ByKind(lambda k: k.cart_indices)


def coulomb_forces(p: PlantParams) -> tuple[float, ...]:
    """The Coulomb (breakaway) force of each cart [N], ``CARTS`` order."""
    return kinds.of_params(p).coulomb_forces(p)


def stick(before: Sequence[float], after: Sequence[float], p: PlantParams) -> tuple[list[float], float]:
    """``(state, number of carts stuck)`` at the end of a step: Karnopp's stick phase made exact.

    A cart with Coulomb friction whose velocity ended inside the stick band (or changed sign during the
    step) while the applied force at rest is within its breakaway force (``ipcosim.fmus.physics``) has
    stuck: its velocity is set to 0 and, if it was at rest at the start of the step, its position to
    the start's (a stuck cart does not move). Plain arithmetic and comparisons (the native plant traces it).
    """
    x = list(after)
    kind = kinds.of_params(p)
    band = p.coulomb_velocity
    stuck = 0.0
    for k, ((ip, iv), b) in enumerate(zip(kind.cart_indices, kind.coulomb_forces(p))):
        if not b:
            continue
        v0, v1 = before[iv], x[iv]
        if -band < v1 < band or v0 * v1 < 0.0:
            rest = list(x)
            rest[iv] = 0.0
            applied = kind.applied_forces(rest, p)[k]
            if -b <= applied <= b:
                rest[ip] = before[ip] if v0 == 0.0 else rest[ip]
                x = rest
                stuck = stuck + 1.0
    return x, stuck


def constrain(before: Sequence[float], after: Sequence[float], p: PlantParams, end_stop: float) -> list[float]:
    """``[*state, carts stuck, carts stopped]`` after a step's constraints: :func:`stick`, then the end stops
    (``ipcosim.fmus.instruments.stop_carts``)."""
    x, stuck = stick(before, after, p)
    x, stopped = stop_carts(x, kinds.of_params(p).cart_indices, end_stop)
    return [*x, stuck, stopped]


class Plant:
    """Nonlinear IP02 plant advanced in fixed steps with the voltage held over each step.

    The integrator is ETDRK4 (``ipcosim.fmus.integrator``) with the stiff linear part taken at the
    upright equilibrium -- the armature circuit's row and column of the Jacobian (:meth:`_circuit_part`)
    --, on an internal state in which the motor current enters the slow
    equations with constant coefficients: the momentum form ``[xc, p1, th, p2, i]`` for the
    single mass (``ipcosim.fmus.physics``), the plain state for the double mass (there the current
    drives only the active cart, whose mass matrix is constant).

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
        Physical parameters (validated on construction).
    x0 : sequence of float, optional
        Initial state in ``ipcosim.fmus.physics.state_names(kind)`` order; zeros by default.
    t0 : float
        Initial time [s].
    """

    def __init__(self, params: PlantParams, x0: Sequence[float] | None = None, t0: float = 0.0) -> None:
        self.params = validate(params)
        kind = kinds.of_params(params)
        self.kind = kind.name
        self.state_names = kind.states
        self._rhs = kind.rhs
        self._f = kind.folded_rhs(params)
        if kind.internal is not None:
            self._irhs = kind.internal.rhs
            self._to_int = kind.internal.to_internal
            self._out: Callable[[Sequence[float]], Sequence[float]] | None = kind.internal.output_map(params)
        else:
            self._out = None
            self._irhs = self._rhs
            self._to_int = lambda x, p: tuple(x)
        self._L = self._circuit_part(self._internal_jacobian())
        self._steppers: dict[float, FastETDRK4] = {}
        self._limit = params.voltage_limit
        self._amplifier_gain = params.amplifier_gain
        #: track end stops [m] (0 = none; set by ``InstrumentedPlant``)
        self.end_stop = 0.0
        self._friction = any(coulomb_forces(params))
        self.end_stop_hits = 0
        self.t = float(t0)
        self.voltage = 0.0
        self._xl: list[float] = [0.0] * len(self.state_names)
        self._z: list[float] = list(self._to_int(self._xl, params))
        if x0 is not None:
            self.set_state(x0)

    def set_state(self, x: Sequence[float]) -> None:
        """Replace the state vector (checked for length and finiteness)."""
        try:
            values = [float(v) for v in x]
        except (TypeError, ValueError):
            raise ValueError(f"{self.kind} state must be a sequence of numbers, got {x!r}") from None
        if len(values) != len(self.state_names):
            raise ValueError(f"{self.kind} state needs {len(self.state_names)} values "
                             f"({', '.join(self.state_names)}), got {len(values)}")
        bad = [f"{n} = {v}" for n, v in zip(self.state_names, values) if not math.isfinite(v)]
        if bad:
            raise ValueError(f"initial state is not finite: {', '.join(bad)}")
        self._xl = values
        self._z = list(self._to_int(self._xl, self.params))

    @property
    def x(self) -> Any:
        """The state as a numpy array (a copy; for analysis code -- the FMUs use :attr:`state`,
        which needs no numpy)."""
        import numpy as np  # noqa: PLC0415 -- off the FMU runtime's path

        return np.array(self._xl)

    def do_step(self, t: float, h: float, voltage: float) -> None:
        """Advance from time ``t`` to ``t + h`` with ``voltage`` [V] held constant.

        Raises
        ------
        PlantStepError
            If the new state is not finite; the state is left at its value at ``t``.
        ValueError
            If ``h`` is not a positive finite number or ``voltage`` is not finite.
        """
        stepper = self._steppers.get(h)
        if stepper is None:
            if not (h > 0 and math.isfinite(h)):
                raise ValueError(f"step size h = {h} s must be positive and finite")
            stepper = self._steppers[h] = shared_etdrk4(self._L, h)
        if not math.isfinite(voltage):
            raise ValueError(f"input voltage = {voltage} V at t = {t} s is not finite")
        limit = self._limit
        vA = self._amplifier_gain * (limit if voltage > limit else (-limit if voltage < -limit else voltage))
        try:
            z = stepper.step(self._z, self._f, vA)
            x = z if self._out is None else self._out(z)
            finite = all(map(math.isfinite, x))
        except (ValueError, OverflowError, ZeroDivisionError):  # math.sin(inf), float overflow, ...
            finite = False
        if not finite:
            state = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.state_names, self._xl))
            raise PlantStepError(f"plant state became non-finite in the step from t = {t:.6g} s "
                                 f"(h = {h:g} s, voltage = {voltage:g} V); state at t: {state}")
        x = list(x)
        if self._friction or self.end_stop:
            *x, stuck, stopped = constrain(self._xl, x, self.params, self.end_stop)
            self.end_stop_hits += int(stopped)
            if stuck or stopped:
                z = list(self._to_int(x, self.params))
        self._z = z
        self._xl = x
        self.voltage = voltage
        self.t = t + h

    @property
    def state(self) -> list[float]:
        """The state as a list of floats (a copy), ``state_names`` order."""
        return list(self._xl)

    def snapshot(self) -> tuple:
        """Everything a step starts from; :meth:`restore` returns to it exactly (a step repeated from it
        gives the same numbers, which :meth:`set_state` does not promise: it rebuilds the internal state)."""
        return list(self._z), list(self._xl), self.t, self.voltage, self.end_stop_hits

    def restore(self, snap: tuple) -> None:
        """Return to a :meth:`snapshot`."""
        z, xl, self.t, self.voltage, self.end_stop_hits = snap
        self._z, self._xl = list(z), list(xl)

    def prepare_steps(self, sizes: Sequence[float], shared: dict | None = None) -> None:
        """Make the steppers of the step sizes ``sizes`` [s] now, not at their first step (each costs
        ~10 ms once). ``shared``: a dict in which plants of equal parameters keep one table of steppers."""
        if shared is not None:
            self._steppers = shared.setdefault(tuple(tuple(row) for row in self._L), self._steppers)
        for h in sizes:
            if h not in self._steppers:
                self._steppers[h] = shared_etdrk4(self._L, h)

    def _internal_jacobian(self, eps: float = 1e-6) -> list[list[float]]:
        """Jacobian of the internal right-hand side at the upright equilibrium (the stiff linear part)."""
        n = len(self.state_names)
        cols = []
        for j in range(n):
            dz = [0.0] * n
            dz[j] = eps
            fp = self._irhs(dz, 0.0, self.params)
            dz[j] = -eps
            fm = self._irhs(dz, 0.0, self.params)
            cols.append([(a - b) / (2 * eps) for a, b in zip(fp, fm)])
        return [list(row) for row in zip(*cols)]

    @staticmethod
    def _circuit_part(J: list[list[float]]) -> list[list[float]]:
        """The stiff linear part: the motor current's row and column of the Jacobian ``J`` (current last).

        The only stiff mode is the armature circuit's (-Ra/La); the mechanical eigenvalues are
        below ~20 rad/s (h |lambda| <= 0.02 at 1 ms), which the scheme's explicit part (RK4 where
        L vanishes) integrates to ~1e-7 m / 1e-6 rad over 2 s (measured: docs/plant.md, Integration). This
        sparse L makes most stage coefficients exact zeros: a step costs a third of the
        arithmetic of the full Jacobian's.
        """
        last = len(J) - 1
        return [[v if j == last or i == last else 0.0 for j, v in enumerate(row)] for i, row in enumerate(J)]

    def values(self) -> dict[str, float]:
        """Every state by name (SI units)."""
        return dict(zip(self.state_names, self._xl))

    def measured(self) -> tuple[float, ...]:
        """The encoder-measured positions (``ipcosim.fmus.physics.MEASURED``)."""
        v = self.values()
        return tuple(v[n] for n in MEASURED[self.kind])


def tapped_state(kind: str, x: Sequence[Any], p: PlantParams, force_impulse: Any, torque_impulse: Any) -> list[Any]:
    """State ``x`` after the taps: an impulse ``force_impulse`` [N s] on the cart carrying the pendulum (the
    double mass's passive cart) and ``torque_impulse`` [N m s] on the pendulum, as velocity jumps of the
    cart-pendulum mass matrix at the current angle (``ipcosim.fmus.instruments.tap_velocity_change``).
    Pure arithmetic: the native plant traces it too."""
    entry = kinds.get(kind)
    names = entry.states
    th = x[names.index("pendulum_angle")]
    dv, dw = tap_velocity_change(entry.pendulum_mass_matrix(th, p), force_impulse, torque_impulse)
    out = list(x)
    out[names.index(entry.carts[-1].velocity)] += dv
    out[names.index("pendulum_velocity")] += dw
    return out


class InstrumentedPlant(Plant):
    """``Plant`` with the bench's instruments (``ipcosim.fmus.instruments``): encoder quantization and
    seeded noise on the measured positions (``readings``), track end stops applied after each step, the
    DAC's quantization and the computation delay of the voltage, and taps.

    With ``Instruments()`` (the default, everything off) it behaves exactly as ``Plant`` and its
    readings are the true positions.
    """

    def __init__(self, params: PlantParams, x0: Sequence[float] | None = None, t0: float = 0.0,
                 instruments: Instruments | None = None) -> None:
        super().__init__(params, x0, t0)
        self.instruments = instruments or Instruments()
        res = [self.instruments.pendulum_resolution if n == "pendulum_angle" else self.instruments.cart_resolution
               for n in MEASURED[self.kind]]
        self._readout = Readout(self.instruments, res)
        self.end_stop = self.instruments.end_stop
        self.tapped = False
        self._delayed: list[float] = []
        self.readings = self._readout.read(self.measured())

    def _tap(self, t: float, h: float) -> None:
        inst = self.instruments
        if self.tapped or not (inst.tap_force_impulse or inst.tap_torque_impulse) or t + h <= inst.tap_time:
            return
        self.tapped = True
        self.set_state(tapped_state(self.kind, self._xl, self.params, inst.tap_force_impulse, inst.tap_torque_impulse))

    def _delay(self, h: float, voltage: float) -> float:
        """The DAC's code of ``voltage``, delayed by the computation delay (``delay_line``)."""
        inst = self.instruments
        voltage = quantize(voltage, inst.voltage_resolution)
        if not inst.input_delay:
            return voltage
        n = delay_steps(inst.input_delay, h)
        if len(self._delayed) < n:
            self._delayed = [0.0] * int(n)
        out, self._delayed = delay_line(self._delayed, voltage, n)
        return out

    def do_step(self, t: float, h: float, voltage: float) -> None:
        """``Plant.do_step`` with the DAC's and the delayed voltage and the taps, then new readings."""
        self._tap(t, h)
        super().do_step(t, h, self._delay(h, voltage))
        self.readings = self._readout.read(self.measured())


def replay(params: PlantParams, voltages: Sequence[float], h: float, x0: Sequence[float] | None = None,
           instruments: Instruments | None = None) -> list[tuple[float, ...]]:
    """The measured positions (``MEASURED`` order, true values before the encoders) of the plant
    driven by a logged voltage: the one simulation behind identification.

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
    voltages : sequence of float
        The voltage [V] held over each step: ``voltages[k]`` from ``k h`` to ``(k + 1) h``.
    h : float
        Step [s].
    x0 : sequence of float, optional
        Initial state (``state_names`` order).
    instruments : Instruments, optional
        The bench between the command and the motion (input delay, end stops...); its encoder
        readout (resolutions, noise) is left out: the result is what the encoders look at.

    Returns
    -------
    list of tuple
        ``len(voltages) + 1`` rows: the start, then the positions after each step.
    """
    bench = replace(instruments or Instruments(), cart_resolution=0.0, pendulum_resolution=0.0, noise_counts=0.0)
    plant = InstrumentedPlant(params, x0, instruments=bench)
    rows = [plant.measured()]
    for k, v in enumerate(voltages):
        plant.do_step(k * h, h, v)
        rows.append(plant.measured())
    return rows
