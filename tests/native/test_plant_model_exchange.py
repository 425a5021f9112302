"""Model exchange of the native plants (``ipcosim.fmus.hybrid``, ``harness/native/exchange.py``), FMI 2.0 and 3.0.

Checked against the standard's validator (fmpy), against closed forms (the motor current of a cart held by
static friction, the breakaway instant, an end stop), and against the co-simulation kernel: fmpy's CVode
integrating the model-exchange plant under the voltage a co-simulation run of the closed loop applied.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ipcosim.toolchain import find_compiler

CC = find_compiler()
pytestmark = [pytest.mark.integration, pytest.mark.skipif(CC is None, reason="no C compiler (set CC or install gcc)")]
PLANTS = ("IP02SingleMass", "IP02DoubleMass")


def _plants(native_fmus: tuple[Path, Path], native_fmus3: Path) -> list[Path]:
    return [folder / f"{name}.fmu" for folder in (native_fmus[1], native_fmus3) for name in PLANTS]


def _constant(volts: float, stop: float) -> np.ndarray:
    sig = np.zeros(2, dtype=[("time", float), ("voltage", float)])
    sig["time"], sig["voltage"] = (0.0, stop), volts
    return sig


def _me(fmu: Path, sig: np.ndarray, stop: float, **start: float) -> np.ndarray:
    import fmpy

    return fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", input=sig, stop_time=stop, start_values=start,
                             relative_tolerance=1e-10, output_interval=1e-3, record_events=True)


def test_plants_offer_both_interfaces_and_validate(native_fmus: tuple[Path, Path], native_fmus3: Path) -> None:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    for fmu in _plants(native_fmus, native_fmus3):
        assert validate_fmu(str(fmu)) == [], fmu
        md = read_model_description(str(fmu))
        assert md.modelExchange is not None and md.coSimulation is not None, fmu
        states = [d.variable.derivative.name for d in md.derivatives]
        assert states == [f"state.{n}" for n in _state_names(fmu.stem)], fmu
        assert md.numberOfEventIndicators == 2 * (1 if "Single" in fmu.stem else 2), fmu


def test_plants_pass_vdmcheck(native_fmus: tuple[Path, Path]) -> None:
    """VDMCheck2 (the FMI 2.0 static rules, model exchange's included: states, derivatives, initial
    unknowns) finds nothing in either plant."""
    from fmi_helpers import assert_vdmcheck_clean

    for name in PLANTS:
        assert_vdmcheck_clean(native_fmus[1] / f"{name}.fmu")


def _state_names(model: str) -> tuple[str, ...]:
    from ipcosim.fmus.physics import state_names

    return state_names("single-mass" if "Single" in model else "double-mass")


def test_cart_held_by_static_friction_and_its_breakaway(native_fmus: tuple[Path, Path], native_fmus3: Path) -> None:
    """Single mass upright at rest, constant voltage V: while the motor force kf i stays below the Coulomb
    force b the cart stays exactly where it is and i(t) = V/Ra (1 - exp(-Ra t/La)) (no back EMF); it breaks
    away at kf i(t*) = b, t* = -La/Ra ln(1 - Ra b/(kf V)), an event located by the solver."""
    from ipcosim.fmus.params import DEFAULT_PRESET, PRESETS, make

    p = make("single-mass", **dict(PRESETS[DEFAULT_PRESET["single-mass"]][1]))
    volts = 1.0
    for folder in (native_fmus[1], native_fmus3):
        fmu = folder / "IP02SingleMass.fmu"
        held = _me(fmu, _constant(volts, 0.05), 0.05, b=10.0)
        # at rest the cart's derivatives are exactly 0; CVode's dense linear algebra leaves ~1e-24 of rounding
        assert np.max(np.abs(held["cart_position"])) < 1e-15 and np.max(np.abs(held["cart_velocity"])) < 1e-15
        current = volts / p.Ra * (1.0 - np.exp(-p.Ra * held["time"] / p.La))
        assert np.max(np.abs(held["motor_current"] - current)) < 1e-7
        b = 0.5 * p.force_per_amp * volts / p.Ra
        t_star = -p.La / p.Ra * math.log(1.0 - p.Ra * b / (p.force_per_amp * volts))
        slip = _me(fmu, _constant(volts, 0.05), 0.05, b=b)
        ticks = slip["time"] / 1e-3
        events = slip["time"][np.abs(ticks - np.round(ticks)) > 1e-6]  # rows off the output grid: events
        print(f"{fmu.parent.name}: breakaway event at {events[0]:.12g} s, closed form {t_star:.12g} s")
        assert abs(events[0] - t_star) < 1e-8
        assert slip["cart_velocity"][-1] > 1e-3  # and it slides
        assert np.max(np.abs(slip["cart_position"][slip["time"] < t_star - 1e-8])) < 1e-15


def test_end_stop_holds_the_cart(native_fmus: tuple[Path, Path]) -> None:
    """Double mass pushed at 2 V into an end stop at 1 cm: no cart goes past it further than the solver's
    event location (the row recorded at an event is the state before its update), and the active cart is
    put on it and stopped there (velocity 0) while the voltage pushes it on."""
    fmu = native_fmus[1] / "IP02DoubleMass.fmu"
    stop = 0.01
    r = _me(fmu, _constant(2.0, 0.4), 0.4, end_stop=stop)
    for cart in ("active_cart", "passive_cart"):
        worst = np.max(np.abs(r[f"{cart}_position"]))
        print(f"{cart}: furthest {worst - stop:.3g} m beyond the stop")
        assert worst <= stop + 1e-9
    at = r["active_cart_position"] == stop
    assert at.sum() > 10 and np.max(np.abs(r["active_cart_velocity"][at])) < 1e-15


def test_input_delay_is_refused_in_model_exchange(native_fmus: tuple[Path, Path]) -> None:
    import fmpy
    from fmpy.fmi1 import FMICallException

    log: list[str] = []
    with pytest.raises(FMICallException):
        fmpy.simulate_fmu(str(native_fmus[1] / "IP02SingleMass.fmu"), fmi_type="ModelExchange", stop_time=0.01,
                          start_values={"input_delay": 0.001}, logger=lambda *a: log.append(str(a[-1])))
    assert any("input_delay" in line and "model exchange" in line for line in log), log


@pytest.mark.parametrize("scenario,model", [("single-mass-lqr", "IP02SingleMass"),
                                            ("double-mass-lqr", "IP02DoubleMass")])
def test_model_exchange_follows_the_cosimulation_kernel(scenario: str, model: str, native_fmus: tuple[Path, Path],
                                                        native_fmus3: Path) -> None:
    """CVode (rtol 1e-10) on the model-exchange plant, under the voltage the plant held in each step of the
    co-simulation run of the closed loop, against the co-simulation plant's states at every 1 ms sample.

    Over 0.3 s: the difference is the fixed-step kernel's own error (ETDRK4 at 1 ms, docs/plant.md),
    1e-7 m and 1e-6 rad. Over a longer replay it is no test of either: without the controller's feedback
    the upright pendulum amplifies any difference at its unstable pole (e^(7 t))."""
    import ipcosim

    stop = 0.3
    cs = ipcosim.run(scenario, fmus="native", fmu_dirs=[native_fmus[1]], stop_time=stop).data
    t, u = cs["time"], cs["plant.voltage"]
    sig = np.zeros(2 * len(t) - 2, dtype=[("time", float), ("voltage", float)])
    sig["time"], sig["voltage"] = np.repeat(t, 2)[1:-1], np.repeat(u[:-1], 2)  # held over each step
    names = _state_names(model)
    results = [_me(folder / f"{model}.fmu", sig, stop) for folder in (native_fmus[1], native_fmus3)]
    for r in results:
        r = r[np.r_[np.diff(r["time"]) > 0, True]]  # one row per instant (events repeat it)
        for n in names:
            diff = np.max(np.abs(np.interp(t, r["time"], r[n]) - cs[f"plant.{n}"]))
            print(f"{scenario}: {n} max |ME - CS| {diff:.3g}")
            bound = {"m": 1e-6, "rad": 5e-6}.get(_unit(n), 5e-5)
            assert diff < bound, n
    assert np.max(np.abs(results[0][names[0]] - results[1][names[0]])) <= 1e-12  # FMI 3.0 = FMI 2.0


def _unit(name: str) -> str:
    from ipcosim.fmus.physics import STATE_UNITS

    return STATE_UNITS[name]


class _Loop:
    """The plant and the native LQR controller in a closed loop sampled at ``h``, the plant either
    co-simulated (``fmi2DoStep``) or integrated through its model exchange by fmpy's CVode (the solver
    ``simulate_fmu`` uses) as a model-exchange host does: at each sample instant the controller's new
    voltage is set in Event Mode, the event iteration run and the solver restarted; state events inside
    a sample interval are located by CVode and handled the same way."""

    def __init__(self, folder: Path, model: str, law: str, exchange: bool, start: dict[str, float]) -> None:
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        self.exchange = exchange
        self.plant, self.pvr, pmd = self._open(folder / f"{model}.fmu", FMU2Model if exchange else FMU2Slave,
                                              extract, read_model_description)
        self.law, self.lvr, _ = self._open(folder / f"{law}.fmu", FMU2Slave, extract, read_model_description)
        self.measured = [v.name for v in pmd.modelVariables if v.causality == "output"
                         and v.name in self.lvr]
        self.nx, self.nz = pmd.numberOfContinuousStates, pmd.numberOfEventIndicators
        for fmu, vr in ((self.plant, self.pvr), (self.law, self.lvr)):
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            for name, value in start.items():
                if name in vr and fmu is self.plant:
                    fmu.setReal([vr[name]], [value])
            fmu.exitInitializationMode()

    @staticmethod
    def _open(fmu: Path, cls: type, extract: object, read: object) -> tuple[object, dict[str, int], object]:
        md = read(str(fmu))  # type: ignore[operator]
        unzipped = extract(str(fmu))  # type: ignore[operator]
        instance = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=fmu.stem, instanceName=fmu.stem)
        instance.instantiate()
        return instance, {v.name: v.valueReference for v in md.modelVariables}, md

    def _settle(self) -> None:
        more = True
        while more:
            more = self.plant.newDiscreteStates()[0]
        self.plant.enterContinuousTimeMode()

    def run(self, h: float, steps: int) -> np.ndarray:
        from fmpy.sundials import CVodeSolver

        names = list(_state_names(self.plant.modelIdentifier))
        if self.exchange:
            self._settle()
            solver = CVodeSolver(nx=self.nx, nz=self.nz, get_x=self.plant.getContinuousStates,
                                 set_x=self.plant.setContinuousStates, get_dx=self.plant.getDerivatives,
                                 get_z=self.plant.getEventIndicators,
                                 get_nominals=self.plant.getNominalsOfContinuousStates, set_time=self.plant.setTime,
                                 input=type("NoInput", (), {"apply": lambda *a, **k: None})(), startTime=0.0,
                                 relativeTolerance=1e-10, maxNumSteps=100000)
        rows = []
        for k in range(steps):
            t = k * h
            y = self.plant.getReal([self.pvr[n] for n in names])
            rows.append([t, *y])
            self.law.setReal([self.lvr[n] for n in self.measured], [y[names.index(n)] for n in self.measured])
            voltage = self.law.getReal([self.lvr["voltage"]])
            self.law.doStep(t, h)
            if not self.exchange:
                self.plant.setReal([self.pvr["voltage"]], voltage)
                self.plant.doStep(t, h)
                continue
            self.plant.enterEventMode()
            self.plant.setReal([self.pvr["voltage"]], voltage)
            self._settle()
            solver.reset(t)
            now = t
            while now < t + h - 1e-12:
                event, _, now = solver.step(now, t + h)
                self.plant.setTime(now)
                self.plant.completedIntegratorStep()
                if event:
                    self.plant.enterEventMode()
                    self._settle()
                    solver.reset(now)
        return np.array(rows)


@pytest.mark.parametrize("model,law,start,bound", [
    ("IP02SingleMass", "LQRSingleMass", {"initial_pendulum_angle": 0.05}, 1e-3),
    ("IP02DoubleMass", "LQRDoubleMass", {"initial_pendulum_angle": 0.05}, 1e-3),
    ("IP02DoubleMass", "LQRDoubleMass", {"initial_pendulum_angle": 0.05, "b1": 0.1047, "b2": 0.1047}, 0.15),
])
def test_closed_loop_in_model_exchange_agrees_with_cosimulation(model: str, law: str, start: dict[str, float],
                                                                bound: float, native_fmus: tuple[Path, Path]) -> None:
    """The LQR balancing the pendulum from 0.05 rad for 3 s at 1 ms, the plant co-simulated and in model
    exchange: without Coulomb friction the same loop to the fixed-step kernel's error (ETDRK4 at 1 ms), which
    the feedback keeps from growing: 1e-3 of each column's largest magnitude asserted (observed at most
    1.5e-5 in the positions and the angle, 4.5e-4 in the motor current, whose 69 us time constant the
    kernel's step does not resolve). With Coulomb friction the two interfaces are two models of stiction,
    Karnopp's 1 mm/s band applied per step and exact stick and slip located as events: asserted within 0.15
    of each column's largest magnitude (observed 0.072 in the active cart's position)."""
    h, steps = 1e-3, 3000
    cs = _Loop(native_fmus[1], model, law, False, start).run(h, steps)
    me = _Loop(native_fmus[1], model, law, True, start).run(h, steps)
    names = _state_names(model)
    for j, n in enumerate(names, start=1):
        diff, scale = np.max(np.abs(me[:, j] - cs[:, j])), np.max(np.abs(cs[:, j]))
        print(f"{model} {start}: {n} max |ME - CS| {diff:.3g} (of {scale:.3g}, {diff / scale:.2g})")
        assert diff <= bound * scale, n
    assert np.max(np.abs(cs[:, names.index("pendulum_angle") + 1])) >= 0.05  # the loop moved


def test_model_exchange_answers_every_getter_in_every_state(native_fmus: tuple[Path, Path], native_fmus3: Path,
                                                            tmp_path: Path) -> None:
    """A strict model-exchange importer: every variable of the model description read, one call per type,
    in Initialization Mode, Event Mode, Continuous-Time Mode and Terminated (FMI 2.0 section 3.2.3, FMI 3.0
    section 3.2); the states equal the initial values set; calls the state does not allow refused."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Model
    from fmpy.fmi3 import FMU3Model

    for fmu in _plants(native_fmus, native_fmus3):
        md = read_model_description(str(fmu))
        three = md.fmiVersion.startswith("3")
        cls = FMU3Model if three else FMU2Model
        model = cls(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / fmu.parent.name / fmu.stem)),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="strict")
        by_type: dict[str, list[int]] = {}
        for v in md.modelVariables:
            by_type.setdefault(v.type, []).append(v.valueReference)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        real = "Float64" if three else "Real"

        model.instantiate()
        if three:
            model.enterInitializationMode(startTime=0.0)
        else:
            model.setupExperiment(startTime=0.0)
            model.enterInitializationMode()
        getattr(model, f"set{real}")([vr["initial_pendulum_angle"]], [0.1])
        _read_all(model, by_type)
        assert getattr(model, f"get{real}")([vr["state.pendulum_angle"]]) == [0.1], fmu
        model.exitInitializationMode()
        _read_all(model, by_type)
        assert not (model.updateDiscreteStates() if three else model.newDiscreteStates())[0], fmu  # settled
        model.enterContinuousTimeMode()
        with pytest.raises(FMICallException):
            model.enterContinuousTimeMode()  # only from Event Mode
        model.setTime(0.01)
        _read_all(model, by_type)
        angle = getattr(model, f"get{real}")([vr["der(state.pendulum_velocity)"]])[0]
        assert angle > 0.0, fmu  # the upright pendulum tilted counter-clockwise falls on that way
        model.terminate()
        _read_all(model, by_type)
        model.freeInstance()


