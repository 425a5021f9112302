"""The fixed-step ETDRK4 plant integrator: accuracy against a tight-tolerance Radau reference,
the f-form stage matrices against the textbook scheme, and the constant-folded right-hand
sides against ``ipcosim.fmus.physics``."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from ipcosim.fmus.expm import SingularMatrixError, solve
from ipcosim.fmus.expm import expm as pure_expm
from ipcosim.fmus.integrator import ETDRK4, FastETDRK4, etdrk4_f_form
from ipcosim.fmus.kinds.double_mass import double_mass_internal_rhs
from ipcosim.fmus.kinds.single_mass import single_mass_internal_rhs
from ipcosim.fmus.params import preset
from ipcosim.fmus.physics import double_mass_rhs, rhs_for, single_mass_momentum_rhs, single_mass_to_momentum
from ipcosim.fmus.plant import Plant

H = 1e-3
#: Open-loop experiment: 2 s, a +5 V pulse from 0.1 s to 0.3 s (edges on the 1 ms grid).
SEGMENTS = ((0.0, 0.1, 0.0), (0.1, 0.3, 5.0), (0.3, 2.0, 0.0))


def pulse(k: int) -> float:
    return 5.0 if 100 <= k < 300 else 0.0


def radau_reference(params, x0: np.ndarray) -> np.ndarray:
    """States on the 1 ms grid from scipy's Radau at rtol 1e-10, restarted at the pulse edges."""
    rhs = rhs_for(params)
    x = np.array(x0, dtype=float)
    rows = [x]
    for a, b, v in SEGMENTS:
        n = int(round((b - a) / H))
        t_eval = a + H * np.arange(1, n + 1)
        t_eval[-1] = b
        sol = solve_ivp(lambda t, y, v=v: rhs(y, v, params), (a, b), x, method="Radau", rtol=1e-10, atol=1e-13,
                        t_eval=t_eval)
        assert sol.success, sol.message
        rows.extend(sol.y.T)
        x = sol.y[:, -1]
    return np.array(rows)


def plant_trajectory(params, x0: np.ndarray) -> np.ndarray:
    plant = Plant(params, x0)
    rows = [plant.x.copy()]
    for k in range(2000):
        plant.do_step(k * H, H, pulse(k))
        rows.append(plant.x.copy())
    return np.array(rows)


CASES = [  # (preset, index of the pendulum angle, initial angle)
    ("thesis-ch3", 2, 0.0), ("thesis-ch3", 2, math.pi),
    ("thesis-appendix-a", 2, 0.0), ("thesis-appendix-a", 2, math.pi),
    ("thesis-ch4", 4, 0.0), ("thesis-ch4", 4, math.pi),
]


@pytest.mark.parametrize("name, angle_index, angle0", CASES,
                         ids=[f"{n}-{'upright' if a == 0 else 'down'}" for n, _, a in CASES])
def test_accuracy_against_radau(name: str, angle_index: int, angle0: float) -> None:
    params = preset(name)
    x0 = np.zeros(7 if name == "thesis-ch4" else 5)
    x0[angle_index] = angle0
    ref = radau_reference(params, x0)
    got = plant_trajectory(params, x0)
    assert ref.shape == got.shape
    pos_err = np.max(np.abs(got[:, 0] - ref[:, 0]))
    ang_err = np.max(np.abs(got[:, angle_index] - ref[:, angle_index]))
    # the experiment is not trivial: the cart moves by centimetres, the pendulum swings
    assert np.max(np.abs(ref[:, 0])) > 0.01
    assert np.ptp(ref[:, angle_index]) > 0.05
    assert pos_err < 1e-6, f"cart position error {pos_err:.3g} m"
    assert ang_err < 1e-5, f"pendulum angle error {ang_err:.3g} rad"
    if name == "thesis-ch4":
        assert np.max(np.abs(got[:, 2] - ref[:, 2])) < 1e-6  # passive cart too


def test_f_form_equals_textbook_etdrk4() -> None:
    """FastETDRK4 (stage matrices) and ETDRK4 (Cox-Matthews form) are the same scheme."""
    rng = np.random.default_rng(1)
    n = 4
    L = rng.normal(size=(n, n)) - 50 * np.eye(n)
    L[0, 0] = -3000.0

    def f(*x: float) -> tuple[float, ...]:
        x = np.array(x)
        return tuple(L @ x + np.sin(x) + 0.3 * x[::-1] ** 2)

    x = rng.normal(size=n)
    fast, slow = FastETDRK4(L, 2e-3), ETDRK4(L, 2e-3)
    a = fast.step(list(x), f)
    b = slow.step(x, lambda z: np.array(f(*z)) - L @ z)
    assert np.allclose(a, b, rtol=1e-12, atol=1e-13)
    assert not np.allclose(a, x)


