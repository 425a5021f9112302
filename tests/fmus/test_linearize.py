"""The linearization reproduces the thesis's matrices and poles (thesis-data.md section 1)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from ipcosim.fmus.linearize import linearize
from ipcosim.fmus.params import ParameterError, UnknownPresetError, preset

# thesis eq. 3.24, state [th, th', xc, xc', i]
EQ_3_24_A = [[0, 1, 0, 0, 0],
             [50.21, -0.317, 0, -44.6575, 17.3349],
             [0, 0, 0, 1, 0],
             [1.47, -0.0093, 0, -10.033, 3.8946],
             [0, 0, 0, -24895.63, -14444.44]]
EQ_3_24_B = [0, 0, 0, 0, 50000 / 9]
EQ_3_24_ORDER = ["pendulum_angle", "pendulum_velocity", "cart_position", "cart_velocity", "motor_current"]
POLES_3_24 = [0, 6.604454017, -6.418833021, -17.25594561, -14437.72415]

# App. A.2, state [xc, xc', th, th'] (long pendulum, no inductance)
A2_A = [[0, 1, 0, 0], [0, -16.74554526, 1.470698607, -0.004878730576],
        [0, 0, 0, 1], [0, -39.16781208, 26.38554173, -0.08752843618]]
A2_B = [0, 1.497917086, 0, 3.50362642]

# eq. 4.23, state [i, xa, xa', xc, xc', th, th']
EQ_4_23_A = [[-14444.44, 0, -24895.63, 0, 0, 0, 0],
             [0, 0, 1, 0, 0, 0, 0],
             [4.099, -129.90, -7.635, 129.90, 2.01, 0, 0],
             [0, 0, 0, 0, 1, 0, 0],
             [0, 143.18, 2.218, -143.18, -2.22, 0.94, -0.01],
             [0, 0, 0, 0, 0, 0, 1],
             [0, 637.31, 9.874, -637.31, -9.88, 47.86, -0.55]]
EQ_4_23_B = [50000 / 9, 0, 0, 0, 0, 0, 0]
EQ_4_23_ORDER = ["motor_current", "active_cart_position", "active_cart_velocity", "passive_cart_position",
                 "passive_cart_velocity", "pendulum_angle", "pendulum_velocity"]
POLES_4_23 = [6.469034991, -4.568631367 + 14.4109187j, -4.568631367 - 14.4109187j, -6.342778315,
              -8.464477867, -14437.37167]

# App. B.3, state [xa, xa', xc, xc', th, th'] (no inductance)
B3_A = [[0, 1, 0, 0, 0, 0],
        [-129.9026065, -14.70083144, 129.902606, 2.012575593, 0, 0],
        [0, 0, 0, 1, 0, 0],
        [143.1812453, 2.218300983, -143.1812453, -2.220317620, 0.942175447, -0.01077135627],
        [0, 0, 0, 0, 0, 1],
        [637.3052461, 9.873743249, -637.3052461, -9.882719379, 47.85834769, -0.5471372821]]
B3_B = [0, 1.576709633, 0, 0, 0, 0]


def reorder(model, order):
    idx = [model.states.index(s) for s in order]
    return model.A[np.ix_(idx, idx)], model.B[idx, 0]


def assert_entries_close(actual, expected, rel=0.005, floor=1e-3, printed=0.0):
    """Every entry of magnitude > floor within rel (or within ``printed``, half a unit of the last
    digit the thesis printed, where that is larger); smaller thesis entries within floor absolutely."""
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    big = np.abs(expected) > floor
    tol = np.maximum(rel * np.abs(expected[big]), printed)
    assert np.all(np.abs(actual[big] - expected[big]) <= tol), (actual[big], expected[big])
    np.testing.assert_allclose(actual[~big], expected[~big], atol=floor)


def assert_poles_close(actual, expected, rel=0.005):
    for p in expected:
        nearest = min(actual, key=lambda a: abs(a - p))
        assert abs(nearest - p) <= rel * max(abs(p), 1e-9) + 1e-9, (p, nearest)


def test_eq_3_24_and_poles():
    m = linearize(preset("thesis-ch3"))
    A, B = reorder(m, EQ_3_24_ORDER)
    assert_entries_close(A, EQ_3_24_A)
    assert_entries_close(B, EQ_3_24_B)
    assert_poles_close(m.poles, POLES_3_24)


def test_appendix_a2_without_inductance():
    m = linearize(preset("thesis-appendix-a"), inductance=False)
    assert m.states == ("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity")
    assert_entries_close(m.A, A2_A)
    assert_entries_close(m.B[:, 0], A2_B)


def test_eq_4_23_and_poles():
    m = linearize(preset("thesis-ch4"))
    A, B = reorder(m, EQ_4_23_ORDER)
    # eq. 4.23 prints -0.01 and -0.55 with two decimals; App. B.3 checks them to full precision
    assert_entries_close(A, EQ_4_23_A, printed=0.005)
    assert_entries_close(B, EQ_4_23_B)
    assert_poles_close(m.poles, POLES_4_23)


def test_appendix_b3_without_inductance():
    m = linearize(preset("thesis-ch4"), inductance=False)
    assert_entries_close(m.A, B3_A)
    assert_entries_close(m.B[:, 0], B3_B)


def test_linearization_is_the_jacobian_of_the_nonlinear_model():
    """A small perturbation of the nonlinear model follows A x + B u to first order."""
    from ipcosim.fmus.physics import rhs_for
    p = preset("thesis-ch3")
    m = linearize(p)
    dx = np.array([1e-5, -2e-5, 3e-5, 1e-5, -1e-5])
    f = np.array(rhs_for(p)(dx, 1e-4, p))
    np.testing.assert_allclose(f, m.A @ dx + m.B[:, 0] * 1e-4, rtol=1e-4, atol=1e-9)


def test_cli_json_format():
    out = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", "linearize", "double-mass", "--no-inductance",
                          "--json"], capture_output=True, text=True, check=True).stdout
    doc = json.loads(out)
    assert set(doc) >= {"A", "B", "C", "D", "states", "poles"}
    assert np.shape(doc["A"]) == (6, 6) and np.shape(doc["B"]) == (6, 1)
    assert np.shape(doc["C"]) == (3, 6) and np.shape(doc["D"]) == (3, 1)
    assert_entries_close(doc["A"], B3_A)
    assert all(len(p) == 2 for p in doc["poles"])


@pytest.mark.parametrize("argv, needle", [
    (["linearize", "single-mass", "--preset", "nope", "--json"], "unknown preset 'nope'"),
    (["linearize", "single-mass", "--set", "Mp=-1", "--json"], "Mp = -1.0"),
    (["linearize", "single-mass", "--set", "Lp=nan", "--json"], "Lp = nan"),
    (["linearize", "double-mass", "--preset", "thesis-ch3", "--json"], "single-mass preset"),
    (["linearize", "single-mass", "--set", "Mx=1", "--json"], "no parameter 'Mx'"),
])
def test_cli_bad_input_one_line(argv, needle):
    r = subprocess.run([sys.executable, "-m", "ipcosim.harness.cli", *argv], capture_output=True, text=True)
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], r.stderr
    assert r.stdout == ""


@pytest.mark.parametrize("kw", [{"Mp": 0.0}, {"Lp": -0.3}, {"Ra": float("inf")}, {"Beq": float("nan")}])
def test_bad_parameters_are_named(kw):
    (name, value), = kw.items()
    with pytest.raises(ParameterError, match=name):
        preset("thesis-ch3", **kw)


def test_unknown_preset():
    with pytest.raises(UnknownPresetError, match="thesis-ch9"):
        preset("thesis-ch9")
