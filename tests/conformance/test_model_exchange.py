"""Model-exchange components (FMI 2.0 section 3, FMI 3.0 section 3; SSP 1.0 ``implementation``),
integrated by the master with CVODE between communication points, checked against the models'
closed forms and against ``fmpy.simulate_fmu`` in model-exchange mode (the same solver, driven by
FMPy). The models are the project's C test models' model-exchange interface (``tests/cfmu.py``):
a linear decay ``x' = -k x + u``, a Van der Pol oscillator, a bouncing ball (state events) and a
staircase (time events). Every run uses relative tolerance 1e-8, given in the SSD as OMSimulator
writes it (``oms:VariableStepSolver relativeTolerance``)."""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import cfmu
import numpy as np
import pytest
import ssp_text as t

import ipcosim
from ipcosim.harness.api.describe import describe
from ipcosim.harness.scenario.errors import BindingError

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

RTOL = 1e-8
#: Agreement asked of the runs (relative, at RTOL).
AGREE = 1e-6
OMS = 'xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"'
SOLVER = ('<ssd:Annotations><ssc:Annotation type="org.openmodelica"><oms:Annotations><oms:SimulationInformation>'
          f'<oms:VariableStepSolver description="cvode" relativeTolerance="{RTOL!r}"/>'
          '</oms:SimulationInformation></oms:Annotations></ssc:Annotation></ssd:Annotations>')
FMI = {"2.0": lambda spec: spec, "3.0": cfmu.fmi3_variant}


def _connectors(*pairs: tuple[str, str, str]) -> str:
    return "<ssd:Connectors>" + "".join(t.connector(n, k, "1.0", type_=ty) for n, k, ty in pairs) + "</ssd:Connectors>"


def _scenario(folder: Path, elements: list[str], fmus: dict[str, Path], connections: tuple[str, ...] = (),
              stop: float = 1.0, solver: bool = True) -> Path:
    """A scenario folder; the system carries the OMSimulator solver annotation unless ``solver`` is false."""
    root = t.system("root", elements, connections)
    if solver:
        root = root[:-len("</ssd:System>")] + SOLVER + "</ssd:System>"
    doc = t.document(root, "1.0", stop=stop).replace("<ssd:SystemStructureDescription ",
                                                      f"<ssd:SystemStructureDescription {OMS} ", 1)
    return t.write(folder, doc, fmus)


def _single(tmp_path: Path, spec: cfmu.Spec, outputs: tuple[tuple[str, str], ...], implementation: str = "ModelExchange"
            ) -> tuple[Path, Path]:
    """The FMU of ``spec`` and a scenario running it alone as component ``m``."""
    fmu = cfmu.build(spec, tmp_path)
    conns = _connectors(*((n, "output", ty) for n, ty in outputs))
    comp = t.component("m", spec.name, conns, extra=f' implementation="{implementation}"')
    return fmu, _scenario(tmp_path / "s", [comp], {spec.name: fmu}, stop=spec.stop)


def _fmpy(fmu: Path, spec: cfmu.Spec) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), fmi_type="ModelExchange", relative_tolerance=RTOL, stop_time=spec.stop,
                        output_interval=spec.step, record_events=False)


