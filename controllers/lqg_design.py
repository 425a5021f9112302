"""Discrete LQG design with integral action and the computation delay (``LQGSingleMass``, ``LQGDoubleMass``).

Regulator (linear quadratic with integral action, LQI). The design model (``design.design_model``:
upright linearization without the armature inductance, n states) is sampled with a zero-order
hold at the controller's period T (``Ad``, ``Bd``). The law needs one sample to compute: the
voltage it computes from the measurements of instant k is applied from instant k + 1 on (the
output the real rig's D/A writes at the next tick). Its design state is therefore augmented by the
voltage being applied ``v`` and by the integral ``q`` of the motor-cart position error::

    x[k+1] = Ad x[k] + Bd v[k]
    v[k+1] = u[k]                                  (one-sample computation delay)
    q[k+1] = q[k] + T (r - C1 x[k])                (integral action on the motor-cart position)

    u[k]   = -K (x^[k] - x_r r) - K_voltage v[k] - K_integral q[k]

with ``[K, K_voltage, K_integral]`` the discrete LQR gain (``design.lqr_gain``, discrete) of the augmented
model for the per-sample cost ``(x - x_r r)' Q (x - x_r r) + Q_integral q^2 + R u^2``. ``x_r``
holds 1 for every cart position and 0 otherwise (at rest both carts stand at the reference, the
pendulum upright, the voltage 0: viscous friction alone needs no holding voltage); the
integrator removes the error that Coulomb friction and model errors leave.

Estimator (steady-state Kalman filter, current form: the measurement of instant k corrects the
estimate used at instant k). Measurement noise: the encoders' quantization, a uniform error of one
count, variance ``resolution^2 / 12`` per output (cart 2.275e-5 m, pendulum 2 pi/4096 rad:
``ipcosim.fmus.instruments``). Process noise: a voltage-equivalent disturbance at the plant input,
piecewise constant over a sample (so it enters through ``Bd``), standard deviation
``process_noise`` [V]: what the design model leaves out acts there (Coulomb friction, 0.1 N =
0.06 V of motor force; the D/A's steps; +-20 % masses and dampings, which at the task's
accelerations are tenths of a volt). On the double mass the filter also needs an acceleration
disturbance on every body, ``acceleration_noise`` [m/s^2, rad/s^2 for the pendulum] held over a
sample (velocity increments of ``acceleration_noise T``): with noise at the motor input alone it
hardly corrects the spring-coupled passive cart, whose slow estimation error then turns the loop
unstable for a 20 % error in the spring or the passive cart's mass (the passive cart's friction and
the spring force's error, 20 % of 143 N/m over 0.05 m, are such accelerations; docs/controllers.md).
Putting the process noise at the plant input is also loop
transfer recovery at the plant input (Doyle & Stein, *IEEE TAC* 26, 1981; Maciejowski, *Automatica*
21, 1985, for the discrete current estimator): the larger ``process_noise`` against the encoder
noise, the closer the loop at the plant input comes to the full-state loop. The shipped sets take
a value that keeps most of the full-state margins while the encoder noise on the voltage stays
small (docs/controllers.md, "LQG")::

    P = Ad P Ad' - Ad P C'(C P C' + Rv)^-1 C P Ad' + process_noise^2 Bd Bd' + (acceleration_noise T)^2 Iv
    M = P C' (C P C' + Rv)^-1                      (x^ = x- + M (y - C x-))

By separation the closed loop's poles are those of the augmented regulator, ``eig(Phi - Gamma Ka)``,
and of the estimator, ``eig((I - M C) Ad)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import scipy.linalg

from ipcosim.controllers.design import BACKENDS, check_observable, check_weights, design_inputs, lqr_gain, zoh
from ipcosim.controllers.errors import DesignError
from ipcosim.controllers.laws.base import rest_state
from ipcosim.fmus.linearize import LinearModel


@dataclass(frozen=True)
class LQGDesign:
    """A discrete LQG design (see the module docstring).

    Attributes
    ----------
    model : LinearModel
        Continuous design model.
    sample_period : float
        T [s].
    Ad, Bd : ndarray
        Zero-order-hold model.
    Phi, Gamma : ndarray
        Augmented model ``[x, v, q]`` (n + 2 states).
    Q_augmented, R : ndarray
        Weights of the augmented regulator.
    K_augmented : ndarray (1, n + 2)
        ``[K, K_voltage, K_integral]``.
    M : ndarray (n, p)
        Current-estimator (Kalman) gain.
    P : ndarray (n, n)
        A-priori estimation error covariance.
    measurement_variance : ndarray (p,)
        ``resolution^2 / 12`` per output.
    process_noise : float
        Standard deviation of the input disturbance [V].
    reference_states : tuple of float
        ``x_r``: the state at rest per metre of reference.
    """

    model: LinearModel
    sample_period: float
    Ad: np.ndarray
    Bd: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    Q_augmented: np.ndarray
    R: np.ndarray
    K_augmented: np.ndarray
    M: np.ndarray
    P: np.ndarray
    measurement_variance: np.ndarray
    process_noise: float
    reference_states: tuple[float, ...]

    @property
    def regulator_poles(self) -> np.ndarray:
        """Poles (z) of the augmented state feedback, ``eig(Phi - Gamma Ka)``."""
        return np.linalg.eigvals(self.Phi - self.Gamma @ self.K_augmented)

    @property
    def estimator_poles(self) -> np.ndarray:
        """Poles (z) of the estimation error, ``eig((I - M C) Ad)``."""
        n = self.Ad.shape[0]
        return np.linalg.eigvals((np.eye(n) - self.M @ self.model.C) @ self.Ad)


def augmented_model(Ad: np.ndarray, Bd: np.ndarray, C1: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Gamma)`` of the state ``[x, v, q]``: the plant, the voltage being applied (one-sample
    computation delay) and the integral of the error ``r - C1 x`` (at r = 0)."""
    n = Ad.shape[0]
    Phi = np.zeros((n + 2, n + 2))
    Phi[:n, :n], Phi[:n, n] = Ad, Bd[:, 0]
    Phi[n + 1, :n], Phi[n + 1, n + 1] = -T * np.asarray(C1).reshape(n), 1.0
    Gamma = np.zeros((n + 2, 1))
    Gamma[n, 0] = 1.0
    return Phi, Gamma