def _read_all(model: object, by_type: dict[str, list[int]]) -> None:
    """Every variable, one get per type (fmpy raises on a status above a warning)."""
    for t, vrs in by_type.items():
        assert len(getattr(model, f"get{t}")(vrs)) == len(vrs), t


@pytest.mark.parametrize("model", PLANTS)
def test_fmi3_plant_model_exchange_in_the_strict_host(model: str, native_fmus3: Path, tmp_path: Path) -> None:
    """``tests/c/strict_host.c`` (``me``): the FMI 3.0 plant through its model exchange, every variable read
    in every state, ``time`` the time set, explicit Euler steps of 10 us under 1 V with Coulomb friction
    half the motor's stall force: the breakaway is an event the host sees and iterates."""
    import subprocess

    from loop_plans import _binary
    from test_fmi3_strict_host import ROOT, variables

    from ipcosim.harness.native.cbuild import fmi_header_dir

    host = tmp_path / "strict_host"
    subprocess.run([CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-I", str(fmi_header_dir()),
                    str(ROOT / "tests" / "c" / "strict_host.c"), "-o", str(host), "-ldl"], check=True)
    fmu = native_fmus3 / f"{model}.fmu"
    lib, token, md = _binary(fmu, tmp_path / model, "linux64")
    found, time_vr, _ = variables(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    friction = {"b": 0.85} if "Single" in model else {"b1": 0.85}  # kf V/Ra = 1.73 N at 1 V
    steps = 200
    plan = [f"fmu {lib} {token}", *(f"var {t} {v}" for t, v in found), f"time {time_vr}",
            f"set {vr['voltage']} 1.0", *(f"set {vr[k]} {x!r}" for k, x in friction.items()), f"me 0.0 1e-05 {steps}"]
    (tmp_path / "me.plan").write_text("\n".join(plan) + "\n")
    proc = subprocess.run([str(host), str(tmp_path / "me.plan")], capture_output=True, text=True, timeout=300)
    lines = proc.stdout.splitlines()
    assert proc.returncode == 0 and lines[-1] == "ok", proc.stdout[-600:] + proc.stderr[-600:]
    rows = [line.split() for line in lines[1:-1]]
    assert all(int(r[2]) == len(found) for r in rows)  # every variable, in every state
    states = [r[0] for r in rows]
    events = [s for s in states if s.startswith("event") and s != "event0"]
    print(f"{model}: strict model-exchange host, events at {events}")
    assert states[:3] == ["instantiated", "initialization", "event0"] and states[-1] == "terminated"
    # the breakaway (about 5e-5 s: the current reaches b / kf), then the step after it, where the motion
    # indicator (the velocity along the new mode, 0 at the breakaway) leaves the domain z <= 0 for z > 0:
    # a domain change the standard counts as an event (FMI 3.0 section 3.1), which changes nothing
    assert len(events) == 2 and int(events[1][5:]) == int(events[0][5:]) + 1, events
    assert [float(r[1]) for r in rows if r[0].startswith("ct")] == [k * 1e-05 for k in range(1, steps + 1)]
