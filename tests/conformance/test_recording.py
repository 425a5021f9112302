"""What the record holds.

A connected input (``docs/master.md``, "What an input's column holds"): the value its connection
delivers at the row's time, i.e. the source's output at ``t_n`` through the connection's
transformation (SSP 1.0 4.5.2 LinearTransformation: ``target = factor * source + offset``); under
Jacobi that is the value the FMU uses in its step from ``t_n``, so its output at ``t_n+1`` is
computed from the input recorded at ``t_n``. Source: ``Source3`` (FMI 3.0, ``y`` = 0 before
``step_time`` = 0.5 s and ``amplitude`` = 1 from then on), into the FMI 3.0 adder ``y = k1*u1 + k2*u2``.

A variable that is not a connector (a parameter, a calculated parameter, a local), named with
``--record``: the value the FMU reports at each row, its column after the connectors'; with the
value a parameter binding should have given it worked out here from the SSD and SSP 1.0 5.2.3
("bindings at a system level take precedence over bindings at a sub-system or component level")."""
from __future__ import annotations

import csv
import shutil

import adder_fmus
import cfmu
import numpy as np
import pytest
import ssp_text as t

import ipcosim
from ipcosim.errors import UsageError
from ipcosim.harness import cli
from ipcosim.harness.api.describe import describe

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

FACTOR, OFFSET = 2.0, 0.5
STEP_TIME, AMPLITUDE, H, STOP = 0.5, 1.0, 0.1, 1.0


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_connected_input_is_recorded_as_the_value_exchanged_at_its_row(algorithm, tmp_path):
    out = tmp_path / "fmus"
    out.mkdir()
    src, add = cfmu.build(cfmu.SOURCE3, out), cfmu.build(adder_fmus.adder("Adder3", "3.0"), out)
    src_conn = "<ssd:Connectors>" + t.connector("y", "output", "2.0") + "</ssd:Connectors>"
    root = t.system("root", [t.component("src", "Source3", src_conn), t.component("A", "Adder3",
                                                                                  t.adder_connectors("2.0"))],
                    [t.connection("src.y", "A.u1", f'<ssc:LinearTransformation factor="{FACTOR}" offset="{OFFSET}"/>')])
    folder = t.write(tmp_path / "s", t.document(root, "2.0", stop=STOP), {"Source3": src, "Adder3": add})
    r = ipcosim.run(folder, stop_time=STOP, step=H, algorithm=algorithm)
    times = np.arange(round(STOP / H) + 1) * H
    source = np.where(times >= STEP_TIME - 1e-9, AMPLITUDE, 0.0)  # the step, at 0.5 s
    assert np.array_equal(r["src.y"], source)
    assert np.array_equal(r["A.u1"], FACTOR * source + OFFSET)  # the row at t_n: the value exchanged at t_n
    k1, k2, u2 = adder_fmus.K1, adder_fmus.K2, adder_fmus.U2
    if algorithm == "jacobi":  # the step from t_n uses the input recorded at t_n: y at t_n+1 from u1 at t_n
        assert np.array_equal(r["A.y"][1:], k1 * r["A.u1"][:-1] + k2 * u2)
    else:  # the adder steps after the source (direct feedthrough u1 -> y): y at t_n from u1 at t_n
        assert np.array_equal(r["A.y"], k1 * r["A.u1"] + k2 * u2)


def _bound_adder(tmp_path, version, fmus=None):
    """One adder ``addP`` with k1, k2 bound at component level and k1 again at system level
    (SSP 1.0 / FMI 2.0 adder, or SSP 2.0 / FMI 3.0), its parameter connectors declared as OMSimulator
    does; returns the scenario folder and the values bound (component k1, k2, system k1)."""
    comp_k1, comp_k2, sys_k1 = 10.0, 20.0, -200.0
    adder = cfmu.build(adder_fmus.adder("Adder", "2.0" if version == "1.0" else "3.0"), tmp_path)
    ssd = t.document(t.system("root", [t.component("addP", "Adder", t.adder_connectors(version, True),
                                                   t.bindings(t.from_file("resources/addp.ssv")))],
                              binding=t.bindings(t.from_file("resources/root.ssv"))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": adder}, {
        "resources/addp.ssv": t.parameter_set({"k1": comp_k1, "k2": comp_k2}, version, standalone=True),
        "resources/root.ssv": t.parameter_set({"addP.k1": sys_k1}, version, standalone=True)})
    return folder, (comp_k1, comp_k2, sys_k1)