def test_exact_for_linear_systems() -> None:
    """With f = L x + c the exponential integrator is exact: one step equals the matrix exponential."""
    rng = np.random.default_rng(2)
    n = 5
    L = rng.normal(size=(n, n))
    L[4, 4] = -14444.0
    c = rng.normal(size=n)
    x = rng.normal(size=n)
    h = 1e-3
    got = FastETDRK4(L, h).step(list(x), lambda *z: tuple(L @ np.array(z) + c))
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n] = L
    aug[:n, n] = c
    exact = (expm(aug * h) @ np.append(x, 1.0))[:n]
    assert np.allclose(got, exact, rtol=1e-11, atol=1e-12)


def test_stage_matrices_shapes() -> None:
    S = etdrk4_f_form(-np.eye(3), 0.1)
    assert [np.shape(s) for s in S] == [(3, 6), (3, 9), (3, 12), (3, 15)]


@pytest.mark.parametrize("n, scale", [(1, 0.3), (5, 1.0), (14, 4.0), (28, 30.0)])
def test_pure_python_expm_equals_scipy(n: int, scale: float) -> None:
    """The runtime's plain-Python expm (no numpy in an FMU) against scipy's, including norms that need squaring."""
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) * scale
    A[0, 0] = -14.4 * scale  # one stiff entry, as in the plant's h L
    want = expm(A)
    got = np.array(pure_expm(A.tolist()))
    assert np.max(np.abs(got - want)) <= 1e-13 * np.max(np.abs(want))


def test_pure_python_solve_and_singular_matrix() -> None:
    rng = np.random.default_rng(5)
    A, B = rng.normal(size=(6, 6)), rng.normal(size=(6, 3))
    assert np.allclose(np.array(solve(A.tolist(), B.tolist())), np.linalg.solve(A, B), rtol=1e-12, atol=1e-13)
    with pytest.raises(SingularMatrixError):
        solve([[1.0, 2.0], [2.0, 4.0]], [[1.0], [1.0]])


@pytest.mark.parametrize("b", [0.0, 0.7])
def test_folded_rhs_single_mass_equals_physics(b: float) -> None:
    p = preset("thesis-ch3", b=b)
    f = single_mass_internal_rhs(p)
    rng = np.random.default_rng(3)
    for _ in range(50):
        x = rng.normal(size=5) * [0.1, 0.5, 2.0, 3.0, 1.0]
        z = single_mass_to_momentum(x, p)
        v = rng.uniform(-9, 9)
        assert np.allclose(f(*z, v), single_mass_momentum_rhs(z, v, p), rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("b", [0.0, 0.7])
def test_folded_rhs_double_mass_equals_physics(b: float) -> None:
    p = preset("thesis-ch4", b1=b, b2=b / 2)
    f = double_mass_internal_rhs(p)
    rng = np.random.default_rng(4)
    for _ in range(50):
        x = rng.normal(size=7) * [0.1, 0.5, 0.1, 0.5, 2.0, 3.0, 1.0]
        v = rng.uniform(-9, 9)
        assert np.allclose(f(*x, v), double_mass_rhs(x, v, p), rtol=1e-13, atol=1e-12)


def test_one_stepper_per_linear_part_and_step_steps_as_a_new_one() -> None:
    """Plants of the same parameters share the stepper of their (L, h) (making one is most of an instance's
    set-up), and a shared one steps bit for bit as one made for the caller; another L or h gets its own."""
    from ipcosim.fmus.integrator import shared_etdrk4

    rng = np.random.default_rng(3)
    L = rng.normal(size=(3, 3))
    L[2, 2] = -5000.0
    first, again = shared_etdrk4(L.tolist(), 1e-3), shared_etdrk4([list(row) for row in L], 1e-3)
    assert again is first
    assert shared_etdrk4(L.tolist(), 2e-3) is not first and shared_etdrk4((L * 1.01).tolist(), 1e-3) is not first

    def f(*x: float) -> tuple[float, ...]:
        return tuple(L @ np.array(x) + np.cos(x))

    x = rng.normal(size=3).tolist()
    assert first.step(x, f) == FastETDRK4(L, 1e-3).step(x, f)  # exactly: the same arithmetic
