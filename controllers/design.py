"""Controller design from a plant's linearization: LQR gain, reference gain, Luenberger observer.

Two interchangeable back ends compute the same design:

* ``backend="control"`` (reference): python-control's ``control.lqr``, ``control.place``,
  ``control.ss`` and ``control.c2d``. Used by the analysis tools and the tests.
* ``backend="scipy"``: ``scipy.linalg.solve_continuous_are``, ``scipy.signal.place_poles`` and
  ``scipy.linalg.expm``. The controller FMUs redo the design with it in initialization mode
  (their runtime needs only numpy and scipy), so a weight changed through an FMU parameter
  gives the gains it implies. Both back ends agree to 1e-8 (docs/controllers.md).

The design model is the plant linearized about the upright equilibrium *without* the armature
inductance (current eliminated: the thesis's App. A.2 and B.3 models; the electrical pole at
-Ra/La ~ -14 400 rad/s is far outside every design bandwidth and would only make the observer
stiff). States in ``ipcosim.fmus.physics`` order without the current; outputs are the measured positions.

Design steps (thesis 3.2.2, 4.2.2, App. A.2, B.3)::

    K = R^-1 B' P,  A'P + PA - PBR^-1B'P + Q = 0        (continuous LQR, u = -K x + N r)
    N = -1 / (C1 (A - B K)^-1 B)                          (unit DC gain from r to the motor cart)
    L : eig(A - L C) = observer poles                     (continuous Luenberger observer)

Discretization for the controller's sample period T ("current estimator", Franklin, Powell &
Workman, *Digital Control of Dynamic Systems*, sec. 8.2): the plant is discretized exactly with
a zero-order hold on the voltage (``c2d(..., 'zoh')``: Ad = e^{AT}, Bd = int_0^T e^{As} ds B), and
the estimator gain M is placed so that the estimation error ``e[k+1] = (I - M C) Ad e[k]`` has
the poles ``z_i = exp(p_i T)`` of the continuous observer poles ``p_i`` mapped exactly. Each
sample the estimate is corrected with the measurement of the same instant before the control is
computed (no one-sample delay), and predicted with the voltage actually applied (after the
limit)::

    x^[k]   = x-[k] + M (y[k] - C x-[k])          correction with the new measurement
    u[k]    = sat(-K x^[k] + N r[k])
    x-[k+1] = Ad x^[k] + Bd u[k]                  prediction

K itself is the continuous LQR gain used unchanged at the sample instants (emulation). At the
default 1 ms the sampled loop keeps every continuous pole slower than ~300 rad/s to within a few
percent (``sampled_closed_loop_poles``, tested); the single-mass thesis weights also give one very
fast regulator pole (-548 rad/s long pendulum, -680 rad/s short) which sampling moves (to about
-1150 rad/s for the short pendulum) but which stays stable.

``discrete=True`` designs K with the discrete LQR on the sampled model instead (``lqr_gain`` with ``discrete``, on
``Ad, Bd`` with the same Q and R, per-sample cost ``x'Qx + u'Ru``), and N for unit DC gain of the
sampled loop, ``N = 1 / (C1 (I - Ad + Bd K)^-1 Bd)``: the gain is then right for the sample period
it runs at (the emulated one fails at 5 ms on the single mass, see docs/controllers.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.linalg

# DesignError, check_sample_period and the thesis's numbers live in numpy-free modules (the FMU runtime
# reads them).
from ipcosim.controllers.errors import DesignError
from ipcosim.controllers.laws.base import check_sample_period
from ipcosim.controllers.thesis import (
    THESIS_DOUBLE_MASS_Q_DIAGONAL,
    THESIS_SINGLE_MASS_Q_DIAGONAL,
)
from ipcosim.fmus.linearize import LinearModel, linearize
from ipcosim.fmus.params import PlantParams

BACKENDS = ("control", "scipy")

#: Relative tolerance of the PBH rank tests (smallest singular value / matrix norm).
PBH_TOLERANCE = 1e-10


# --- the thesis's design data (the thesis, sec. 3.2.2 / 4.2.2, App. A.2 / B.3) ---------------------

def thesis_single_mass_Q() -> np.ndarray:
    """App. A.2 state weights for ``[xc, xc', th, th']``: Bryson-style q_i = w / (a * x_max^2)."""
    return np.diag(THESIS_SINGLE_MASS_Q_DIAGONAL)


THESIS_DOUBLE_MASS_Q = np.diag(THESIS_DOUBLE_MASS_Q_DIAGONAL)
# --- checks ------------------------------------------------------------------------------------------

def _finite_matrix(name: str, M: Any, shape: tuple[int, int]) -> np.ndarray:
    try:
        arr = np.array(M, dtype=float, ndmin=2)
    except (TypeError, ValueError) as exc:
        raise DesignError(name, f"design input {name} is not a numeric matrix: {exc}") from None
    if arr.shape != shape:
        raise DesignError(name, f"design input {name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise DesignError(name, f"design input {name} has a non-finite entry (NaN or inf)")
    return arr


def check_weights(Q: Any, R: Any, n: int, m: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Validate LQR weights: Q symmetric positive semidefinite (n x n), R symmetric positive definite.

    Raises
    ------
    DesignError
        Naming ``Q`` or ``R`` and what is wrong.
    """
    Q = _finite_matrix("Q", Q, (n, n))
    R = _finite_matrix("R", R, (m, m))
    for name, M in (("Q", Q), ("R", R)):
        if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
            raise DesignError(name, f"weight {name} must be symmetric")
    q_eig = np.linalg.eigvalsh(Q)
    scale = max(float(np.max(np.abs(q_eig))), 1e-300)
    if q_eig[0] < -1e-12 * scale:
        raise DesignError("Q", f"weight Q must be positive semidefinite; smallest eigenvalue {q_eig[0]:.6g}")
    r_eig = np.linalg.eigvalsh(R)
    if r_eig[0] <= 0:
        raise DesignError("R", f"weight R must be positive definite; smallest eigenvalue {r_eig[0]:.6g}")
    return Q, R


