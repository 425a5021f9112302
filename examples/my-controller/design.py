"""My controller's design: pole placement for the state feedback, a steady-state Kalman filter
as the observer, both in discrete time at the sample period, from ipcosim's linear plant model.

Run ``python design.py`` to write ``gains_single_mass.json`` and ``gains_double_mass.json``,
which the FMUs carry (see README.md). Needs numpy and scipy (design time only: the FMUs run
on the Python standard library).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.linalg import expm, solve_discrete_are
from scipy.signal import place_poles

import ipcosim

HERE = Path(__file__).resolve().parent
SAMPLE_PERIOD = 0.001  # s
#: Continuous-time closed-loop poles [1/s], mapped to z = exp(s T).
POLES = {
    "single-mass": [-4.0 + 3.0j, -4.0 - 3.0j, -12.0, -20.0],
    "double-mass": [-4.0 + 3.0j, -4.0 - 3.0j, -10.0 + 8.0j, -10.0 - 8.0j, -14.0, -20.0],
}
#: Encoder noise (standard deviation) of the measured outputs: cart positions [m], angle [rad].
NOISE = {"cart": 2.3e-5, "angle": 1.5e-3}
#: Process noise: an input disturbance of this many volts (standard deviation).
PROCESS_VOLTS = 0.5


def discretize(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization."""
    n, m = A.shape[0], B.shape[1]
    M = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * T)
    return M[:n, :n], M[:n, n:]


def design(plant: str, T: float = SAMPLE_PERIOD) -> dict:
    """Gains of the observer-based state feedback for one plant (a JSON-ready dict)."""
    model = ipcosim.linearize(plant, inductance=False)
    Ad, Bd = discretize(model.A, model.B, T)
    K = place_poles(Ad, Bd, np.exp(np.array(POLES[plant]) * T)).gain_matrix
    measured = [s for s in model.states if not s.endswith("velocity")]
    C = np.array([[1.0 if s == m else 0.0 for s in model.states] for m in measured])
    R = np.diag([NOISE["angle" if m == "pendulum_angle" else "cart"] ** 2 for m in measured])
    Q = Bd @ Bd.T * PROCESS_VOLTS ** 2 + 1e-12 * np.eye(len(model.states))
    P = solve_discrete_are(Ad.T, C.T, Q, R)  # predicted error covariance
    L = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)  # current-estimator (filter) gain
    reference_state = [1.0 if s.endswith("cart_position") else 0.0 for s in model.states]
    return {"plant": plant, "sample_period": T, "states": list(model.states), "measured": measured,
            "Ad": Ad.tolist(), "Bd": Bd[:, 0].tolist(), "C": C.tolist(), "K": K[0].tolist(), "L": L.tolist(),
            "reference_state": reference_state}


def write_gains(folder: Path = HERE) -> dict[str, Path]:
    """Write ``gains_<plant>.json`` for both plants; returns plant -> file."""
    out = {}
    for plant in POLES:
        path = folder / f"gains_{plant.replace('-', '_')}.json"
        text = json.dumps(design(plant), indent=1) + "\n"
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        out[plant] = path
    return out


if __name__ == "__main__":
    for plant, path in write_gains().items():
        print(f"{plant}: {path}")
