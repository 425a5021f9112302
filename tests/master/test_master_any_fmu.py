"""The master with FMUs the project did not design for itself (``tests/cfmu.py``: C models on a
plain FMI 2.0 / 3.0 glue, compiled here): every value type, FMU-requested termination, step
rules that never skip time, FMI 3.0 beside 2.0; compared against FMPy's ``simulate_fmu`` and
hand-written loops."""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

import cfmu
import numpy as np
import pytest
from ssd_helpers import HEAD, write_scenario

import ipcosim
from ipcosim.harness import cli
from ipcosim.harness.master.algorithm import StepSizeError
from ipcosim.harness.master.results import SimulationError
from ipcosim.harness.scenario.errors import BindingError

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

SPECS = {s.name: s for s in (cfmu.STAIR, cfmu.PASSTHROUGH, cfmu.BOUNCING_BALL, cfmu.counter(),
                             cfmu.counter("CounterFixed", variable_step=False), cfmu.counter("Counter25", step=0.25),
                             cfmu.PASSTHROUGH3, cfmu.SOURCE3, cfmu.STAIR3)}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("cfmus")
    return {name: cfmu.build(spec, out) for name, spec in SPECS.items()}


# ------------------------------------------------------------------ SSD writing
def conn_xml(name: str, spec: cfmu.Spec, only: tuple[str, ...] | None = None) -> str:
    """SSD connectors of a component: its inputs and outputs with their SSP types."""
    ssp = {"Float64": "Real", "Float32": "Real", "Boolean": "Boolean", "String": "String"}
    parts = []
    for v in spec.variables:
        if v.causality in ("input", "output") and (only is None or v.name in only):
            t = ssp.get(v.type, "Real" if v.type == "Real" else "Integer")
            parts.append(f'<ssd:Connector name="{v.name}" kind="{v.causality}"><ssc:{t}/></ssd:Connector>')
    return "".join(parts)


def comp(name: str, model: str, params: str = "", hint: float | None = None, only=None) -> str:
    ann = ""
    if hint is not None:
        ann = (f'<ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">'
               f'<osp:StepSizeHint value="{hint!r}"/></ssc:Annotation></ssd:Annotations>')
    bind = ""
    if params:
        bind = (f'<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0" '
                f'name="inline"><ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues>'
                f'</ssd:ParameterBinding></ssd:ParameterBindings>')
    return (f'<ssd:Component name="{name}" source="resources/{model}.fmu"><ssd:Connectors>'
            f'{conn_xml(name, SPECS[model], only)}</ssd:Connectors>{bind}{ann}</ssd:Component>')


def link(a: str, b: str, inner: str = "") -> str:
    (se, sc), (ee, ec) = a.split("."), b.split(".")
    return (f'<ssd:Connection startElement="{se}" startConnector="{sc}" endElement="{ee}" endConnector="{ec}">'
            f'{inner}</ssd:Connection>')


def scenario(tmp_path: Path, fmus, comps, links=(), stop: float | None = 1.0, step: float | None = 0.1,
             name="s", ssvs=None) -> Path:
    body = [HEAD.format(name=name), f'<ssd:System name="{name}"><ssd:Elements>', *comps, "</ssd:Elements>"]
    if links:
        body += ["<ssd:Connections>", *links, "</ssd:Connections>"]
    body.append("</ssd:System>")
    stop_attr = f' stopTime="{stop!r}"' if stop is not None else ""
    ann = ""
    if step is not None:
        ann = (f'<ssd:Annotations><ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm>'
               f'<osp:FixedStepAlgorithm baseStepSize="{step!r}"/></osp:Algorithm></ssc:Annotation></ssd:Annotations>')
    body.append(f'<ssd:DefaultExperiment startTime="0.0"{stop_attr}>{ann}</ssd:DefaultExperiment>')
    body.append("</ssd:SystemStructureDescription>\n")
    models = {m: fmus[m] for m in SPECS if f'resources/{m}.fmu"' in "".join(comps)}
    return write_scenario(tmp_path / name, "\n".join(body), models, ssvs)


def p(name: str, type_: str, value: str) -> str:
    return f'<ssv:Parameter name="{name}"><ssv:{type_} value="{value}"/></ssv:Parameter>'