def uncontrollable_modes(A: np.ndarray, B: np.ndarray, tol: float = PBH_TOLERANCE) -> list[complex]:
    """Eigenvalues of A that B cannot move (Popov-Belevitch-Hautus rank test, relative tolerance).

    A mode lambda is uncontrollable if ``[A - lambda I, B]`` loses rank; the rank is judged from
    the smallest singular value relative to the norm of ``[A, B]``.
    """
    n = A.shape[0]
    scale = max(np.linalg.norm(np.hstack([A, B]), 2), 1e-300)
    modes = []
    for lam in np.linalg.eigvals(A):
        s = np.linalg.svd(np.hstack([A - lam * np.eye(n), B]), compute_uv=False)
        if s[-1] <= tol * scale:
            modes.append(complex(lam))
    return modes


def unobservable_modes(A: np.ndarray, C: np.ndarray, tol: float = PBH_TOLERANCE) -> list[complex]:
    """Eigenvalues of A that the outputs C do not see (PBH test on the dual system)."""
    return uncontrollable_modes(A.T, C.T, tol)


def _fmt_modes(modes: Sequence[complex]) -> str:
    return ", ".join(f"{m.real:.4g}{m.imag:+.4g}j" if abs(m.imag) > 0 else f"{m.real:.4g}" for m in modes)


def check_controllable(A: np.ndarray, B: np.ndarray, name: str = "model") -> None:
    """Raise DesignError(``name``) if (A, B) has an uncontrollable mode."""
    modes = uncontrollable_modes(A, B)
    if modes:
        raise DesignError(name, f"design model is not controllable from the voltage: uncontrollable "
                                f"mode(s) {_fmt_modes(modes)} rad/s (check the design model parameters)")


def check_observable(A: np.ndarray, C: np.ndarray, name: str = "model") -> None:
    """Raise DesignError(``name``) if (A, C) has an unobservable mode."""
    modes = unobservable_modes(A, C)
    if modes:
        raise DesignError(name, f"design model is not observable from the measured positions: unobservable "
                                f"mode(s) {_fmt_modes(modes)} rad/s (check the design model parameters)")


# --- the numerical kernels, per back end -----------------------------------------------------------