def _csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], [[float(x) for x in row] for row in rows[1:]]


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("version", ["1.0", "2.0"])
def test_record_of_a_bound_parameter_shows_the_system_level_value(version, algorithm, tmp_path):
    """``--record addP.k1`` of a parameter bound at component level (10) and at system level (-200):
    every row shows -200, as the FMU reports it; the calculated parameter ``k_sum = k1 + k2`` and the
    local ``twice_y = 2 y`` beside it, from the same bound values. Without ``--record`` the columns
    are the connectors' alone, as before; ``describe`` lists the three with their causality."""
    folder, (comp_k1, comp_k2, sys_k1) = _bound_adder(tmp_path, version)
    out = tmp_path / "out"
    assert cli.main(["run", str(folder), "--stop-time", "0.3", "--step", "0.1", "--algorithm", algorithm,
                     "--record", "addP.y,addP.k1", "--record", "addP.k_sum", "--record", "addP.twice_y",
                     "--out", str(out), "--quiet"]) == 0
    header, rows = _csv(out / "results.csv")
    assert header == ["time", "addP.y", "addP.k1", "addP.k_sum", "addP.twice_y"]
    y = sys_k1 * adder_fmus.U1 + comp_k2 * adder_fmus.U2  # -180: the system-level k1, the component's k2
    assert len(rows) == 4
    for row in rows:
        assert row[1:] == [y, sys_k1, sys_k1 + comp_k2, 2 * y]
    assert comp_k1 not in [row[2] for row in rows]
    default = ipcosim.run(folder, stop_time=0.3, step=0.1, algorithm=algorithm)
    assert default.columns == ["time", "addP.u1", "addP.u2", "addP.y"]
    assert ipcosim.run(folder, stop_time=0.3, step=0.1, record=["addP.*"]).columns == default.columns
    listed = {v["name"]: (v["causality"], v["start"]) for v in describe(folder)["components"][0]["variables"]}
    assert listed["k1"] == ("parameter", sys_k1) and listed["k_sum"][0] == "calculatedParameter"
    assert listed["twice_y"][0] == "local"


def test_a_recorded_parameter_is_the_fmus_value_not_the_bound_one(tmp_path):
    """B.k1 has no binding (its start is 1.0): it is set in initialization mode from A's calculated
    parameter through ``factor * A.k_sum + offset`` (SSP 1.0 5.3.2.1); the record shows what B then
    holds, and A's k_sum the value A computed from its bindings, both read from the FMUs."""
    a_k1, a_k2, factor, offset = 2.0, 3.0, 2.0, 1.0
    adder = cfmu.build(adder_fmus.adder("Adder", "2.0"), tmp_path)
    ssd = t.document(t.system("root", [
        t.component("A", "Adder", t.adder_connectors("1.0", True), t.bindings(t.inline({"k1": a_k1, "k2": a_k2},
                                                                                       "1.0"))),
        t.component("B", "Adder", t.adder_connectors("1.0", True))],
        [t.connection("A.k_sum", "B.k1", f'<ssc:LinearTransformation factor="{factor}" offset="{offset}"/>')]),
        "1.0")
    folder = t.write(tmp_path / "s", ssd, {"Adder": adder})
    r = ipcosim.run(folder, stop_time=0.2, step=0.1, record=["A.k_sum", "B.k1"])
    assert r.columns[-2:] == ["A.k_sum", "B.k1"]
    assert np.all(r["A.k_sum"] == a_k1 + a_k2)
    assert np.all(r["B.k1"] == factor * (a_k1 + a_k2) + offset)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_recorded_local_is_read_after_every_step(algorithm, tmp_path):
    """The adder's local ``twice_y = 2 y`` follows its output row by row, through the source's step at
    0.5 s (``y = k1 * u1 + k2 * u2`` with ``u1`` the recorded, connected input)."""
    src, add = cfmu.build(cfmu.SOURCE3, tmp_path), cfmu.build(adder_fmus.adder("Adder3", "3.0"), tmp_path)
    src_conn = "<ssd:Connectors>" + t.connector("y", "output", "2.0") + "</ssd:Connectors>"
    root = t.system("root", [t.component("src", "Source3", src_conn),
                             t.component("A", "Adder3", t.adder_connectors("2.0"))], [t.connection("src.y", "A.u1")])
    folder = t.write(tmp_path / "s", t.document(root, "2.0", stop=STOP), {"Source3": src, "Adder3": add})
    r = ipcosim.run(folder, stop_time=STOP, step=H, algorithm=algorithm, record=["A.twice_y", "src.amplitude"])
    times = np.arange(round(STOP / H) + 1) * H
    y_at_row = adder_fmus.K1 * np.where(times >= STEP_TIME - 1e-9, AMPLITUDE, 0.0) + adder_fmus.K2 * adder_fmus.U2
    if algorithm == "jacobi":  # y at t_n+1 from the u1 recorded at t_n; row 0 from the start values
        y_at_row = np.concatenate(([adder_fmus.K1 * 0.0 + adder_fmus.K2 * adder_fmus.U2], y_at_row[:-1]))
    assert np.array_equal(r["A.twice_y"], 2 * y_at_row)
    assert np.all(r["src.amplitude"] == AMPLITUDE)