def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def fmpy_result(fmu: Path, stop: float, step: float, start_values=None) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), stop_time=stop, output_interval=step, fmi_type="CoSimulation",
                        start_values=start_values or {})


# ------------------------------------------------------------------ 1 + 4: every type, FMI 3.0 beside 2.0
CHAIN = [link("src.y", "pt.real_in"), link("src.count", "pt.int_in"), link("src.on", "pt.bool_in"),
         link("src.label", "pt.string_in"), link("pt.real_out", "pt3.f64_in"), link("pt.real_out", "pt3.f32_in"),
         link("pt.int_out", "pt3.i32_in"), link("pt.int_out", "pt3.i16_in"), link("pt.int_out", "pt3.u8_in"),
         link("pt.int_out", "pt3.i64_in"), link("pt.bool_out", "pt3.bool_in"), link("pt.string_out", "pt3.string_in")]


def test_every_type_through_fmi3_and_fmi2_with_set_and_typed_csv(tmp_path, fmus, capsys):
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt", "PassThrough"), comp("pt3", "PassThrough3")],
                      CHAIN)
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet", "--set", "pt.offset=5",
                   "--set", "pt.invert=true", "--set", "pt.prefix=x-", "--set", "pt.gain=2.5",
                   "--set", "src.step_time=0.3"])
    assert rc == 0, capsys.readouterr().err
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    # every connector of every type is recorded by default, in SSD order
    assert header[:5] == ["time", "src.y", "src.count", "src.on", "src.label"]
    assert "pt3.string_out" in header and "pt.bool_out" in header and "pt3.u8_out" in header
    col = {name: [r[k] for r in rows] for k, name in enumerate(header)}
    # a hand-written loop: Gauss-Seidel src -> pt -> pt3 (direct feedthrough), tick n at t = n / 10
    for n in range(11):
        t = n / 10
        on = t >= 0.3 - 1e-12
        y, label = (1.0 if on else 0.0), ("on" if on else "off")
        assert float(col["time"][n]) == pytest.approx(t, abs=1e-15)
        assert col["src.count"][n] == str(n) and col["src.on"][n] == ("true" if on else "false")
        assert col["src.label"][n] == label
        assert float(col["pt.real_out"][n]) == 2.5 * y and float(col["pt3.f32_out"][n]) == 2.5 * y
        assert col["pt.int_out"][n] == str(n + 5) == col["pt3.i32_out"][n] == col["pt3.u8_out"][n]
        assert col["pt.bool_out"][n] == ("false" if on else "true") == col["pt3.bool_out"][n]
        assert col["pt3.string_out"][n] == "x-" + label


def test_typed_columns_stream_over_many_chunks(tmp_path, fmus):
    """3000 ticks recorded every third one: the rows reach results.csv and the spool in many
    chunks; every typed column keeps its values and type across the chunk boundaries. (Counts
    above 255 cannot reach a UInt8 input: that connection is left out here.)"""
    chain = [c for c in CHAIN if "u8_in" not in c]
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt", "PassThrough"), comp("pt3", "PassThrough3")],
                      chain, stop=3.0, step=0.001)
    with ipcosim.prepare(folder) as prepared:
        r = prepared.run(out=tmp_path / "out", set={"pt.offset": 5, "pt.prefix": "x-", "pt.invert": True,
                                                               "src.step_time": 1.2}, record_every=3)
    assert len(r.data) == 1001 and r.data.dtype["src.count"] == np.int32 and r.data.dtype["src.on"] == np.bool_
    ticks = np.arange(1001) * 3
    on = r["time"] >= 1.2 - 1e-12
    assert list(r["src.count"]) == list(ticks) and list(r["pt.int_out"]) == list(ticks + 5)
    assert list(r["src.on"]) == list(on) and list(r["pt3.bool_out"]) == list(~on)
    assert list(r["pt3.string_out"]) == ["x-on" if o else "x-off" for o in on]
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    assert header == list(r.data.dtype.names) and len(rows) == 1001
    col = {name: [row[k] for row in rows] for k, name in enumerate(header)}
    assert col["src.count"] == [str(n) for n in ticks] and col["src.on"] == ["true" if o else "false" for o in on]
    assert col["pt3.string_out"] == list(r["pt3.string_out"])
    assert [float(x) for x in col["pt.real_out"]] == list(r["pt.real_out"])