def lqr_gain(A: np.ndarray, B: np.ndarray, Q: Any, R: Any, backend: str = "control",
             discrete: bool = False) -> np.ndarray:
    """LQR gain K (m x n) for ``u = -K x``: continuous, minimizing ``int x'Qx + u'Ru dt``
    (``K = R^-1 B'P``), or with ``discrete`` for ``x[k+1] = A x[k] + B u[k]`` minimizing
    ``sum x'Qx + u'Ru`` (``K = (R + B'P B)^-1 B'P A``), P from the algebraic Riccati equation.

    Raises
    ------
    DesignError
        Bad weights (``Q``/``R``), uncontrollable model (``model``), or no stabilizing solution.
    """
    n, m = B.shape
    Q, R = check_weights(Q, R, n, m)
    check_controllable(A, B)
    what = "discrete LQR" if discrete else "LQR"
    try:
        if backend == "control":
            import control
            K = np.asarray((control.dlqr if discrete else control.lqr)(A, B, Q, R)[0], dtype=float)
        elif backend == "scipy" and discrete:
            P = scipy.linalg.solve_discrete_are(A, B, Q, R)
            K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        elif backend == "scipy":
            K = np.linalg.solve(R, B.T @ scipy.linalg.solve_continuous_are(A, B, Q, R))
        else:
            raise DesignError("backend", f"unknown design backend {backend!r}; expected one of {BACKENDS}")
    except DesignError:
        raise
    except (ValueError, np.linalg.LinAlgError, ArithmeticError) as exc:
        raise DesignError("Q", f"{what} has no stabilizing solution for these weights "
                               f"(is every unstable mode weighted in Q?): {exc}") from None
    poles = np.linalg.eigvals(A - B @ K)
    if discrete:
        unstable = np.max(np.abs(poles)) >= 1.0 - 1e-12
    else:
        unstable = np.max(poles.real) >= -1e-8 * max(1.0, float(np.linalg.norm(A, 2)))
    if not np.all(np.isfinite(K)) or unstable:
        raise DesignError("Q", f"{what} has no stabilizing solution for these weights (an unstable mode is "
                               "not weighted in Q)")
    return K.reshape(m, n)


def place_gain(A: np.ndarray, B: np.ndarray, poles: Sequence[complex], backend: str = "control",
               name: str = "observer_poles") -> np.ndarray:
    """State-feedback gain G with ``eig(A - B G) = poles`` (used on the dual for observers).

    Raises
    ------
    DesignError
        Naming ``name`` if the poles are not finite, not closed under conjugation, repeated more
        often than the number of inputs, or the placement fails.
    """
    p = np.asarray(poles, dtype=complex).ravel()
    n, m = B.shape
    if p.size != n:
        raise DesignError(name, f"{name}: need {n} poles, got {p.size}")
    if not np.all(np.isfinite(p)):
        raise DesignError(name, f"{name}: poles must be finite")
    if not np.allclose(np.sort_complex(p), np.sort_complex(p.conj()), rtol=1e-9, atol=1e-12):
        raise DesignError(name, f"{name}: complex poles must come in conjugate pairs")
    for q in p:
        if np.sum(np.abs(p - q) <= 1e-9 * max(1.0, abs(q))) > m:
            raise DesignError(name, f"{name}: pole {q:.6g} repeated more than rank(B) = {m} times "
                                    "cannot be placed")
    try:
        if backend == "control":
            import control
            G = np.asarray(control.place(A, B, p), dtype=float)
        elif backend == "scipy":
            import scipy.signal  # imported here: ~0.5 s, needed only by observer placement
            G = scipy.signal.place_poles(A, B, p, method="YT").gain_matrix
        else:
            raise DesignError("backend", f"unknown design backend {backend!r}; expected one of {BACKENDS}")
    except DesignError:
        raise
    except (ValueError, np.linalg.LinAlgError, ArithmeticError) as exc:
        raise DesignError(name, f"{name}: poles {_fmt_modes(p)} cannot be placed: {exc}") from None
    achieved = np.sort_complex(np.linalg.eigvals(A - B @ G))
    want = np.sort_complex(p)
    if not np.all(np.isfinite(G)) or np.max(np.abs(achieved - want) / np.maximum(1.0, np.abs(want))) > 1e-6:
        raise DesignError(name, f"{name}: poles {_fmt_modes(p)} could not be placed accurately "
                                "(ill-conditioned placement)")
    return G


