"""The master's algorithm with mock slaves (no FMUs): ordering from ModelStructure, algebraic
loops, Gauss-Seidel and Jacobi against hand-written recurrences, step multiples, integer
ticks, the initialization fixed point, and cleanup after every kind of failure."""
from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest
from master_mocks import (
    DISCARD,
    ERROR,
    LOOP_CONNECTIONS,
    OK,
    Factory,
    loop_factory,
    loop_models,
    loop_system,
    model,
    system,
)

from ipcosim.errors import UsageError
from ipcosim.harness.api.engine import Prepared
from ipcosim.harness.master.algorithm import AlgebraicLoopError, StepSizeError, gauss_seidel_order
from ipcosim.harness.master.execution import check_times
from ipcosim.harness.master.manipulators import ScheduledValues
from ipcosim.harness.master.observers import Observer, Progress
from ipcosim.harness.scenario.binding import UnconnectedInputWarning
from ipcosim.harness.scenario.errors import BindingError

K, H = 5.0, 0.01


def run(sysm, factory, **kw):
    kw.setdefault("raise_on_error", False)
    return Prepared(system=sysm, slave_factory=factory, algorithm=kw.pop("algorithm", "gauss-seidel")).run(**kw)


def expected_gauss_seidel(n: int, k: float = K, h: float = H, r: float = 1.0,
                          m: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """x' = u with u held over each step (ZOH), u sampled every m steps without delay: u_j = k (r - x_j)."""
    x = np.zeros(n + 1)
    u = np.zeros(n + 1)
    u[0] = k * (r - x[0])
    for i in range(n):
        x[i + 1] = x[i] + h * u[i]
        u[i + 1] = k * (r - x[i + 1]) if (i + 1) % m == 0 else u[i]
    return x, u


# ------------------------------------------------------------------ ordering
def test_gauss_seidel_order_follows_direct_dependencies_not_ssd_order():
    for ssd_order in (("controller", "plant", "setpoint"), ("plant", "controller", "setpoint"),
                      ("setpoint", "controller", "plant")):
        order = gauss_seidel_order(loop_system(order=ssd_order))
        # the controller samples the plant's and the setpoint's new outputs without delay;
        # setpoint and plant are independent (ties keep the SSD order)
        assert order[-1] == "controller" and sorted(order[:2]) == ["plant", "setpoint"]
        assert order[:2] == [n for n in ssd_order if n != "controller"]


def test_input_without_feedthrough_steps_before_its_source():
    # plant's voltage has no direct feedthrough: the plant steps before the controller that feeds it
    models = {"ctrl": model("Ctrl", outputs=["u"]), "plant": model("Plant", inputs=["u"], outputs=["x"])}
    sysm = system([("ctrl", models["ctrl"]), ("plant", models["plant"])], [("ctrl.u", "plant.u")])
    assert gauss_seidel_order(sysm) == ["plant", "ctrl"]


def test_algebraic_loop_is_reported_with_its_variables():
    models = loop_models()
    leaky = model("Plant", inputs=["voltage"], outputs=["position"], parameters={"x0": 0.0},
                  feedthrough={"position": ["voltage"]})
    sysm = system([("setpoint", models["setpoint"]), ("controller", models["controller"]), ("plant", leaky)],
                  LOOP_CONNECTIONS)
    with pytest.raises(AlgebraicLoopError) as info:
        gauss_seidel_order(sysm)
    loop = info.value.variables
    assert loop[0] == loop[-1]
    assert {"controller.voltage", "plant.voltage", "plant.position", "controller.position"} <= set(loop)
    assert "algebraic loop" in str(info.value) and "plant.voltage" in str(info.value)
    # the run reports it before instantiating anything
    f = loop_factory()
    with pytest.raises(AlgebraicLoopError):
        run(sysm, f, stop_time=0.1, step=H)
    assert f.slaves == {}
    # Jacobi does not need an order
    r = run(sysm, loop_factory(), stop_time=0.1, step=H, algorithm="jacobi")
    assert r.ok


# ------------------------------------------------------------------ stepping
def test_gauss_seidel_is_zero_order_hold_with_zero_delay_sampling():
    r = run(loop_system(), loop_factory(), stop_time=1.0, step=H)
    assert r.ok and r.metadata["order"] == ["setpoint", "plant", "controller"]
    x, u = expected_gauss_seidel(100)
    assert np.array_equal(r["plant.position"], x)
    assert np.array_equal(r["controller.voltage"], u)
    assert np.array_equal(r["plant.voltage"], u)  # connected input column = the value delivered
    assert np.array_equal(r["controller.position"], x)
    assert len(r.data) == 101 and r["time"][-1] == 1.0


def test_jacobi_uses_the_values_of_the_previous_communication_point():
    r = run(loop_system(), loop_factory(), stop_time=1.0, step=H, algorithm="jacobi")
    n = 100
    x = np.zeros(n + 1)
    u = np.zeros(n + 1)
    # every component leaves initialization from the values of initialization mode (as in
    # libcosim): the setpoint's step appears only on leaving, so the controller's first output is 0
    u[0] = 0.0
    for i in range(n):
        x[i + 1] = x[i] + H * u[i]
        u[i + 1] = K * (1.0 - x[i])  # the controller saw x_i, not x_{i+1}
    assert np.array_equal(r["plant.position"], x)
    assert np.array_equal(r["controller.voltage"], u)
    gs = run(loop_system(), loop_factory(), stop_time=1.0, step=H)
    assert not np.array_equal(gs["controller.voltage"], r["controller.voltage"])


def test_controller_with_twice_the_step_as_sample_period_steps_every_second_tick():
    f = loop_factory()
    r = run(loop_system(), f, stop_time=1.0, step=H, set={"controller.sample_period": 2 * H})
    assert r.metadata["step_multiples"] == {"setpoint": 1, "controller": 2, "plant": 1}
    steps = f.slaves["controller"].steps
    assert len(steps) == 50
    assert all(h == pytest.approx(2 * H, abs=1e-15) for _, h in steps)
    assert [t for t, _ in steps] == [pytest.approx(2 * H * j, abs=1e-12) for j in range(50)]
    assert len(f.slaves["plant"].steps) == 100
    x, u = expected_gauss_seidel(100, m=2)
    assert np.array_equal(r["plant.position"], x)
    assert np.array_equal(r["controller.voltage"], u)


def test_jacobi_multirate_publishes_at_the_end_of_the_period():
    f = loop_factory()
    r = run(loop_system(), f, stop_time=0.2, step=H, set={"controller.sample_period": 2 * H},
            algorithm="jacobi")
    assert len(f.slaves["controller"].steps) == 10
    u = r["controller.voltage"]
    assert np.all(u[1::2] == u[0:-1:2])  # published at the end of each 2-tick period: held in between
    assert not np.all(u[2::2] == u[1:-1:2])


def test_sample_period_that_the_step_does_not_divide_is_rejected():
    with pytest.raises(StepSizeError,
                       match=r"controller.sample_period = 0.015 s is not a whole multiple of the step 0.01 s"):
        run(loop_system(), loop_factory(), stop_time=1.0, step=H, set={"controller.sample_period": 0.015})
    with pytest.raises(StepSizeError, match="sample_period"):
        run(loop_system(), loop_factory(), stop_time=1.0, step=0.02)  # period 0.01 < step


@pytest.mark.parametrize("kw, match", [({"stop_time": 0.0}, "--stop-time 0.0"),
                                       ({"stop_time": -1.0}, "--stop-time -1.0"),
                                       ({"step": 0.0}, "--step 0.0"), ({"step": -0.01}, "--step -0.01")])
def test_bad_stop_time_or_step(kw, match):
    """Refused as the run's options are made, with the command line's message, as ipcosim.run refuses them."""
    args = {"stop_time": 1.0, "step": H, **kw}
    f = loop_factory()
    with pytest.raises(UsageError, match=f"^{match}: must be a positive number of seconds$"):
        run(loop_system(), f, **args)
    assert f.slaves == {}  # rejected before anything was instantiated


def test_time_is_integer_ticks_never_accumulated():
    assert sum([0.001] * 1000) != 1.0  # what accumulating would give
    f = loop_factory()
    r = run(loop_system(), f, stop_time=1.0, step=0.001, set={"controller.sample_period": 0.001})
    times = [t for t, _ in f.slaves["plant"].steps]
    assert times == [(n * 1_000_000) / 1e9 for n in range(1000)]
    assert r["time"][-1] == 1.0 and r["time"][700] == 0.7


# ------------------------------------------------------------------ initialization
def _gain_chain():
    src = model("Src", outputs=["y"], parameters={"a": 3.0})
    g = model("Gain", inputs=["u"], outputs=["y"], parameters={"g": 2.0}, feedthrough={"y": ["u"]})
    return system([("c", g), ("b", g), ("a", src)], [("a.y", "b.u"), ("b.y", "c.u")])


def _gain_get(s):
    s["y"] = s["g"] * s["u"]


def test_initialization_propagates_outputs_to_inputs_until_a_fixed_point():
    f = Factory(a={"get_fn": lambda s: s.__setitem__("y", s["a"])}, b={"get_fn": _gain_get}, c={"get_fn": _gain_get})
    r = run(_gain_chain(), f, stop_time=0.1, step=H)
    assert r.ok
    assert r["c.y"][0] == 12.0 and r["b.y"][0] == 6.0 and r["c.u"][0] == 6.0
    assert 1 <= r.metadata["initialization_iterations"] <= 2


def test_initialization_that_does_not_settle_names_the_variables_and_frees_everything():
    # outputs grow with every read although ModelStructure declares no feedthrough: no fixed point
    grow = model("Grow", inputs=["u"], outputs=["y"])
    sysm = system([("a", grow), ("b", grow)], [("a.y", "b.u"), ("b.y", "a.u")])
    bump = {"get_fn": lambda s: s.__setitem__("y", s["u"] + 1.0)}
    f = Factory(a=bump, b=bump)
    r = Prepared(system=sysm, slave_factory=f).run(stop_time=0.1, step=H, raise_on_error=False,
                                                   max_init_iterations=7)
    assert "did not reach a fixed point in 7 iterations" in r.error
    assert "a.u" in r.error and "b.u" in r.error
    assert len(r.data) == 0
    for s in f.slaves.values():
        assert s.calls[-2:] == ["terminate", "free"]


# ------------------------------------------------------------------ failures and cleanup
def _failing_plant(status):
    def step(s, t, h):
        if t >= 0.5 - 1e-12:
            return status
        s["position"] = s["position"] + h * s["voltage"]
        return OK
    return step


@pytest.mark.parametrize("status, name", [(ERROR, "fmi2Error"), (DISCARD, "fmi2Discard")])
def test_failing_step_keeps_results_up_to_the_failure_and_frees_every_instance(status, name):
    f = loop_factory(plant={"step_fn": _failing_plant(status)})
    r = run(loop_system(), f, stop_time=1.0, step=H)
    # a Discard says what the FMU's status query returned (here: not terminated)
    query = " (the status query returned false, the FMU did not end the simulation)" if status == DISCARD else ""
    assert r.error == f"component plant (Plant): fmi2DoStep returned {name} at t = 0.5 s{query}"
    assert r["time"][-1] == 0.5 and len(r.data) == 51
    x, _ = expected_gauss_seidel(50)
    assert np.array_equal(r["plant.position"], x)
    for comp, s in f.slaves.items():
        assert s.calls[-1] == "free", comp
        # after fmi2Error only fmi2FreeInstance is allowed; after a discard terminate is
        assert ("terminate" in s.calls) == (comp != "plant" or status == DISCARD)
    assert r.metadata["status"] == "failed"
    with pytest.raises(Exception) as info:
        run(loop_system(), loop_factory(plant={"step_fn": _failing_plant(status)}), stop_time=1.0, step=H,
            raise_on_error=True)
    assert info.value.result is not None and len(info.value.result.data) == 51


def test_exception_in_a_python_slave_is_an_error_status_with_its_message():
    def explode(s, t, h):
        if t > 0.25:
            raise RuntimeError("sensor cable unplugged")
        return OK
    r = run(loop_system(), loop_factory(controller={"step_fn": explode}), stop_time=1.0, step=H)
    assert "fmi2Error at t = 0.26 s: sensor cable unplugged" in r.error


def test_non_finite_output_names_variable_and_time():
    def step(s, t, h):
        s["position"] = math.nan if t + h > 0.3 + 1e-12 else s["position"] + h * s["voltage"]
        return OK
    f = loop_factory(plant={"step_fn": step})
    r = run(loop_system(), f, stop_time=1.0, step=H)
    assert r.error == "component plant (Plant): output plant.position = nan at t = 0.31 s (non-finite value)"
    assert len(r.data) == 32 and math.isnan(r["plant.position"][-1]) and np.isfinite(r["plant.position"][:-1]).all()
    assert all(s.calls[-1] == "free" for s in f.slaves.values())


def test_instantiation_failure_frees_the_instances_already_made():
    f = loop_factory()
    f.fail_instantiate = {"plant"}
    r = run(loop_system(order=("setpoint", "controller", "plant")), f, stop_time=0.1, step=H)
    assert "fmi2Instantiate failed" in r.error
    assert f.slaves["setpoint"].calls[-1] == "free" and f.slaves["controller"].calls[-1] == "free"
    assert "free" not in f.slaves["plant"].calls


def test_keyboard_interrupt_still_frees_every_instance():
    f = loop_factory()
    sysm = loop_system()
    ex = Prepared(system=sysm, slave_factory=f).execution(stop_time=1.0, step=H)

    class Interrupting(Observer):
        def next_tick(self, n):
            return 20

        def step(self, execution, n):
            raise KeyboardInterrupt

    ex.observers.append(Interrupting())
    with pytest.raises(KeyboardInterrupt) as info:
        ex.run()
    assert all(s.calls[-1] == "free" for s in f.slaves.values())
    partial = info.value.result
    assert partial.error == "interrupted at t = 0.2 s" and len(partial.data) == 21


# ------------------------------------------------------------------ observers and manipulators
class Counting(Observer):
    def __init__(self, every):
        self.every, self.seen, self.started, self.finished = every, [], False, "not called"

    def start(self, execution):
        self.started = execution.tick == 0

    def next_tick(self, n):
        return (n // self.every + 1) * self.every

    def step(self, execution, n):
        self.seen.append((n, execution.time_of(n), execution.get("plant", "position")))

    def finish(self, execution, error):
        self.finished = error

    def metrics(self):
        return {"observed_steps": len(self.seen)}


def test_observers_are_called_at_the_ticks_they_ask_for_with_the_state_of_that_time():
    obs = Counting(every=10)
    r = run(loop_system(), loop_factory(), stop_time=1.0, step=H, observers=[obs])
    assert obs.started and obs.finished is None
    assert [n for n, _, _ in obs.seen] == list(range(10, 101, 10))
    assert all(x == r["plant.position"][n] for n, _, x in obs.seen)
    assert r.metrics["observed_steps"] == 10


def test_scheduled_manipulator_changes_a_parameter_before_the_tick_at_its_time():
    base = run(loop_system(), loop_factory(), stop_time=1.0, step=H)
    r = run(loop_system(), loop_factory(), stop_time=1.0, step=H,
            manipulators=[ScheduledValues([(0.5, "setpoint", "amplitude", 2.0)])])
    assert np.array_equal(r["plant.position"][:52], base["plant.position"][:52])
    assert r["setpoint.reference"][50] == 1.0 and r["setpoint.reference"][51] == 2.0
    assert r["plant.position"][-1] > 1.5 > base["plant.position"][-1]


def test_progress_bar_draws_only_after_its_delay():
    stream = io.StringIO()
    bar = Progress(stream=stream, delay=0.0, force=True)
    run(loop_system(), loop_factory(), stop_time=1.0, step=H, observers=[bar])
    assert "100.0%" in stream.getvalue() and stream.getvalue().endswith("\n")
    quiet = io.StringIO()
    run(loop_system(), loop_factory(), stop_time=1.0, step=H,
        observers=[Progress(stream=quiet, delay=60.0, force=True)])
    assert quiet.getvalue() == ""


# ------------------------------------------------------------------ overrides and warnings
def test_overrides_are_applied_after_the_bindings():
    sysm = loop_system(bindings={"controller": {"k": 1.0}})
    r = run(sysm, loop_factory(), stop_time=1.0, step=H)
    x1, u1 = expected_gauss_seidel(100, k=1.0)
    assert np.array_equal(r["controller.voltage"], u1)
    r = run(sysm, loop_factory(), stop_time=1.0, step=H, set={"controller.k": "2.5"})
    x2, u2 = expected_gauss_seidel(100, k=2.5)
    assert np.array_equal(r["controller.voltage"], u2)
    assert r.metadata["overrides"] == {"controller.k": 2.5}


@pytest.mark.parametrize("key, value, match", [
    ("controller.nope", "1", "has no variable 'nope'"),
    ("ctrl.k", "1", "no component 'ctrl'"),
    ("controller.k", "abc", "'abc' is not a valid Real"),
    ("plant.position", "1", "output/continuous and cannot be set"),
    ("controller.reference", "1", "connected to setpoint.reference"),
])
def test_bad_overrides(key, value, match):
    f = loop_factory()
    with pytest.raises(BindingError, match=match):
        run(loop_system(), f, stop_time=0.1, step=H, set={key: value})
    assert f.slaves == {}


def test_a_set_key_without_component_is_refused_as_the_command_line_refuses_it():
    f = loop_factory()
    with pytest.raises(UsageError, match=r"^--set k=1: expected COMPONENT\.VARIABLE=VALUE$"):
        run(loop_system(), f, stop_time=0.1, step=H, set={"k": "1"})
    assert f.slaves == {}


@pytest.mark.parametrize("start, stop, step, match", [(0.0, 0.0, H, "stop time"), (0.0, 1.0, 0.0, "step size"),
                                                      (0.0, 1.0, -H, "step size")])
def test_the_master_checks_its_times_itself(start, stop, step, match):
    """The master's own check, for a caller of the master without run options."""
    with pytest.raises(StepSizeError, match=match):
        check_times(start, stop, step)


def test_unconnected_input_is_a_warning_naming_it():
    models = loop_models()
    sysm = system([(n, models[n]) for n in ("setpoint", "controller", "plant")], LOOP_CONNECTIONS[:2])
    assert any("input plant.voltage is not connected" in w for w in sysm.warnings)
    with pytest.warns(UnconnectedInputWarning, match="plant.voltage"):
        Prepared(system=sysm, slave_factory=loop_factory(), warn=False)  # no warning yet...
        from ipcosim.harness.scenario.binding import warn_all
        warn_all(sysm)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = run(sysm, loop_factory(), stop_time=0.1, step=H)
    assert r.ok and np.all(r["plant.voltage"] == 0.0) and np.all(r["plant.position"] == 0.0)


def test_units_convert_through_their_definitions_and_mismatches_are_refused():
    from ipcosim.harness.scenario.structure import Unit

    m = Unit("m", (0, 1, 0, 0, 0, 0, 0, 0))
    mm = Unit("mm", (0, 1, 0, 0, 0, 0, 0, 0), factor=1e-3)
    rad = Unit("rad", (0, 0, 0, 0, 0, 0, 0, 1))
    src = model("Src", outputs=["y"], parameters={"a": 2.0}, units={"y": "m"})
    dst = model("Dst", inputs=["u"], outputs=["v"], units={"u": "mm", "v": "mm"}, feedthrough={"v": ["u"]})
    sysm = system([("a", src), ("b", dst)], [("a.y", "b.u")], units={"m": m, "mm": mm})
    link = sysm.links[0]
    assert link.factor == pytest.approx(1000.0) and link.offset == 0.0
    f = Factory(a={"get_fn": lambda s: s.__setitem__("y", s["a"])},
                b={"get_fn": lambda s: s.__setitem__("v", s["u"])})
    r = run(sysm, f, stop_time=0.05, step=H)
    assert np.all(r["b.u"] == pytest.approx(2000.0)) and r["b.v"][0] == pytest.approx(2000.0)
    bad = model("Dst", inputs=["u"], outputs=["v"], units={"u": "rad"})
    with pytest.raises(BindingError, match="unit 'm' does not match 'rad'"):
        system([("a", src), ("b", bad)], [("a.y", "b.u")], units={"m": m, "rad": rad})


def test_a_traceback_through_the_generated_loop_shows_its_source() -> None:
    """The generated stepping loop is registered with linecache: a traceback through it shows
    the line that failed, not just a file name."""
    import ctypes
    import linecache
    import traceback

    from ipcosim.harness.master.algorithm import GAUSS_SEIDEL, TimeBase
    from ipcosim.harness.master.plan import Block
    from ipcosim.harness.master.pyloop import compile_loop

    def failing_step(*args):
        return 1 / 0

    none = (ctypes.c_uint * 0)()
    block = Block(index=0, name="broken", handle=None, do_step=failing_step, get_real=lambda *a: 0,
                  set_real=lambda *a: 0, out_vrs=none, in_vrs=none, out_values=(ctypes.c_double * 0)(),
                  in_values=(ctypes.c_double * 0)(), n_out=0, n_in=0, multiple=1)
    run, source = compile_loop([block], [0], GAUSS_SEIDEL, TimeBase.make(0.0, 1.0, 0.1))
    frames = []
    try:
        run(0, 1, 0, 0, 8)
    except ZeroDivisionError as exc:
        frames = traceback.extract_tb(exc.__traceback__)
    loop = [f for f in frames if f.filename.startswith("<ipcosim stepping loop")]
    assert loop and loop[-1].line, frames
    assert loop[-1].line.strip() in source
    assert linecache.getline(loop[-1].filename, loop[-1].lineno).strip() == loop[-1].line.strip()