def test_jacobi_delays_every_type_by_one_step(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt", "PassThrough"), comp("pt3", "PassThrough3")],
                      CHAIN)
    r = ipcosim.run(folder, algorithm="jacobi", set={"pt.offset": 1})
    count = r["src.count"]
    assert r.data.dtype["src.count"] == np.int32 and r.data.dtype["pt.bool_out"] == np.bool_
    # libcosim's fixed-step Jacobi: an input at step n is the source's value at n - 1
    assert list(r["pt.int_out"][1:]) == [c + 1 for c in count[:-1]]
    assert list(r["pt3.i32_out"][2:]) == [c + 1 for c in count[:-2]]
    assert list(r["pt3.string_out"][3:]) == list(r["src.label"][1:-2])


def test_ssv_binds_every_type_and_mapping_transformations_apply(tmp_path, fmus):
    imap = ('<ssc:IntegerMappingTransformation><ssc:MapEntry source="2" target="20"/>'
            '<ssc:MapEntry source="3" target="30"/></ssc:IntegerMappingTransformation>')
    bmap = ('<ssc:BooleanMappingTransformation><ssc:MapEntry source="true" target="false"/>'
            '<ssc:MapEntry source="false" target="true"/></ssc:BooleanMappingTransformation>')
    params = p("offset", "Integer", "100") + p("invert", "Boolean", "false") + p("prefix", "String", "ssv:") + \
        p("gain", "Real", "-1.0")
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt", "PassThrough", params=params)],
                      [link("src.count", "pt.int_in", imap), link("src.on", "pt.bool_in", bmap),
                       link("src.label", "pt.string_in"), link("src.y", "pt.real_in")])
    r = ipcosim.run(folder)
    mapped = [{2: 20, 3: 30}.get(int(c), int(c)) for c in r["src.count"]]
    assert list(r["pt.int_in"]) == mapped  # the column of a connected input: what the connection delivers
    assert list(r["pt.int_out"]) == [m + 100 for m in mapped]
    assert list(r["pt.bool_out"]) == [not on for on in r["src.on"]]
    assert list(r["pt.string_out"]) == ["ssv:" + s for s in r["src.label"]]
    assert np.array_equal(r["pt.real_out"], -r["src.y"])


@pytest.mark.parametrize("links, message", [
    ([link("src.count", "pt.real_in")],
     "connects Int32 to Real; SSP 1.0 connects connectors of one type"),
    ([link("src.on", "pt.int_in")], "connects Boolean to Integer; SSP 1.0 connects connectors of one type"),
    ([link("src.count", "pt.int_in", '<ssc:LinearTransformation factor="2"/>')],
     "ssc:LinearTransformation on a Integer connection; SSP 1.0 defines it for Real connectors only"),
    ([link("src.y", "pt.real_in", '<ssc:BooleanMappingTransformation><ssc:MapEntry source="true" target="false"/>'
                                  '</ssc:BooleanMappingTransformation>')],
     "ssc:BooleanMappingTransformation on a Real connection; SSP 1.0 defines it for Boolean connectors only"),
])
def test_type_mismatch_is_one_clear_line_citing_the_ssp_rule(tmp_path, fmus, capsys, links, message):
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt", "PassThrough")], links)
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet"])
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert rc != 0 and len(err) == 1 and message in err[0] and "SystemStructure.ssd: connection" in err[0]
    with pytest.raises(BindingError, match="SSP 1.0"):
        ipcosim.run(folder)


# ------------------------------------------------------------------ 2: termination by an FMU
@pytest.mark.parametrize("model", ["Stair", "Stair3"])
def test_fmu_ending_the_simulation_ends_the_run_normally_and_matches_fmpy(tmp_path, fmus, model):
    folder = scenario(tmp_path, fmus, [comp("stair", model)], stop=2.0)
    r = ipcosim.run(folder, out=tmp_path / "out")
    assert r.ok and r.metadata["status"] == "ok"
    by = r.metadata["terminated_by"]
    assert by["component"] == "stair" and by["time"] == pytest.approx(0.9)
    assert any("component stair" in n and "ended the simulation" in n for n in r.metadata["notes"])
    assert r["time"][-1] == pytest.approx(0.9) and list(r["stair.counter"]) == list(range(1, 11))
    ref = fmpy_result(fmus[model], 2.0, 0.1)
    ref = ref[ref["time"] <= 0.9 + 1e-9][:10]  # FMPy also samples the last successful time once more
    # times: ours are integer ticks (t_n = n h from integer nanoseconds), FMPy's n * h in floating point
    assert np.allclose(r["time"], ref["time"], rtol=0, atol=1e-15)
    assert np.array_equal(r["stair.counter"], ref["counter"])
    assert np.array_equal(r["stair.height"], ref["height"])
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    assert header == ["time", "stair.counter", "stair.height"] and rows[-1][1] == "10"


