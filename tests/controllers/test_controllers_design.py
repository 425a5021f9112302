"""ipcosim.controllers.design: the thesis's LQR designs reproduced, both back ends agree, the discrete
estimator has the mapped poles, and bad design inputs are rejected naming the input."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.controllers.catalog import build_law, make_law, schema
from ipcosim.controllers.design import (
    THESIS_DOUBLE_MASS_Q,
    check_weights,
    design_lqr,
    design_model,
    output_filter,
    place_gain,
    reference_gain,
    sampled_closed_loop_poles,
    thesis_single_mass_Q,
    zoh,
)
from ipcosim.controllers.errors import ControllerParameterError, DesignError
from ipcosim.controllers.laws.lqr import lqr_design_for
from ipcosim.controllers.thesis import (
    THESIS_DOUBLE_MASS_K,
    THESIS_DOUBLE_MASS_R,
    THESIS_SINGLE_MASS_OBSERVER_POLES,
    THESIS_SINGLE_MASS_R,
)
from ipcosim.fmus.linearize import LinearModel
from ipcosim.fmus.params import preset


def test_double_mass_K_reproduces_the_thesis_within_0_1_percent() -> None:
    d = design_lqr(design_model(preset("thesis-ch4")), THESIS_DOUBLE_MASS_Q, THESIS_DOUBLE_MASS_R,
                   observer_pole_factor=10)
    K = d.K[0]
    thesis = np.array(THESIS_DOUBLE_MASS_K)
    assert np.all(np.abs(K - thesis) <= 1e-3 * np.abs(thesis)), (K, thesis)


def test_thesis_single_mass_weights_are_app_a2() -> None:
    Q = thesis_single_mass_Q()
    assert np.allclose(np.diag(Q), [200 / (2.534 * 0.01), 50 / (2 * 0.09211 ** 2), 100 / (3.2 * 0.016 ** 2),
                                    0.008 / (1.1 * 0.0072 ** 2)])
    assert THESIS_SINGLE_MASS_R == pytest.approx(1 / 36)
    assert sorted(THESIS_SINGLE_MASS_OBSERVER_POLES, key=lambda p: (p.real, p.imag)) == \
        sorted([-160 + 20j, -160 - 20j, -120 + 8j, -120 - 8j], key=lambda p: (p.real, p.imag))


@pytest.mark.parametrize("name", ["thesis-appendix-a", "thesis-ch3"])
def test_single_mass_design_is_an_lqr_optimum(name: str) -> None:
    """The App. A.2 weights on both single-mass models: K solves the Riccati equation (checked
    independently of the solver through its residual) and stabilizes; N gives unit DC gain."""
    model = design_model(preset(name))
    d = lqr_design_for("single-mass", preset(name))
    A, B, Q, R = model.A, model.B, thesis_single_mass_Q(), np.array([[THESIS_SINGLE_MASS_R]])
    # P from K: K = R^-1 B' P is one row; check optimality via the closed-loop Lyapunov equation
    Acl = A - B @ d.K
    assert np.max(np.linalg.eigvals(Acl).real) < 0
    from scipy.linalg import solve_continuous_lyapunov
    P = solve_continuous_lyapunov(Acl.T, -(Q + d.K.T @ R @ d.K))
    assert np.allclose(np.linalg.solve(R, B.T @ P), d.K, rtol=1e-7)
    dc = model.C[0] @ np.linalg.solve(-Acl, B[:, 0]) * d.N
    assert dc == pytest.approx(1.0, rel=1e-10)
    # the cart position has a free integrator: N equals the position gain
    assert d.N == pytest.approx(d.K[0, 0], rel=1e-9)


def test_single_mass_design_differs_between_the_two_pendulums() -> None:
    ka = lqr_design_for("single-mass", preset("thesis-appendix-a")).K
    kc = lqr_design_for("single-mass", preset("thesis-ch3")).K
    assert not np.allclose(ka, kc, rtol=1e-3)


@pytest.mark.parametrize("kind,name", [("single-mass", "thesis-appendix-a"), ("single-mass", "thesis-ch3"),
                                       ("double-mass", "thesis-ch4")])
def test_control_and_scipy_back_ends_agree(kind: str, name: str) -> None:
    a = lqr_design_for(kind, preset(name), backend="control")
    b = lqr_design_for(kind, preset(name), backend="scipy")
    for attr in ("K", "L", "Ad", "Bd", "M"):
        x, y = getattr(a, attr), getattr(b, attr)
        assert np.allclose(x, y, rtol=1e-8, atol=1e-10 * np.max(np.abs(x))), attr
    assert a.N == pytest.approx(b.N, rel=1e-10)


@pytest.mark.parametrize("kind,name", [("single-mass", "thesis-ch3"), ("double-mass", "thesis-ch4")])
def test_observer_and_estimator_poles(kind: str, name: str) -> None:
    d = lqr_design_for(kind, preset(name))
    A, C = d.model.A, d.model.C
    got = np.sort_complex(np.linalg.eigvals(A - d.L @ C))
    assert np.allclose(got, np.sort_complex(d.observer_poles), rtol=1e-6)
    z = np.sort_complex(np.linalg.eigvals((np.eye(A.shape[0]) - d.M @ C) @ d.Ad))
    assert np.allclose(z, np.sort_complex(np.exp(d.observer_poles * d.sample_period)), rtol=1e-6, atol=1e-9)
    if kind == "double-mass":  # App. B.3: observer poles = 2 * 5 * eig(A - B K)
        assert np.allclose(np.sort_complex(d.observer_poles), np.sort_complex(10 * d.poles))


@pytest.mark.parametrize("kind,name", [("single-mass", "thesis-ch3"), ("double-mass", "thesis-ch4")])
def test_sampled_loop_keeps_the_continuous_poles(kind: str, name: str) -> None:
    """At 1 ms the sampled loop (ZOH plant, current estimator, continuous K) is stable and keeps
    the continuous regulator and observer poles with |p| T < 0.3 to within a few percent (emulation
    is justified for them; the single-mass weights' one pole near -680 rad/s is not kept)."""
    d = lqr_design_for(kind, preset(name))
    sampled = sampled_closed_loop_poles(d)
    assert np.max(sampled.real) < 0
    wanted = np.concatenate([d.poles, d.observer_poles])
    wanted = wanted[np.abs(wanted) * d.sample_period < 0.3]
    assert wanted.size >= 2 * d.K.shape[1] - 1
    for p in wanted:
        nearest = sampled[np.argmin(np.abs(sampled - p))]
        assert abs(nearest - p) <= 0.06 * abs(p), (p, nearest)


def test_zoh_matches_the_matrix_exponential() -> None:
    A = np.array([[0.0, 1.0], [-4.0, -0.4]])
    B = np.array([[0.0], [1.0]])
    Ad, Bd = zoh(A, B, 0.01)
    from scipy.linalg import expm
    assert np.allclose(Ad, expm(A * 0.01))
    # Bd = A^-1 (Ad - I) B for invertible A
    assert np.allclose(Bd, np.linalg.solve(A, (Ad - np.eye(2)) @ B))


def test_output_filter_is_a_unit_gain_double_lag() -> None:
    Ad, Bd, Cd = output_filter(0.0008, 1e-3)
    x = np.zeros(2)
    for _ in range(100):
        x = Ad @ x + Bd[:, 0]
    assert (Cd @ x).item() == pytest.approx(1.0, abs=1e-12)
    # step response after one sample of a (tau s + 1)^-2: 1 - (1 + T/tau) e^(-T/tau), sampled at k = 1
    x = Ad @ np.zeros(2) + Bd[:, 0]
    r = 1e-3 / 0.0008
    assert (Cd @ x).item() == pytest.approx(1 - (1 + r) * math.exp(-r), rel=1e-9)


# --- bad inputs ----------------------------------------------------------------------------------------

def _model() -> LinearModel:
    return design_model(preset("thesis-ch4"))


@pytest.mark.parametrize("Q,R,param", [
    (np.diag([32, 0.5, 19, 2, -1700, 0.4]), 0.1, "Q"),
    (np.diag([32, 0.5, 19, 2, np.nan, 0.4]), 0.1, "Q"),
    (np.diag([32, 0.5, 19, np.inf, 1700, 0.4]), 0.1, "Q"),
    (np.diag([32, 0.5, 19, 2, 1700, 0.4]), 0.0, "R"),
    (np.diag([32, 0.5, 19, 2, 1700, 0.4]), -1.0, "R"),
    (np.diag([32, 0.5, 19, 2, 1700, 0.4]), np.inf, "R"),
    (np.triu(np.ones((6, 6))), 0.1, "Q"),
])
def test_bad_weights_name_the_weight(Q, R, param: str) -> None:
    with pytest.raises(DesignError) as err:
        design_lqr(_model(), Q, R, observer_pole_factor=10)
    assert err.value.parameter == param
    assert param in str(err.value)


def test_unweighted_marginal_mode_has_no_stabilizing_solution() -> None:
    # Q = 0 leaves the free cart's pole at 0 where it is: no stabilizing Riccati solution
    with pytest.raises(DesignError) as err:
        design_lqr(_model(), np.zeros((6, 6)), 0.1, observer_pole_factor=10)
    assert err.value.parameter == "Q"


def test_uncontrollable_model_is_rejected() -> None:
    params = preset("thesis-ch4", K=0.0, Bf=0.0)  # active cart decoupled from the pendulum cart
    with pytest.raises(DesignError) as err:
        design_lqr(design_model(params), THESIS_DOUBLE_MASS_Q, THESIS_DOUBLE_MASS_R, observer_pole_factor=10)
    assert err.value.parameter == "model" and "not controllable" in str(err.value)


def test_unobservable_model_is_rejected() -> None:
    m = _model()
    blind = LinearModel(A=m.A, B=m.B, C=m.C[:1] * 0 + np.eye(6)[5:6], D=m.D[:1], states=m.states,
                        outputs=("pendulum_velocity",))
    with pytest.raises(DesignError) as err:
        design_lqr(blind, THESIS_DOUBLE_MASS_Q, THESIS_DOUBLE_MASS_R, observer_pole_factor=10)
    assert err.value.parameter == "model" and "not observable" in str(err.value)


@pytest.mark.parametrize("poles,reason", [
    ([-100.0] * 4, "repeated"),
    ([-100 + 5j, -100 + 5j, -50.0, -60.0], "conjugate"),
    ([-100.0, -110.0, -120.0], "need 4"),
    ([-100.0, -110.0, np.nan, -130.0], "finite"),
])
def test_unplaceable_observer_poles(poles, reason: str) -> None:
    m = design_model(preset("thesis-ch3"))
    with pytest.raises(DesignError) as err:
        design_lqr(m, thesis_single_mass_Q(), THESIS_SINGLE_MASS_R, observer_poles=poles)
    assert err.value.parameter == "observer_poles" and reason in str(err.value)


@pytest.mark.parametrize("T", [0.0, -1e-3, math.nan, math.inf])
def test_non_positive_sample_period(T: float) -> None:
    with pytest.raises(DesignError) as err:
        design_lqr(design_model(preset("thesis-ch3")), thesis_single_mass_Q(), THESIS_SINGLE_MASS_R,
                   observer_poles=THESIS_SINGLE_MASS_OBSERVER_POLES, sample_period=T)
    assert err.value.parameter == "sample_period"


def test_check_weights_accepts_semidefinite_q() -> None:
    Q, R = check_weights(np.diag([1.0, 0.0]), 2.0, 2)
    assert Q.shape == (2, 2) and R.shape == (1, 1)


def test_place_gain_places() -> None:
    A = np.array([[0.0, 1.0], [2.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    G = place_gain(A, B, [-3.0, -4.0])
    assert np.allclose(np.sort(np.linalg.eigvals(A - B @ G).real), [-4.0, -3.0])


def test_reference_gain_formula() -> None:
    A = np.array([[0.0, 1.0], [0.0, -1.0]])
    B = np.array([[0.0], [1.0]])
    K = np.array([[2.0, 3.0]])
    # closed loop x'' + 4 x' + 2 x = N r  ->  DC gain N/2
    assert reference_gain(A, B, K, np.array([[1.0, 0.0]])) == pytest.approx(2.0)


# --- through the flat parameters (what the FMUs do) -------------------------------------------------------

def test_changing_a_weight_changes_the_gains_it_implies() -> None:
    base = make_law("double-mass", "LQR")
    heavier = make_law("double-mass", "LQR", Q_pendulum_angle=3400.0)
    assert not np.allclose(base.design.K, heavier.design.K)
    d = design_lqr(design_model(preset("thesis-ch4")), np.diag([32, 0.5, 19, 2, 3400, 0.4]), THESIS_DOUBLE_MASS_R,
                   observer_pole_factor=10)
    assert np.allclose(heavier.design.K, d.K, rtol=1e-9)


@pytest.mark.parametrize("values,param", [
    (dict(Q_pendulum_angle=-1.0), "Q_pendulum_angle"),
    (dict(R=0.0), "R"),
    (dict(R=math.nan), "R"),
    (dict(sample_period=0.0), "sample_period"),
    (dict(model_Mp=-0.1), "model_Mp"),
    (dict(model_K=0.0, model_Bf=0.0), "model_*"),
    (dict(observer_pole_factor=0.0, observer_pole_1_re=-50.0, observer_pole_1_im=0.0, observer_pole_2_re=-50.0,
          observer_pole_2_im=0.0, observer_pole_3_re=-50.0, observer_pole_3_im=0.0), "observer_pole_*"),
    (dict(Q_active_cart_position=0.0, Q_active_cart_velocity=0.0, Q_passive_cart_position=0.0,
          Q_passive_cart_velocity=0.0, Q_pendulum_angle=0.0, Q_pendulum_velocity=0.0), "Q"),
])
def test_flat_parameter_errors_name_the_parameter(values: dict, param: str) -> None:
    with pytest.raises(ControllerParameterError) as err:
        build_law("double-mass", "LQR", values, backend="scipy")
    assert err.value.parameter == param
    assert param.rstrip("*") in str(err.value)


def test_schema_defaults_build_the_default_sets() -> None:
    for law in ("PID", "CascadePID", "LQR", "HSMC", "AdaptiveHSMC"):
        for kind in ("single-mass", "double-mass"):
            names = [s.name for s in schema(kind, law)]
            assert "sample_period" in names and "voltage_limit" in names
            assert len(names) == len(set(names))
            assert all(s.unit for s in schema(kind, law) if s.constraint != "bool")