def _times(spec: cfmu.Spec) -> np.ndarray:
    return np.arange(round(spec.stop / spec.step) + 1) * spec.step


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_linear_decay_follows_its_closed_form_and_fmpy(fmi, tmp_path):
    spec = FMI[fmi](cfmu.DECAY)
    fmu, folder = _single(tmp_path, spec, (("x", "Real"),))
    r = ipcosim.run(folder, step=spec.step)
    exact = np.exp(-1.0 * _times(spec))  # x(0) = 1, k = 1, u = 0
    assert np.max(np.abs(r["m.x"] / exact - 1)) < AGREE
    reference = _fmpy(fmu, spec)
    assert np.allclose(reference["time"], r["time"], rtol=0, atol=1e-12)
    assert np.max(np.abs(r["m.x"] / reference["x"] - 1)) < AGREE


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_a_recorded_parameter_and_derivative_of_a_model_exchange_component(fmi, tmp_path):
    """``record=["m.k", "m.der(x)"]`` on the decay the master integrates: ``k`` as set, and the local
    ``der(x) = -k x = -k exp(-k t)`` at every communication point, as the FMU computes it there."""
    spec = FMI[fmi](cfmu.DECAY)
    _, folder = _single(tmp_path, spec, (("x", "Real"),))
    k = 2.0
    r = ipcosim.run(folder, step=spec.step, set={"m.k": k}, record=["m.k", "m.der(x)"])
    assert r.columns == ["time", "m.x", "m.k", "m.der(x)"]
    assert np.all(r["m.k"] == k)
    exact = -k * np.exp(-k * _times(spec))
    assert np.max(np.abs(r["m.der(x)"] - exact)) < AGREE * k  # of its amplitude: x decays to 0.02
    assert np.array_equal(r["m.der(x)"], -k * r["m.x"])


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_van_der_pol_agrees_with_fmpy(fmi, tmp_path):
    spec = FMI[fmi](cfmu.VANDERPOL)
    fmu, folder = _single(tmp_path, spec, (("x0", "Real"), ("x1", "Real")))
    r = ipcosim.run(folder, step=spec.step)
    reference = _fmpy(fmu, spec)
    for name in ("x0", "x1"):  # relative to the oscillation's amplitude (the signals cross zero)
        scale = np.max(np.abs(reference[name]))
        assert np.max(np.abs(r[f"m.{name}"] - reference[name])) < AGREE * scale
    assert 1.9 < np.max(r["m.x0"][len(r["time"]) // 2:]) < 2.1  # the limit cycle's amplitude, about 2 for mu = 1


def _bounce_instants(h0: float, g: float, e: float, stop: float) -> list[float]:
    """The closed form: the first impact at sqrt(2 h0 / g), then flights of 2 e^k v1 / g, until the
    speed after an impact is below 0.1 m/s (the model's ball then rests)."""
    t, v = math.sqrt(2 * h0 / g), math.sqrt(2 * g * h0)
    out = []
    while t < stop:
        out.append(t)
        v *= e
        if v < 0.1:
            break
        t += 2 * v / g
    return out


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_bouncing_ball_bounces_at_the_closed_form_instants(fmi, tmp_path):
    spec = FMI[fmi](cfmu.BOUNCING_BALL_ME)
    integer = "Integer"
    fmu, folder = _single(tmp_path, spec, (("h", "Real"), ("last_bounce", "Real"), ("bounces", integer)))
    r = ipcosim.run(folder, step=spec.step)
    instants = _bounce_instants(1.0, 9.81, 0.7, spec.stop)
    assert len(instants) == 4 and r["m.bounces"][-1] == 4
    times = r["time"]
    for k, tb in enumerate(instants, start=1):
        after = times >= tb + 1e-9
        assert np.all(r["m.bounces"][after] >= k) and np.all(r["m.bounces"][times < tb - 1e-9] < k)
        seen = r["m.last_bounce"][r["m.bounces"] == k]
        assert seen.size and abs(seen[0] - tb) < 1e-6  # the impact as the event indicator located it
    reference = _fmpy(fmu, spec)
    assert np.max(np.abs(r["m.h"] - reference["h"])) < AGREE * 1.0  # relative to the drop height, 1 m
    assert np.array_equal(r["m.bounces"], reference["bounces"])


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_staircase_steps_at_its_time_events(fmi, tmp_path):
    spec = FMI[fmi](cfmu.STAIRCASE)
    fmu, folder = _single(tmp_path, spec, (("counter", "Integer"), ("last_tick", "Real")))
    r = ipcosim.run(folder, step=spec.step)
    period_ms, times_ms = 150, np.arange(len(r["time"])) * 100  # the period 0.15 s, the step 0.1 s
    expected = 1 + times_ms // period_ms  # one step at t = 0 and at every multiple of the period
    assert np.array_equal(r["m.counter"], expected)
    assert np.allclose(r["m.last_tick"], (expected - 1) * 0.15, rtol=0, atol=1e-12)
    reference = _fmpy(fmu, spec)
    assert np.array_equal(r["m.counter"], reference["counter"])


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_the_fmu_ends_the_simulation_in_an_event(fmi, tmp_path):
    """``terminateSimulation`` from the event iteration at the time event where the counter reaches
    ``limit`` = 4, t = 3 * 0.15 s = 0.45 s, inside the step from 0.4 s: the run ends normally, recorded
    up to that time (the FMU's last successful time)."""
    spec = FMI[fmi](cfmu.STAIRCASE)
    fmu = cfmu.build(spec, tmp_path)
    comp = t.component("m", spec.name, _connectors(("counter", "output", "Integer"), ("limit", "parameter", "Integer")),
                       binding=t.bindings(t.inline({"limit": 4}, "1.0")), extra=' implementation="ModelExchange"')
    r = ipcosim.run(_scenario(tmp_path / "s", [comp], {spec.name: fmu}), step=spec.step)
    assert r.ok and r.metadata["terminated_by"]["component"] == "m"
    assert r["time"][-1] == pytest.approx(0.45, abs=1e-12) and r["m.counter"][-1] == 4
    assert list(r["m.counter"][:-1]) == [1, 1, 2, 3, 3]  # t = 0 ... 0.4 s


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_a_prepared_model_exchange_scenario_runs_again_alike(fmi, tmp_path):
    spec = FMI[fmi](cfmu.BOUNCING_BALL_ME)
    _, folder = _single(tmp_path, spec, (("h", "Real"), ("bounces", "Integer")))
    with ipcosim.prepare(folder) as prepared:
        first = prepared.run(step=spec.step)
        other = prepared.run(step=spec.step, set={"m.e": 0.5})
        again = prepared.run(step=spec.step)
    assert np.array_equal(first["m.h"], again["m.h"]) and np.array_equal(first["m.bounces"], again["m.bounces"])
    assert other["m.bounces"][-1] == len(_bounce_instants(1.0, 9.81, 0.5, spec.stop)) == 6


def test_a_shorter_last_step_is_taken_in_model_exchange(tmp_path):
    """The FMU's co-simulation cannot take a shorter last step (canHandleVariableCommunicationStepSize
    false); integrated by the master, it can: the run of 0.995 s at 0.01 s ends at 0.995 s."""
    import dataclasses

    from ipcosim.harness.master.algorithm import StepSizeError

    spec = dataclasses.replace(cfmu.DECAY, can_handle_variable_step=False)
    fmu = cfmu.build(spec, tmp_path)
    for implementation in ("CoSimulation", "ModelExchange"):
        comp = t.component("m", "Decay", _connectors(("x", "output", "Real")),
                           extra=f' implementation="{implementation}"')
        folder = _scenario(tmp_path / implementation, [comp], {"Decay": fmu})
        if implementation == "CoSimulation":
            with pytest.raises(StepSizeError, match="canHandleVariableCommunicationStepSize"):
                ipcosim.run(folder, step=0.01, stop_time=0.995)
        else:
            r = ipcosim.run(folder, step=0.01, stop_time=0.995)
            assert r["time"][-1] == 0.995 and abs(r["m.x"][-1] / math.exp(-0.995) - 1) < AGREE


def test_the_exported_loop_refuses_a_model_exchange_component_in_one_line(tmp_path):
    from ipcosim.harness.api.export import ExportError, container_spec
    from ipcosim.harness.scenario.binding import bind
    from ipcosim.harness.scenario.ssp import load_scenario

    _, folder = _single(tmp_path, cfmu.DECAY, (("x", "Real"),))
    system = bind(load_scenario(folder))
    with pytest.raises(ExportError) as err:
        container_spec(system, ["m"], {"m": 1}, 0.01, "Loop")
    assert "\n" not in str(err.value) and "component m: runs as model exchange" in str(err.value)


def test_implementation_any_takes_co_simulation_and_model_exchange_where_asked(tmp_path):
    fmu = cfmu.build(cfmu.DECAY, tmp_path)
    conns = _connectors(("x", "output", "Real"))
    for implementation, interface in (("any", "co-simulation"), ("ModelExchange", "model exchange"),
                                      ("CoSimulation", "co-simulation")):
        comp = t.component("m", "Decay", conns, extra=f' implementation="{implementation}"')
        folder = _scenario(tmp_path / implementation, [comp], {"Decay": fmu}, stop=2.0)
        info = describe(folder)
        assert info["components"][0]["interface"].startswith(interface)
        r = ipcosim.run(folder, step=0.01)
        error = np.max(np.abs(r["m.x"] / np.exp(-r["time"]) - 1))
        if interface == "co-simulation":  # the FMU's own step is the exact solution
            assert error < 1e-13
        else:  # CVODE at 1e-8: close, not exact
            assert 1e-13 < error < AGREE


@pytest.mark.parametrize("asked, spec, offered", [("ModelExchange", cfmu.STAIR, "co-simulation"),
                                                  ("CoSimulation", cfmu.VANDERPOL, "model exchange")])
def test_an_interface_the_fmu_lacks_is_refused_in_one_line(asked, spec, offered, tmp_path):
    fmu = cfmu.build(spec, tmp_path)
    comp = t.component("m", spec.name, "", extra=f' implementation="{asked}"')
    folder = _scenario(tmp_path / "s", [comp], {spec.name: fmu})
    with pytest.raises(BindingError) as err:
        ipcosim.run(folder, step=0.1)
    message = str(err.value)
    assert "\n" not in message and "'m'" in message and asked in message and f"offers {offered} only" in message


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_model_exchange_plant_with_a_co_simulation_controller(algorithm, tmp_path):
    """Plant ``x' = -k x + u`` (model exchange), controller ``u = gain * x`` (PassThrough, co-simulation).
    With ``u`` held over each step the loop is the exact recurrence ``x[n+1] = a x[n] + b u[n]``,
    ``a = exp(-k h)``, ``b = (1 - a) / k``; ``u[n] = gain x[n]`` in Gauss-Seidel (the controller, fed
    through, steps after the plant) and ``gain x[n-1]`` in Jacobi (the values of the previous point)."""
    k, gain, h, stop = 1.0, -2.0, 0.01, 2.0
    plant, ctrl = cfmu.build(cfmu.DECAY, tmp_path), cfmu.build(cfmu.PASSTHROUGH, tmp_path)
    elements = [t.component("plant", "Decay", _connectors(("x", "output", "Real"), ("u", "input", "Real")),
                            extra=' implementation="ModelExchange"'),
                t.component("controller", "PassThrough",
                            _connectors(("real_in", "input", "Real"), ("real_out", "output", "Real")),
                            binding=t.bindings(t.inline({"gain": gain}, "1.0")))]
    folder = _scenario(tmp_path / "s", elements, {"Decay": plant, "PassThrough": ctrl},
                       (t.connection("plant.x", "controller.real_in"), t.connection("controller.real_out", "plant.u")),
                       stop=stop)
    r = ipcosim.run(folder, step=h, algorithm=algorithm)
    a, b = math.exp(-k * h), (1 - math.exp(-k * h)) / k
    x = [1.0]
    for n in range(round(stop / h)):
        u = gain * x[n] if algorithm == "gauss-seidel" else gain * x[max(n - 1, 0)]
        x.append(a * x[n] + b * u)
    assert np.max(np.abs(r["plant.x"] - np.array(x))) < AGREE * max(abs(v) for v in x)
    assert abs(r["plant.x"][-1]) < 0.01  # the loop decays at about k - gain = 3 per second


def test_an_ssp_archive_with_a_model_exchange_component_runs_from_the_command_line(tmp_path, capsys):
    """As easySSP and OMSimulator write it: an ``.ssp`` archive, the FMUs under ``resources/``, the
    component asking ``implementation="ModelExchange"``, the solver's tolerance in a tool annotation."""
    import zipfile

    from ipcosim.harness import cli

    spec = cfmu.BOUNCING_BALL_ME
    _, folder = _single(tmp_path, spec, (("h", "Real"), ("bounces", "Integer")))
    archive = tmp_path / "ball.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(folder).as_posix())
    out = tmp_path / "out"
    assert cli.main(["run", str(archive), "--out", str(out), "--quiet"]) == 0
    rows = np.genfromtxt(out / "results.csv", delimiter=",", names=True)
    assert rows["mbounces"][-1] == len(_bounce_instants(1.0, 9.81, 0.7, spec.stop))
    assert cli.main(["describe", str(archive)]) == 0
    assert "model exchange, integrated by the master (CVODE, relative tolerance 1e-08)" in capsys.readouterr().out


def test_a_tolerance_that_is_not_a_positive_number_is_refused_in_one_line(tmp_path):
    fmu, folder = _single(tmp_path, cfmu.DECAY, (("x", "Real"),))
    ssd = folder / "SystemStructure.ssd"
    ssd.write_text(ssd.read_text().replace(f'relativeTolerance="{RTOL!r}"', 'relativeTolerance="-1e-6"'))
    with pytest.raises(ipcosim.IpcosimError) as err:
        ipcosim.run(folder, step=0.01)
    message = str(err.value)
    assert "\n" not in message and "SystemStructure.ssd" in message and "relativeTolerance" in message


def test_a_solver_failure_is_one_line_naming_the_component_and_keeps_the_results(tmp_path, capsys):
    """``k`` = -1e300: ``x' = 1e300 x`` overflows at once; CVODE gives up. One line on stderr (CVODE's
    own printing silenced), exit 1, results.csv and metrics.json written."""
    from ipcosim.harness import cli

    _, folder = _single(tmp_path, cfmu.DECAY, (("x", "Real"),))
    out = tmp_path / "out"
    assert cli.main(["run", str(folder), "--out", str(out), "--quiet", "--set", "m.k=-1e300", "--step", "0.01"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "component m (Decay)" in err and "CVODE" in err and "t = 0 s" in err
    assert (out / "results.csv").is_file() and (out / "metrics.json").is_file()