def test_an_fmu_ending_within_a_step_gets_its_last_successful_time_recorded_as_fmpy_does(tmp_path, fmus):
    """The Reference-FMUs' Stair ends between two communication points: the row at its last successful
    time (here 0.95 s, counting to 11) is recorded after the last full step, as simulate_fmu records it."""
    folder = scenario(tmp_path, fmus, [comp("stair", "Stair")], stop=2.0)
    r = ipcosim.run(folder, set={"stair.end_midstep": True}, out=tmp_path / "out")
    assert r.ok and r.metadata["terminated_by"]["last_successful_time"] == pytest.approx(0.95)
    ref = fmpy_result(fmus["Stair"], 2.0, 0.1, start_values={"end_midstep": True})
    assert list(ref["time"][-2:]) == pytest.approx([0.9, 0.95]) and ref["counter"][-1] == 11
    assert np.allclose(r["time"], ref["time"], rtol=0, atol=1e-15)
    assert np.array_equal(r["stair.counter"], ref["counter"]) and np.array_equal(r["stair.height"], ref["height"])
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    assert float(rows[-1][0]) == r["time"][-1] and rows[-1][1] == "11" and r.metadata["end_time"] == r["time"][-1]
    assert "last successful time t = 0.95 s" in r.metadata["terminated_by"]["note"]


def test_discard_without_termination_is_an_error_saying_what_the_status_query_returned(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("stair", "Stair")], stop=2.0)
    with pytest.raises(SimulationError) as info:
        ipcosim.run(folder, set={"stair.end_simulation": "false", "stair.limit": 3})
    assert str(info.value) == ("component stair (Stair): fmi2DoStep returned fmi2Discard at t = 0.2 s "
                               "(fmi2GetBooleanStatus(fmi2Terminated) returned fmi2False, the FMU did not end "
                               "the simulation)")
    assert info.value.result is not None and info.value.result["time"][-1] == pytest.approx(0.2)


# ------------------------------------------------------------------ events: compared with FMPy
def test_bouncing_ball_equals_fmpy(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("ball", "BouncingBall")], stop=3.0, step=0.01)
    r = ipcosim.run(folder, set={"ball.e": 0.8})
    ref = fmpy_result(fmus["BouncingBall"], 3.0, 0.01, {"e": 0.8})
    assert np.allclose(r["time"], ref["time"], rtol=0, atol=1e-14)
    # FMPy passes h = t_{n+1} - t_n (which differs from 0.01 in the last bits), we pass 0.01: the
    # trajectories agree to rounding, the events exactly
    for name in ("h", "v"):
        assert np.allclose(r[f"ball.{name}"], ref[name], rtol=0, atol=1e-12), name
    for name in ("bounces", "falling"):
        assert np.array_equal(r[f"ball.{name}"], ref[name]), name
    assert r["ball.bounces"][-1] > 5  # events happened inside the steps


# ------------------------------------------------------------------ 3: time is never skipped
def test_multi_rate_component_steps_exactly_to_the_stop_time(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("src", "Source3", only=("y",)), comp("c", "Counter", hint=0.3)],
                      [link("src.y", "c.u")], stop=1.0, step=0.1)
    r = ipcosim.run(folder, set={"src.step_time": 0.5})
    # hand-written: c steps at the end of each period with its input sampled there: 0-0.3, 0.3-0.6,
    # 0.6-0.9 and a last, shorter period 0.9-1.0
    periods = [(0.0, 0.3), (0.3, 0.6), (0.6, 0.9), (0.9, 1.0)]
    integral = sum((1.0 if b >= 0.5 else 0.0) * (b - a) for a, b in periods)
    assert r["c.steps"][-1] == 4 and r["c.reached"][-1] == pytest.approx(1.0, abs=1e-12)
    assert r["c.integral"][-1] == pytest.approx(integral, abs=1e-12)
    assert list(r["c.steps"]) == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 4]
    # Jacobi: inputs read at the start of each period (y at 0, 0.3, 0.6, 0.9), outputs published at its end
    jac = ipcosim.run(folder, set={"src.step_time": 0.5}, algorithm="jacobi")
    assert list(jac["c.steps"]) == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 4]
    assert jac["c.integral"][-1] == pytest.approx(0.3 + 0.1, abs=1e-12)
    # the same component alone, against FMPy (which takes the shorter last step too)
    alone = scenario(tmp_path, fmus, [comp("c", "Counter", hint=0.3)], stop=1.0, step=0.1, name="alone")
    ref = fmpy_result(fmus["Counter"], 1.0, 0.3)
    mine = ipcosim.run(alone)
    assert ref["time"][-1] == 1.0 and mine["c.steps"][-1] == ref["steps"][-1] == 4
    assert mine["c.reached"][-1] == ref["reached"][-1]


