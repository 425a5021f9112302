"""Physics sanity of the stepped plant (ipcosim.fmus.plant.Plant): rest, equilibria and their stability,
energy balance, mirror symmetry, direction of the motor force, amplifier limit, Coulomb
friction, and the failure report for a non-finite state."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ipcosim.fmus.params import preset
from ipcosim.fmus.plant import Plant, PlantStepError

H = 1e-3
ANGLE = {"thesis-ch3": 2, "thesis-appendix-a": 2, "thesis-ch4": 4}
PRESETS = list(ANGLE)


def run(plant: Plant, seconds: float, voltage=0.0) -> np.ndarray:
    rows = [plant.x.copy()]
    for k in range(int(round(seconds / H))):
        v = voltage(k * H) if callable(voltage) else voltage
        plant.do_step(k * H, H, v)
        rows.append(plant.x.copy())
    return np.array(rows)


def state(name: str, angle: float = 0.0, **named: float) -> np.ndarray:
    p = Plant(preset(name))
    x = np.zeros(len(p.state_names))
    x[ANGLE[name]] = angle
    for key, value in named.items():
        x[p.state_names.index(key)] = value
    return x


def energy(params, x: np.ndarray) -> float:
    """Mechanical + magnetic energy [J]; with zero voltage it can only decrease:
    dE/dt = vA i - Ra i^2 - (viscous and Coulomb losses), because N Kt / rg = N Kb / rg."""
    ml = 0.5 * params.Mp * params.Lp
    m22 = params.Mp * params.Lp ** 2 / 3
    if x.shape[0] == 5:
        _, xd, th, thd, i = x
        kin = 0.5 * (params.Meq + params.Mp) * xd ** 2 - ml * math.cos(th) * xd * thd + 0.5 * m22 * thd ** 2
        return kin + ml * params.g * math.cos(th) + 0.5 * params.La * i ** 2
    xa, xad, xc, xcd, th, thd, i = x
    kin = (0.5 * params.Ma_eq * xad ** 2 + 0.5 * (params.Mc + params.Mp) * xcd ** 2
           - ml * math.cos(th) * xcd * thd + 0.5 * m22 * thd ** 2)
    return kin + ml * params.g * math.cos(th) + 0.5 * params.K * (xa - xc) ** 2 + 0.5 * params.La * i ** 2


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("angle", [0.0, math.pi])
def test_rest_stays_at_rest(name: str, angle: float) -> None:
    """Zero input from an equilibrium (upright or hanging) stays there."""
    x0 = state(name, angle)
    traj = run(Plant(preset(name), x0), 2.0)
    # exactly for upright; hanging, sin(float(pi)) = 1.2e-16 leaves a rounding-level torque
    assert np.max(np.abs(traj - x0)) < (1e-15 if angle == 0.0 else 1e-10)


@pytest.mark.parametrize("name", PRESETS)
def test_hanging_down_is_stable(name: str) -> None:
    x0 = state(name, math.pi + 0.2)
    traj = run(Plant(preset(name), x0), 20.0)
    a = ANGLE[name]
    first, last = np.max(np.abs(traj[:1000, a] - math.pi)), np.max(np.abs(traj[-1000:, a] - math.pi))
    assert first > 0.19
    assert last < 0.2 * first  # decays (pivot damping and the cart's viscous/electrical losses)
    assert np.max(np.abs(traj[-1, :])) < 10  # nothing runs away


@pytest.mark.parametrize("name", PRESETS)
def test_upright_is_unstable(name: str) -> None:
    traj = run(Plant(preset(name), state(name, 1e-4)), 2.0)
    assert abs(traj[-1, ANGLE[name]]) > 0.1


@pytest.mark.parametrize("name", PRESETS)
def test_energy_never_increases_without_input(name: str) -> None:
    params = preset(name)
    x0 = state(name, 2.5, **({"cart_velocity": 0.3} if name != "thesis-ch4" else {"active_cart_velocity": 0.3}))
    traj = run(Plant(params, x0), 3.0)
    e = np.array([energy(params, x) for x in traj])
    assert e[0] - e[-1] > 0.01  # something is dissipated
    assert np.max(np.diff(e)) < 1e-9  # ... and nothing created (integration error far below)


@pytest.mark.parametrize("name", PRESETS)
def test_energy_balance_with_input(name: str) -> None:
    """E(T) - E(0) = int (vA i - Ra i^2 - viscous losses) dt, with the damping terms of ipcosim.fmus.physics.

    Fine steps (20 us) resolve the current's 70 us time constant for the power integral."""
    params = preset(name)
    plant = Plant(params, state(name, math.pi))
    h, n = 2e-5, 25000
    v = 3.0 * np.sin(7.0 * h * np.arange(n))
    rows = [plant.x.copy()]
    for k in range(n):
        plant.do_step(k * h, h, float(v[k]))
        rows.append(plant.x.copy())
    x = np.array(rows)
    i = x[:, -1]
    if x.shape[1] == 5:
        losses = params.Beq * x[:, 1] ** 2 + params.Bp * x[:, 3] ** 2
    else:  # Ba xa'^2 - 2 Bf xa' xc' + (Bf + Bc) xc'^2 = (Ba - Bf) xa'^2 + Bf (xa' - xc')^2 + Bc xc'^2
        losses = (params.Ba * x[:, 1] ** 2 - 2 * params.Bf * x[:, 1] * x[:, 3]
                  + (params.Bf + params.Bc) * x[:, 3] ** 2 + params.Bp * x[:, 5] ** 2)
    p_start = v * i[:-1] - params.Ra * i[:-1] ** 2 - losses[:-1]  # voltage held over each step
    p_end = v * i[1:] - params.Ra * i[1:] ** 2 - losses[1:]
    supplied = float(np.sum(0.5 * (p_start + p_end) * h))
    de = energy(params, x[-1]) - energy(params, x[0])
    assert abs(de) > 1e-3
    assert abs(de - supplied) < 1e-3 * abs(de)


