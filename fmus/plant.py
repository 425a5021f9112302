"""Stateful plant model: the one stepping object behind the plant FMUs and the virtual rig."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .integrator import ETDRK4
from .params import PlantParams, kind_of, validate
from .physics import (MEASURED, clip_voltage, rhs_for, single_mass_from_momentum, single_mass_momentum_rhs,
                      single_mass_to_momentum, state_names)


class PlantStepError(FloatingPointError):
    """The plant state became non-finite during a step (reported with time and state)."""


class Plant:
    """Nonlinear IP02 plant advanced in fixed steps with the voltage held over each step.

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
        Physical parameters (validated on construction).
    x0 : sequence of float, optional
        Initial state in ``fmus.physics.state_names(kind)`` order; zeros by default.
    t0 : float
        Initial time [s].
    """

    def __init__(self, params: PlantParams, x0: Sequence[float] | None = None, t0: float = 0.0) -> None:
        self.params = validate(params)
        self.kind = kind_of(params)
        self.state_names = state_names(self.kind)
        self._rhs = rhs_for(params)
        # The integrator works on an internal state in which the stiff current enters the slow
        # equations with constant coefficients (see fmus.physics, momentum form).
        if self.kind == "single-mass":
            self._irhs = single_mass_momentum_rhs
            self._to_int = single_mass_to_momentum
            self._from_int = single_mass_from_momentum
        else:
            self._irhs = self._rhs
            self._to_int = self._from_int = lambda x, p: tuple(x)
        self._L = self._internal_jacobian()
        self._steppers: dict[float, ETDRK4] = {}
        self.t = float(t0)
        self.voltage = 0.0
        self.x = np.zeros(len(self.state_names))
        if x0 is not None:
            self.set_state(x0)

    def set_state(self, x: Sequence[float]) -> None:
        """Replace the state vector (checked for length and finiteness)."""
        x = np.asarray(x, dtype=float)
        if x.shape != (len(self.state_names),):
            raise ValueError(f"{self.kind} state needs {len(self.state_names)} values "
                             f"({', '.join(self.state_names)}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            bad = [n for n, v in zip(self.state_names, x) if not math.isfinite(v)]
            raise ValueError(f"initial state is not finite: {', '.join(bad)}")
        self.x = x.copy()

    def derivatives(self, voltage: float | None = None) -> tuple[float, ...]:
        """Right-hand side at the current state (for the voltage held now, or ``voltage``)."""
        return self._rhs(self.x.tolist(), self.voltage if voltage is None else voltage, self.params)

    def do_step(self, t: float, h: float, voltage: float) -> None:
        """Advance from time ``t`` to ``t + h`` with ``voltage`` [V] held constant.

        Raises
        ------
        PlantStepError
            If the new state is not finite; the state is left at its value at ``t``.
        ValueError
            If ``h`` is not a positive finite number or ``voltage`` is not finite.
        """
        if not (h > 0 and math.isfinite(h)):
            raise ValueError(f"step size h = {h} s must be positive and finite")
        if not math.isfinite(voltage):
            raise ValueError(f"input voltage = {voltage} V at t = {t} s is not finite")
        stepper = self._steppers.get(h)
        if stepper is None:
            stepper = self._steppers[h] = ETDRK4(self._L, h)
        rhs, p, L = self._irhs, self.params, self._L

        def nonlinear(z: np.ndarray) -> np.ndarray:
            return np.array(rhs(z.tolist(), voltage, p)) - L @ z

        z_new = stepper.step(np.array(self._to_int(self.x.tolist(), p)), nonlinear)
        x_new = np.array(self._from_int(z_new.tolist(), p))
        if not np.all(np.isfinite(x_new)):
            state = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.state_names, self.x))
            raise PlantStepError(f"plant state became non-finite in the step from t = {t:.6g} s "
                                 f"(h = {h:g} s, voltage = {voltage:g} V); state at t: {state}")
        self.x = x_new
        self.voltage = voltage
        self.t = t + h

    def _internal_jacobian(self, eps: float = 1e-6) -> np.ndarray:
        """Jacobian of the internal right-hand side at the upright equilibrium (the stiff linear part)."""
        n = len(self.state_names)
        L = np.empty((n, n))
        for j in range(n):
            dz = [0.0] * n
            dz[j] = eps
            fp = self._irhs(dz, 0.0, self.params)
            dz[j] = -eps
            fm = self._irhs(dz, 0.0, self.params)
            L[:, j] = [(a - b) / (2 * eps) for a, b in zip(fp, fm)]
        return L

    def applied_voltage(self) -> float:
        """Voltage after the amplifier's limit [V]."""
        return clip_voltage(self.voltage, self.params.voltage_limit)

    def values(self) -> dict[str, float]:
        """Every state by name (SI units)."""
        return dict(zip(self.state_names, self.x.tolist()))

    def measured(self) -> tuple[float, ...]:
        """The encoder-measured positions (``fmus.physics.MEASURED``)."""
        v = self.values()
        return tuple(v[n] for n in MEASURED[self.kind])