def test_partial_last_period_of_a_fixed_step_fmu_is_a_load_time_error(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("c", "CounterFixed", hint=0.3)], stop=1.0, step=0.1)
    with pytest.raises(StepSizeError, match=r"c \(CounterFixed: step 0.3 s, last step 0.1 s\), which cannot take a "
                                            r"shorter last step"):
        ipcosim.run(folder)
    assert ipcosim.run(folder, stop_time=0.9).ok  # a whole number of its steps


def test_stop_time_not_a_multiple_of_the_step_gets_a_shorter_last_step(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("c", "Counter"), comp("pt", "PassThrough")], stop=0.95, step=0.1)
    r = ipcosim.run(folder)
    assert r["time"][-1] == 0.95 and len(r.data) == 11 and r["c.reached"][-1] == pytest.approx(0.95, abs=1e-12)
    assert r.metadata["stop_time"] == 0.95
    fixed = scenario(tmp_path, fmus, [comp("c", "CounterFixed"), comp("pt", "PassThrough")], stop=0.95, step=0.1,
                     name="fixed")
    with pytest.raises(StepSizeError, match=r"not a whole number of steps of c \(CounterFixed: step 0.1 s, last step "
                                            r"0.05 s\)"):
        ipcosim.run(fixed)


def test_default_step_and_stop_time_come_from_the_fmus(tmp_path, fmus):
    # no step in the SSD: the largest step dividing every FMU's DefaultExperiment step (0.1, 0.25)
    folder = scenario(tmp_path, fmus, [comp("stair", "Stair"), comp("c", "Counter25")], stop=1.0, step=None)
    r = ipcosim.run(folder)
    assert r.metadata["step"] == pytest.approx(0.05)
    assert r["time"][-1] == pytest.approx(0.45) and r["stair.counter"][-1] == 10  # 9 steps, then it ends
    # no stop time in the SSD either: the FMUs' DefaultExperiment stopTime (they agree: 1.0)
    folder = scenario(tmp_path, fmus, [comp("src", "Source3"), comp("pt3", "PassThrough3")], stop=None, step=None,
                      name="nostop")
    r = ipcosim.run(folder)
    assert r.metadata["step"] == pytest.approx(0.1) and r["time"][-1] == pytest.approx(1.0)


def test_an_integer_only_fmu_writes_its_integer_column_and_record_selects_it(tmp_path, fmus, capsys):
    folder = scenario(tmp_path, fmus, [comp("stair", "Stair", only=("counter",))], stop=0.5)
    rc = cli.main(["run", str(folder), "--out", str(tmp_path / "out"), "--quiet", "--record", "stair.counter"])
    assert rc == 0, capsys.readouterr().err
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    assert header == ["time", "stair.counter"] and [r[1] for r in rows] == [str(k) for k in range(1, 7)]


# ------------------------------------------------------------------ the C stepping loop on these FMUs
def _run_keeping_failure(folder: Path, **kw) -> object:
    """The run's result, the partial one of a run that failed."""
    try:
        return ipcosim.run(folder, **kw)
    except ipcosim.SimulationError as exc:
        return exc.result