@pytest.mark.parametrize("name", PRESETS)
def test_mirror_symmetry(name: str) -> None:
    """x -> -x, theta -> -theta (about upright), V -> -V gives the mirrored trajectory."""
    x0 = state(name, 0.1)
    x0[1] = 0.05
    v = lambda t: 4.0 * math.sin(9.0 * t)  # noqa: E731
    a = run(Plant(preset(name), x0), 1.5, v)
    b = run(Plant(preset(name), -x0), 1.5, lambda t: -v(t))
    assert np.max(np.abs(a)) > 0.05
    assert np.max(np.abs(a + b)) < 1e-12


@pytest.mark.parametrize("name", PRESETS)
def test_positive_voltage_pushes_cart_to_plus_x(name: str) -> None:
    traj = run(Plant(preset(name), state(name, math.pi)), 0.3, 3.0)
    assert traj[-1, 0] > 1e-3 and traj[-1, 1] > 0  # motor-driven cart: position and velocity
    assert traj[-1, -1] > 0  # motor current
    if name == "thesis-ch4":
        assert traj[-1, 2] > 1e-3  # the spring drags the passive cart along


@pytest.mark.parametrize("name", PRESETS)
def test_amplifier_limit(name: str) -> None:
    """Commands beyond +-voltage_limit act as the limit itself."""
    a = run(Plant(preset(name), state(name, math.pi)), 0.2, 25.0)
    b = run(Plant(preset(name), state(name, math.pi)), 0.2, 10.0)
    c = run(Plant(preset(name, voltage_limit=5.0), state(name, math.pi)), 0.2, 25.0)
    assert np.array_equal(a, b)
    assert c[-1, 0] < 0.7 * b[-1, 0]


def test_steady_current_and_speed_single_mass() -> None:
    """Constant voltage, pendulum hanging: the cart reaches the speed where motor force = viscous force."""
    p = preset("thesis-ch3", Bp=0.5)  # a well-damped pendulum, so that nothing swings at the end
    traj = run(Plant(p, state("thesis-ch3", math.pi)), 3.0, 2.0)
    # i = (V - Ke v)/Ra and Kf i = Beq v  =>  v = Kf V / (Ra Beq + Kf Ke)
    v_ss = p.force_per_amp * 2.0 / (p.Ra * p.Beq + p.force_per_amp * p.emf_per_velocity)
    assert traj[-1, 1] == pytest.approx(v_ss, rel=1e-3)
    assert traj[-1, 4] == pytest.approx((2.0 - p.emf_per_velocity * v_ss) / p.Ra, rel=1e-3)