def kalman_gain(Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, process_noise: float,
                measurement_variance: Sequence[float], backend: str = "control",
                velocity_noise: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state current-estimator gain ``M`` and a-priori covariance ``P`` for an input
    disturbance of standard deviation ``process_noise`` [V], independent per-sample increments of
    standard deviation ``velocity_noise`` on each state (0 for none) and independent measurement noises.

    Raises
    ------
    DesignError
        ``process_noise`` or a variance not positive and finite, or no stabilizing solution.
    """
    w = float(process_noise)
    if not (math.isfinite(w) and w > 0):
        raise DesignError("process_noise", f"process_noise = {w} V must be positive and finite")
    Rv = np.diag(np.asarray(measurement_variance, dtype=float))
    if not (np.all(np.isfinite(Rv)) and np.all(np.diag(Rv) > 0)):
        raise DesignError("resolution", "every measurement resolution must be positive and finite (the encoder "
                                        "noise variance is resolution^2/12)")
    check_observable(Ad, C)
    Qw = w * w * (Bd @ Bd.T) + np.diag(np.square(velocity_noise if velocity_noise is not None else 0.0 * Bd[:, 0]))
    try:
        if backend == "control":
            import control
            P = np.asarray(control.dare(Ad.T, C.T, Qw, Rv)[0], dtype=float)
        elif backend == "scipy":
            P = scipy.linalg.solve_discrete_are(Ad.T, C.T, Qw, Rv)
        else:
            raise DesignError("backend", f"unknown design backend {backend!r}; expected one of {BACKENDS}")
    except DesignError:
        raise
    except (ValueError, np.linalg.LinAlgError, ArithmeticError) as exc:
        raise DesignError("process_noise", f"the Kalman filter has no stabilizing solution: {exc}") from None
    M = P @ C.T @ np.linalg.inv(C @ P @ C.T + Rv)
    n = Ad.shape[0]
    if not np.all(np.isfinite(M)) or np.max(np.abs(np.linalg.eigvals((np.eye(n) - M @ C) @ Ad))) >= 1.0:
        raise DesignError("process_noise", "the Kalman filter is not stable for this process noise")
    return M, P


def design_lqg(model: LinearModel, Q: Any, q_integral: float, R: float, *, sample_period: float,
               resolutions: Sequence[float], process_noise: float, acceleration_noise: float = 0.0,
               backend: str = "control") -> LQGDesign:
    """Discrete LQG with integral action and a one-sample computation delay (module docstring).

    Parameters
    ----------
    model : LinearModel
        Continuous design model (``design.design_model(params)``); output row 0 is the motor cart.
    Q : array_like (n x n)
        State weight (positive semidefinite), on ``x - x_r r``.
    q_integral : float
        Weight on the integral of the motor-cart position error [1/(m^2 s^2)], > 0.
    R : float
        Voltage weight [1/V^2], > 0.
    sample_period : float
        T [s].
    resolutions : sequence of float
        Encoder resolution of each measured output (model.outputs order) [m or rad].
    process_noise : float
        Standard deviation of the voltage-equivalent input disturbance [V].
    acceleration_noise : float
        Standard deviation of an acceleration disturbance on every velocity state [m/s^2 or rad/s^2], >= 0.
    backend : {'control', 'scipy'}
        Riccati solvers: python-control's ``dlqr``/``dare`` or scipy's ``solve_discrete_are``.

    Raises
    ------
    DesignError
        With ``parameter`` naming the bad input.
    """
    T, A, B, C, n = design_inputs(model, sample_period, backend)
    Q, Rm = check_weights(Q, [[R]], n)
    qi = float(q_integral)
    if not (math.isfinite(qi) and qi > 0):
        raise DesignError("Q_integral", f"Q_integral = {qi} must be positive and finite (an unweighted integrator "
                                        "is not stabilized)")
    Ad, Bd = zoh(A, B, T, backend)
    Phi, Gamma = augmented_model(Ad, Bd, C[0], T)
    Qa = scipy.linalg.block_diag(Q, [[0.0]], [[qi]])
    Ka = lqr_gain(Phi, Gamma, Qa, Rm, backend, discrete=True)
    variance = np.array([float(r) ** 2 / 12.0 for r in resolutions])
    if variance.size != C.shape[0]:
        raise DesignError("resolution", f"need {C.shape[0]} resolutions ({', '.join(model.outputs)}), "
                                        f"got {variance.size}")
    a = float(acceleration_noise)
    if not (math.isfinite(a) and a >= 0):
        raise DesignError("acceleration_noise", f"acceleration_noise = {a} must be >= 0 and finite")
    velocity = [a * T if s.endswith("velocity") else 0.0 for s in model.states]
    M, P = kalman_gain(Ad, Bd, C, process_noise, variance, backend, velocity)
    return LQGDesign(model=model, sample_period=T, Ad=Ad, Bd=Bd, Phi=Phi, Gamma=Gamma, Q_augmented=Qa, R=Rm,
                     K_augmented=Ka, M=M, P=P, measurement_variance=variance, process_noise=float(process_noise),
                     reference_states=rest_state(model.states))