def zoh(A: np.ndarray, B: np.ndarray, T: float, backend: str = "control") -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretization ``(Ad, Bd)`` of ``x' = A x + B u`` for period T."""
    T = check_sample_period(T)
    n, m = B.shape
    if backend == "control":
        import control
        sysd = control.c2d(control.ss(A, B, np.eye(n), np.zeros((n, m))), T, method="zoh")
        return np.asarray(sysd.A, float), np.asarray(sysd.B, float)
    if backend == "scipy":
        M = np.zeros((n + m, n + m))
        M[:n, :n] = A * T
        M[:n, n:] = B * T
        E = scipy.linalg.expm(M)
        return E[:n, :n], E[:n, n:]
    raise DesignError("backend", f"unknown design backend {backend!r}; expected one of {BACKENDS}")


# --- designs -----------------------------------------------------------------------------------------

def design_model(params: PlantParams) -> LinearModel:
    """The design model: the plant linearized upright without the armature inductance."""
    return linearize(params, inductance=False)


@dataclass(frozen=True)
class LQRDesign:
    """An LQR state feedback with reference gain and a discrete current estimator.

    Attributes
    ----------
    model : LinearModel
        Continuous design model (states without the current; outputs = measured positions).
    Q, R : ndarray
        Weights.
    K : ndarray (1, n)
        LQR gain (continuous, or discrete with ``discrete``); ``u = -K x^ + N r``.
    N : float
        Reference gain (unit DC gain from r to the motor cart position).
    poles : ndarray
        Closed-loop poles eig(A - B K) (continuous equivalents ``log(z)/T`` with ``discrete``).
    observer_poles : ndarray
        Continuous observer poles.
    L : ndarray (n, p)
        Continuous Luenberger gain, eig(A - L C) = observer_poles (thesis form).
    sample_period : float
        T [s].
    Ad, Bd : ndarray
        Zero-order-hold discretization of the design model.
    M : ndarray (n, p)
        Current-estimator gain, eig((I - M C) Ad) = exp(observer_poles T).
    backend : str
        Back end that computed it.
    """

    model: LinearModel
    Q: np.ndarray
    R: np.ndarray
    K: np.ndarray
    N: float
    poles: np.ndarray
    observer_poles: np.ndarray
    L: np.ndarray
    sample_period: float
    Ad: np.ndarray
    Bd: np.ndarray
    M: np.ndarray
    backend: str = "control"
    info: dict = field(default_factory=dict)


def reference_gain(A: np.ndarray, B: np.ndarray, K: np.ndarray, C1: np.ndarray) -> float:
    """``N = -1 / (C1 (A - B K)^-1 B)``: unit steady-state gain from the reference to ``C1 x``."""
    dc = float((C1 @ np.linalg.solve(A - B @ K, B)).item())
    if not math.isfinite(dc) or abs(dc) < 1e-12:
        raise DesignError("model", "reference gain undefined: the closed loop has zero DC gain to the "
                                   "motor cart position")
    return -1.0 / dc