def test_coulomb_friction_holds_the_cart_back() -> None:
    free = run(Plant(preset("thesis-ch3"), state("thesis-ch3", math.pi)), 0.5, 1.0)
    stuck = run(Plant(preset("thesis-ch3", b=3.0), state("thesis-ch3", math.pi)), 0.5, 1.0)
    assert free[-1, 0] > 1e-3
    assert stuck[-1, 0] < 0.5 * free[-1, 0]


def _pushed(name: str, breakaway: float, force: float, seconds: float = 2.0) -> list[float]:
    """State after ``seconds`` of a constant voltage that pushes the motor cart with ``force`` [N] at stall, the
    pendulum hanging, every cart with Coulomb (breakaway) force ``breakaway`` [N]."""
    kw = {"b": breakaway} if name == "thesis-ch3" else {"b1": breakaway, "b2": breakaway}
    p = preset(name, **kw)
    plant = Plant(p, state(name, math.pi))
    volts = force * p.Ra / p.force_per_amp
    for k in range(round(seconds / H)):
        plant.do_step(k * H, H, volts)
    return plant.state


@pytest.mark.parametrize("name", ["thesis-ch3", "thesis-ch4"])
def test_a_cart_pushed_below_its_breakaway_force_does_not_move(name: str) -> None:
    """Stick-slip (Karnopp): 95 % of the breakaway force for 2 s leaves every cart exactly where it was; 120 %
    moves the motor cart by millimetres (a smoothed Coulomb law creeps under any force)."""
    stuck = _pushed(name, 0.1, 0.095)
    carts = (0,) if name == "thesis-ch3" else (0, 2)
    assert all(stuck[i] == 0.0 and stuck[i + 1] == 0.0 for i in carts), stuck
    assert _pushed(name, 0.1, 0.12)[0] > 1e-4


def test_karnopp_force_sticks_inside_the_band_and_slides_outside() -> None:
    from ipcosim.fmus.physics import karnopp

    assert karnopp(0.0, 0.05, 0.1, 1e-3) == 0.05          # stuck: balances the applied force
    assert karnopp(5e-4, -0.3, 0.1, 1e-3) == -0.1         # breaking away: the breakaway force
    assert karnopp(-0.02, 0.05, 0.1, 1e-3) == -0.1        # sliding: kinetic, against the motion
    assert karnopp(0.02, 5.0, 0.1, 1e-3) == 0.1


def test_a_sliding_cart_sticks_where_it_stops() -> None:
    """Thrown at 5 cm/s against 0.3 N of friction (no motor force), the cart stops within
    v^2 M / (2 F) and stays there: no creep."""
    p = preset("thesis-ch3", b=0.3)
    x0 = state("thesis-ch3", math.pi)
    x0[1] = 0.05
    plant = Plant(p, x0)
    positions = []
    for k in range(1500):
        plant.do_step(k * H, H, 0.0)
        plant.set_state([*plant.state[:4], 0.0])  # the motor shorted out: no back-EMF braking
        positions.append(plant.state[0])
    assert positions[-1] == positions[700] and plant.state[1] == 0.0
    assert 0.0 < positions[-1] < 0.05 ** 2 * (p.Meq + p.Mp) / (2 * 0.3) * 1.5


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("name", ["thesis-ch3", "thesis-ch4"])
def test_non_finite_state_fails_the_step_with_time_and_state(name: str) -> None:
    x0 = state(name, 0.3, pendulum_velocity=1e160)
    plant = Plant(preset(name), x0)
    with pytest.raises(PlantStepError) as info:
        plant.do_step(0.25, H, 1.0)
    msg = str(info.value)
    assert "t = 0.25 s" in msg and "pendulum_velocity = 1e+160" in msg and "pendulum_angle = 0.3" in msg
    assert np.array_equal(plant.x, x0)  # left at its value at t


def test_bad_step_and_voltage_are_refused() -> None:
    plant = Plant(preset("thesis-ch3"))
    with pytest.raises(ValueError, match="step size"):
        plant.do_step(0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="voltage = nan V"):
        plant.do_step(0.0, H, float("nan"))