def _loops(folder: Path, **kw) -> dict[str, object]:
    """The run on each loop (auto, c, python); the C and the Python loop's records are the same bit for bit."""
    out = {loop: _run_keeping_failure(folder, loop=loop, **kw) for loop in ("auto", "c", "python")}
    c, py = out["c"], out["python"]
    assert c.metadata["loop"] == "c" and py.metadata["loop"] == "python (forced)"
    assert c.data.dtype == py.data.dtype and c.data.tobytes() == py.data.tobytes()
    for key in ("status", "error", "terminated_by", "end_time"):
        assert c.metadata[key] == py.metadata[key], key
    return out


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_c_loop_on_c_fmus_and_fmi3_adapters_equals_the_python_loop(tmp_path, fmus, algorithm):
    # a C FMU stepping every 0.3 s with a partial last period, fed by an FMI 3.0 FMU (its adapter is Python:
    # called back from C when forced, else the Python loop runs)
    reals = ("u", "reached", "integral")
    folder = scenario(tmp_path, fmus, [comp("src", "Source3", only=("y",)), comp("c", "Counter", hint=0.3, only=reals)],
                      [link("src.y", "c.u")], stop=1.0, step=0.1)
    runs = _loops(folder, set={"src.step_time": 0.5}, algorithm=algorithm)
    assert runs["auto"].metadata["loop"] == "python (components stepped by Python functions: src)"
    assert runs["c"]["c.integral"][-1] > 0 and runs["c"]["time"][-1] == 1.0
    alone = scenario(tmp_path, fmus, [comp("c", "Counter", hint=0.3, only=reals)], stop=0.95, step=0.1, name="alone")
    assert _loops(alone, algorithm=algorithm)["auto"].metadata["loop"] == "c"


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_a_variable_recorded_by_name_equals_its_column_as_a_connector(tmp_path, fmus, algorithm):
    """Counter's outputs ``integral`` (Real) and ``steps`` (Integer) left out of the SSD's connectors and
    named with ``record``: the same values as their columns when they are connectors, on a component
    stepping every 0.3 s with a partial last period (Jacobi: read into its private outputs, published
    at the end of the period), on the C and the Python loop alike."""
    declared = scenario(tmp_path, fmus, [comp("c", "Counter", hint=0.3)], stop=0.95, step=0.1, name="declared")
    named = scenario(tmp_path, fmus, [comp("c", "Counter", hint=0.3, only=("reached",))], stop=0.95, step=0.1,
                     name="named")
    reference = ipcosim.run(declared, algorithm=algorithm, set={"c.u": 2.0})
    real = _loops(named, algorithm=algorithm, set={"c.u": 2.0}, record=["c.reached", "c.integral"])["c"]
    assert real.columns == ["time", "c.reached", "c.integral"]
    typed = ipcosim.run(named, algorithm=algorithm, set={"c.u": 2.0}, record=["c.reached", "c.integral", "c.steps"])
    assert reference["c.steps"][-1] == 4 and reference["c.integral"][-1] == pytest.approx(2.0 * 0.95, abs=1e-12)
    for r in (real, typed):
        for name in r.columns:
            assert np.array_equal(r[name], reference[name]), name


@pytest.mark.parametrize("model", ["Stair", "Stair3"])
def test_c_loop_ends_where_the_fmu_ends_the_simulation_or_fails_as_the_python_loop(tmp_path, fmus, model):
    folder = scenario(tmp_path, fmus, [comp("stair", model, only=("height",))], stop=2.0)
    runs = _loops(folder)
    assert runs["c"].ok and runs["c"].metadata["terminated_by"]["component"] == "stair"
    assert runs["c"]["time"][-1] == pytest.approx(0.9)
    if model == "Stair":  # an FMI 2.0 Discard without termination: the same error
        failed = _loops(folder, set={"stair.end_simulation": "false", "stair.limit": 3})
        assert failed["c"].error.startswith("component stair (Stair): fmi2DoStep returned fmi2Discard at t = 0.2 s")


def test_integer_boolean_and_string_connectors_run_on_the_python_loop(tmp_path, fmus):
    folder = scenario(tmp_path, fmus, [comp("pt", "PassThrough")], stop=0.5)
    r = ipcosim.run(folder, loop="auto")
    assert r.ok and r.metadata["loop"] == "python (Integer/Boolean/String connectors (pt))"
    with pytest.raises(SimulationError, match=r"^--loop c: the C stepping loop cannot run: Integer/Boolean/String "
                                              r"connectors \(pt\)$"):
        ipcosim.run(folder, loop="c")