def design_lqr(model: LinearModel, Q: Any, R: Any, *, observer_poles: Sequence[complex] | None = None,
               observer_pole_factor: float | None = None, sample_period: float = 1e-3,
               reference_output: int = 0, backend: str = "control", discrete: bool = False) -> LQRDesign:
    """LQR + reference gain + Luenberger observer, discretized for ``sample_period``.

    Parameters
    ----------
    model : LinearModel
        Continuous design model (``design_model(params)``).
    Q, R : array_like
        State weight (n x n, positive semidefinite) and input weight (positive; scalar allowed).
    observer_poles : sequence of complex, optional
        Continuous observer poles [rad/s] (thesis single mass: ``THESIS_SINGLE_MASS_OBSERVER_POLES``).
    observer_pole_factor : float, optional
        Alternatively: observer poles = factor * eig(A - B K) (thesis double mass: 10).
    sample_period : float
        Controller sample period T [s].
    reference_output : int
        Row of ``model.C`` holding the motor-driven cart position (0 for both plants).
    backend : {'control', 'scipy'}
        Numerical back end (see the module docstring).
    discrete : bool
        Design K with the discrete LQR on the zero-order-hold model (see the module docstring).

    Raises
    ------
    DesignError
        With ``parameter`` naming the bad input.
    """
    T, A, B, C, n = design_inputs(model, sample_period, backend)
    R = np.atleast_2d(np.asarray(R, dtype=float)) if np.ndim(R) < 2 else R
    Ad, Bd = zoh(A, B, T, backend)
    C1 = C[reference_output:reference_output + 1]
    K = lqr_gain(Ad, Bd, Q, R, backend, discrete=True) if discrete else lqr_gain(A, B, Q, R, backend)
    check_observable(A, C)
    if discrete:
        poles = np.log(np.linalg.eigvals(Ad - Bd @ K).astype(complex)) / T
        N = reference_gain(Ad - np.eye(n), Bd, K, C1)  # x = (I - Ad + Bd K)^-1 Bd N r at rest
    else:
        poles = np.linalg.eigvals(A - B @ K)
        N = reference_gain(A, B, K, C1)
    if observer_poles is None:
        if observer_pole_factor is None:
            raise DesignError("observer_poles", "give observer_poles or observer_pole_factor")
        f = float(observer_pole_factor)
        if not (math.isfinite(f) and f > 0):
            raise DesignError("observer_pole_factor", f"observer_pole_factor = {f} must be positive and finite")
        obs = f * poles
    else:
        obs = np.asarray(observer_poles, dtype=complex)
    if obs.size and np.max(obs.real) >= 0:
        raise DesignError("observer_poles", "observer poles must have negative real parts")
    L = place_gain(A.T, C.T, obs, backend).T
    z = np.exp(obs * T)
    M = place_gain(Ad.T, (C @ Ad).T, z, backend).T
    return LQRDesign(model=model, Q=np.asarray(check_weights(Q, R, n)[0]), R=R, K=K, N=N, poles=poles,
                     observer_poles=obs, L=L, sample_period=T, Ad=Ad, Bd=Bd, M=M, backend=backend)


def design_inputs(model: LinearModel, sample_period: float, backend: str
                  ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, int]:
    """``(T, A, B, C, n)`` of a design after checking the back end and the sample period."""
    if backend not in BACKENDS:
        raise DesignError("backend", f"unknown design backend {backend!r}; expected one of {BACKENDS}")
    return check_sample_period(sample_period), model.A, model.B, model.C, model.A.shape[0]


def sampled_closed_loop_poles(design: LQRDesign) -> np.ndarray:
    """Continuous-equivalent poles ``log(z)/T`` of the sampled loop (design model, current estimator).

    Augmented state ``[x, e]`` with e the prediction error; returns the 2n poles.
    """
    A, C = design.model.A, design.model.C
    Ad, Bd, M, K, T = design.Ad, design.Bd, design.M, design.K, design.sample_period
    n = A.shape[0]
    # x^ = x- + M C (x - x-) = x - (I - M C) e ;  u = -K x^ ; e = x - x-
    IMC = np.eye(n) - M @ C
    top = np.hstack([Ad - Bd @ K, Bd @ K @ IMC])
    bottom = np.hstack([np.zeros((n, n)), Ad @ IMC])
    z = np.linalg.eigvals(np.vstack([top, bottom]))
    return np.log(z.astype(complex)) / T


def output_filter(time_constant: float, sample_period: float, backend: str = "control"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete 1/(tau s + 1)^2 filter (zero-order hold), as ``(Ad, Bd, Cd)`` of a 2-state system.

    The thesis's double-mass LQR filters each measured position through 1/(0.0008 s + 1)^2.
    """
    tau = float(time_constant)
    if not (math.isfinite(tau) and tau > 0):
        raise DesignError("output_filter_time_constant", f"output_filter_time_constant = {tau} s must be "
                                                         "positive and finite")
    a = 1.0 / tau
    # state [y1, y2]: y1' = a (u - y1), y2' = a (y1 - y2); output y2
    A = np.array([[-a, 0.0], [a, -a]])
    B = np.array([[a], [0.0]])
    Ad, Bd = zoh(A, B, sample_period, backend)
    return Ad, Bd, np.array([[0.0, 1.0]])