def test_recorded_parameters_of_every_type_keep_their_type(tmp_path):
    """PassThrough's Real, Integer, Boolean and String parameters, bound in the SSD, recorded in
    ``Result`` and ``results.csv`` in their own types."""
    fmu = cfmu.build(cfmu.PASSTHROUGH, tmp_path)
    params = (t.value("gain", 2.5) + t.value("offset", 3) + t.value("invert", True)
              + '<ssv:Parameter name="prefix"><ssv:String value="ab"/></ssv:Parameter>')
    binding = (f'<ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet {t.NS} version="1.0" name="v">'
               f'<ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues>'
               f'</ssd:ParameterBinding>')
    conn = "<ssd:Connectors>" + t.connector("real_out", "output", "1.0") + "</ssd:Connectors>"
    ssd = t.document(t.system("root", [t.component("P", "PassThrough", conn, t.bindings(binding))]), "1.0")
    folder = t.write(tmp_path / "s", ssd, {"PassThrough": fmu})
    out = tmp_path / "out"
    r = ipcosim.run(folder, stop_time=0.2, step=0.1, record=["P.gain", "P.offset", "P.invert", "P.prefix"], out=out)
    assert r.data.dtype["P.offset"] == np.int32 and r.data.dtype["P.invert"] == np.bool_
    assert [r[name][-1] for name in ("P.gain", "P.offset", "P.invert", "P.prefix")] == [2.5, 3, True, "ab"]
    header = (out / "results.csv").read_text().splitlines()
    assert header[0] == "time,P.gain,P.offset,P.invert,P.prefix" and header[-1].endswith(",2.5,3,true,ab")


def test_an_unknown_name_is_refused_with_the_closest_variables(tmp_path, capsys):
    """A name no variable has: one line naming it and the closest names, the parameters among them; exit 2."""
    folder, _ = _bound_adder(tmp_path, "1.0")
    with pytest.raises(UsageError, match=r"--record addP\.k3: no such variable; did you mean .*'addP\.k1'"):
        ipcosim.run(folder, stop_time=0.2, step=0.1, record=["addP.k3"])
    capsys.readouterr()
    assert cli.main(["run", str(folder), "--record", "addP.k3", "--out", str(tmp_path / "out")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]  # not the unconnected inputs'
    assert len(err) == 1 and "--record addP.k3: no such variable" in err[0] and "'addP.k1'" in err[0], err


def test_a_name_with_brackets_is_recorded_as_it_is_written():
    """FMI 2.0 names array elements ``x[1]`` (2.2.9, ``variableNamingConvention="structured"``): given
    whole, such a name selects its own column, not what ``[1]`` would be as a shell pattern."""
    data = np.zeros(2, dtype=[("time", "f8"), ("p.x[1]", "f8"), ("p.x[2]", "f8"), ("p.x1", "f8")])
    result = ipcosim.Result(data=data)
    assert result.select(["p.x[1]"]) == ["time", "p.x[1]"]
    assert result.select(["p.x[[]*"]) == ["time", "p.x[1]", "p.x[2]"]
