"""SSP conformance: one small scenario per rule of the standard the master meets, in SSP 1.0 (FMI 2.0
adder) and SSP 2.0 (FMI 3.0 adder, ``ssc:Float64`` connectors), each checked against the value the
standard's text gives, worked out here from the rule and the adder's equation

    y = k1 * u1 + k2 * u2        (start values k1 = k2 = u1 = u2 = 1; k_sum = k1 + k2)

or refused in one line naming the file, the element and the feature. Sections cited are SSP 1.0's
(``docs/5___ssd.adoc`` "ParameterBindings", 4.5.2 "Transformation Choice", ``7___ssm.adoc``,
``6___ssv.adoc``) and SSP 2.0's where it adds to them. ``docs/master.md`` lists these tests in its
conformance table."""
from __future__ import annotations

import shutil

import adder_fmus
import cfmu
import pytest
import ssp_text as t

import ipcosim
from ipcosim.errors import IpcosimError
from ipcosim.harness import cli
from ipcosim.harness.api.describe import describe
from ipcosim.harness.scenario.errors import BindingError

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

VERSIONS = ("1.0", "2.0")
K1, K2, U1, U2 = adder_fmus.K1, adder_fmus.K2, adder_fmus.U1, adder_fmus.U2


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """The adder for each SSP version (FMI 2.0 for 1.0, FMI 3.0 for 2.0), its copy with units
    (k1 and u1 in m/s2, y in m), PassThrough for the Integer and Boolean rules and its copy whose
    int_in, int_out and offset are of the Enumeration type Mode (Off 0, Slow 1, Fast 2)."""
    out = tmp_path_factory.mktemp("conformance-fmus")
    a2 = cfmu.build(adder_fmus.adder("Adder", "2.0"), out)
    a3 = cfmu.build(adder_fmus.adder("Adder3", "3.0"), out)
    units = {"k1": "m/s2", "u1": "m", "y": "m"}
    passthrough = cfmu.build(cfmu.PASSTHROUGH, out)
    modes = adder_fmus.with_enumeration(passthrough, ("int_in", "int_out", "offset"), out / "Modes.fmu")
    return {"1.0": {"Adder": a2, "AdderU": adder_fmus.with_units(a2, units, out / "AdderU.fmu"),
                    "PassThrough": passthrough, "Modes": modes},
            "2.0": {"Adder": a3, "AdderU": adder_fmus.with_units(a3, units, out / "AdderU3.fmu")}}


def run(folder, stop_time=0.2):
    """The run's values at its end, by column."""
    result = ipcosim.run(folder, stop_time=stop_time, step=0.1)
    return {name: result[name][-1] for name in result.columns}


def start_values(folder, component):
    """``ipcosim describe``'s start values of one component."""
    info = describe(folder)
    comp = next(c for c in info["components"] if c["name"] == component)
    return {v["name"]: v["start"] for v in comp["variables"]}


# ------------------------------------------------------------------ parameter bindings (SSP 5.2.3 / 5.3.3)
@pytest.mark.parametrize("version", VERSIONS)
def test_system_level_binding_wins_over_component_level(version, fmus, tmp_path):
    """"bindings at a system level take precedence over bindings at a sub-system or component level";
    the system addresses the variable by hierarchical name ``component.variable``."""
    comp_k1, comp_k2, sys_k1, sys_k2 = 10.0, 20.0, -200.0, -300.0
    ssd = t.document(t.system("root", [t.component("addP", "Adder", t.adder_connectors(version, True),
                                                   t.bindings(t.from_file("resources/addp.ssv")))],
                              binding=t.bindings(t.from_file("resources/root.ssv"))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]}, {
        "resources/addp.ssv": t.parameter_set({"k1": comp_k1, "k2": comp_k2}, version, standalone=True),
        "resources/root.ssv": t.parameter_set({"addP.k1": sys_k1, "addP.k2": sys_k2}, version, standalone=True)})
    expected = sys_k1 * U1 + sys_k2 * U2  # -500, not comp_k1 * U1 + comp_k2 * U2 = 30
    assert run(folder)["addP.y"] == pytest.approx(expected, abs=1e-12)
    starts = start_values(folder, "addP")
    assert (starts["k1"], starts["k2"]) == (sys_k1, sys_k2)


@pytest.mark.parametrize("version", VERSIONS)
def test_prefix_makes_names_hierarchical(version, fmus, tmp_path):
    """``prefix="A."`` "is prepended to all names in the parameter source", so a component's bare
    names bound at system level reach component A (and win over A's own binding)."""
    ssd = t.document(t.system("root", [t.component("A", "Adder", t.adder_connectors(version),
                                                   t.bindings(t.inline({"k1": 5.0, "k2": 6.0}, version)))],
                              binding=t.bindings(t.inline({"k1": 3.0}, version, prefix="A."))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    assert run(folder)["A.y"] == pytest.approx(3.0 * U1 + 6.0 * U2, abs=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
def test_later_binding_wins_at_the_same_level(version, fmus, tmp_path):
    """"parameter values in ParameterBinding sources appearing at a succeeding position in the element
    order taking priority over prior sources at the same hierarchy level"."""
    first, second = {"k1": 2.0, "k2": 4.0}, {"k1": 7.0}
    ssd = t.document(t.system("root", [t.component("A", "Adder", t.adder_connectors(version),
                                                   t.bindings(t.from_file("first.ssv"), t.inline(second, version)))]),
                     version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]},
                     {"first.ssv": t.parameter_set(first, version, standalone=True)})
    assert run(folder)["A.y"] == pytest.approx(second["k1"] * U1 + first["k2"] * U2, abs=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
def test_parameter_connectors_are_bound_not_crashing(version, fmus, tmp_path):
    """``kind="parameter"`` and ``kind="calculatedParameter"`` connectors (OMSimulator and easySSP declare
    one for every parameter): the parameters are set from the binding, the run goes through."""
    ssd = t.document(t.system("root", [t.component("Add1", "Adder", t.adder_connectors(version, True),
                                                   t.bindings(t.inline({"k1": 2.0, "k2": 3.0}, version)))]), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    values = run(folder)
    assert values["Add1.y"] == pytest.approx(2.0 * U1 + 3.0 * U2, abs=1e-12)
    assert start_values(folder, "Add1")["k1"] == 2.0


@pytest.mark.parametrize("version", VERSIONS)
def test_system_parameter_connector_feeds_component_parameters(version, fmus, tmp_path):
    """An OMSimulator-style file: system connectors of kind parameter and input (``startElement=""``)
    connected to a component's parameter and input connectors, their values given by the system's
    binding; a hierarchical name beside them; the output led out to a system output connector.
    A system parameter connected to an element parameter is in the table of allowed connections;
    its value is the element's start value."""
    k_cref, addp_k2, input_cref = 4.0, -3.0, 2.0
    conns = "<ssd:Connectors>" + "".join([t.connector("Input_cref", "input", version),
                                          t.connector("Output_cref", "output", version),
                                          t.connector("k_cref", "parameter", version)]) + "</ssd:Connectors>"
    ssd = t.document(t.system(
        "root", [t.component("addP", "Adder", t.adder_connectors(version, True),
                             t.bindings(t.inline({"k1": 10.0, "k2": 20.0}, version)))],
        [t.connection(".k_cref", "addP.k1"), t.connection(".Input_cref", "addP.u1"),
         t.connection("addP.y", ".Output_cref")],
        connectors=conns,
        binding=t.bindings(t.from_file("resources/root.ssv"))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]}, {
        "resources/root.ssv": t.parameter_set({"k_cref": k_cref, "addP.k2": addp_k2, "Input_cref": input_cref},
                                              version, standalone=True)})
    assert run(folder)["addP.y"] == pytest.approx(k_cref * input_cref + addp_k2 * U2, abs=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
def test_unknown_system_level_name_is_named(version, fmus, tmp_path):
    """A system-level value that reaches no variable: SSP ignores it, the master (strict by default, as for
    component-level sets) refuses in one line naming the file and the name, as a BindingError and from
    the command line."""
    ssd = t.document(t.system("root", [t.component("A", "Adder", t.adder_connectors(version))],
                              binding=t.bindings(t.inline({"A.k9": 1.0}, version))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    with pytest.raises(BindingError, match=r"SystemStructure.ssd:\d+: system-level parameter set .* A\.k9"):
        ipcosim.run(folder, stop_time=0.2)


# ------------------------------------------------------------------ units and transformations (4.5.2, 6.2)
UNITS = ('<ssd:Units><ssc:Unit name="km"><ssc:BaseUnit m="1" factor="1000"/></ssc:Unit>'
         '<ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit></ssd:Units>')


@pytest.mark.parametrize("version", VERSIONS)
def test_unit_conversion_before_linear_transformation(version, fmus, tmp_path):
    """"conversions based on different units are performed ... prior to the application of the linear
    transformation, i.e. the value of source is already converted to the target unit": from A.y = 1.5 km
    to B.u1 in m with factor 2 and offset 5."""
    km, factor, offset = 1.5, 2.0, 5.0
    expected_u1 = factor * (km * 1000.0) + offset  # 3005 m (the other order gives (2 * 1.5 + 5) km = 8000 m)
    ssd = t.document(t.system("root", [
        t.component("A", "Adder", "<ssd:Connectors>" + t.connector("y", "output", version, "km") + "</ssd:Connectors>",
                    t.bindings(t.inline({"u1": km, "k2": 0.0}, version))),
        t.component("B", "Adder", "<ssd:Connectors>" + t.connector("u1", "input", version, "m")
                    + t.connector("y", "output", version, "m") + "</ssd:Connectors>",
                    t.bindings(t.inline({"k2": 0.0}, version)))],
        [t.connection("A.y", "B.u1", f'<ssc:LinearTransformation factor="{factor}" offset="{offset}"/>')]),
        version, units=UNITS)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    values = run(folder)
    assert values["B.u1"] == pytest.approx(expected_u1, rel=1e-12)
    assert values["B.y"] == pytest.approx(K1 * expected_u1, rel=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
def test_suppress_unit_conversion_applies_the_transformation_alone(version, fmus, tmp_path):
    """"With suppressUnitConversion = true, the linear transformation is performed instead of any unit
    conversions"."""
    km, factor, offset = 1.5, 2.0, 5.0
    ssd = t.document(t.system("root", [
        t.component("A", "Adder", "<ssd:Connectors>" + t.connector("y", "output", version, "km") + "</ssd:Connectors>",
                    t.bindings(t.inline({"u1": km, "k2": 0.0}, version))),
        t.component("B", "Adder", "<ssd:Connectors>" + t.connector("u1", "input", version, "m") + "</ssd:Connectors>")],
        [t.connection("A.y", "B.u1", f'<ssc:LinearTransformation factor="{factor}" offset="{offset}"/>')
         .replace("<ssd:Connection ", '<ssd:Connection suppressUnitConversion="true" ')]), version, units=UNITS)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    assert run(folder)["B.u1"] == pytest.approx(factor * km + offset, rel=1e-12)


SSV_UNITS = ('<ssv:Units><ssc:Unit name="cm/s2"><ssc:BaseUnit m="1" s="-2" factor="0.01"/></ssc:Unit>'
             '<ssc:Unit name="s"><ssc:BaseUnit s="1"/></ssc:Unit></ssv:Units>')


@pytest.mark.parametrize("version", VERSIONS)
def test_ssv_value_unit_is_converted_to_the_variables_unit(version, fmus, tmp_path):
    """An SSV Real's ``unit`` names a unit of the set's own ``Units``; the FMU's k1 is in m/s2, so
    g = -981 cm/s2 arrives as -9.81 m/s2."""
    g_cm = -981.0
    ssd = t.document(t.system("root", [t.component("g", "AdderU", t.adder_connectors(version),
                                                   t.bindings(t.from_file("g.ssv")))]), version)
    folder = t.write(tmp_path / "s", ssd, {"AdderU": fmus[version]["AdderU"]}, {
        "g.ssv": t.parameter_set({"k1": (g_cm, "cm/s2"), "k2": 0.0}, version, SSV_UNITS, standalone=True)})
    assert run(folder)["g.y"] == pytest.approx(g_cm * 0.01 * U1, rel=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("unit, why", [("s", "different quantities"), ("furlong", "not defined")])
def test_ssv_value_unit_that_cannot_convert_is_refused(version, unit, why, fmus, tmp_path, capsys):
    """A value whose unit does not convert to the variable's: one line naming the file, the value and the
    unit, from the Python API (a BindingError) and the command line (exit 1)."""
    ssd = t.document(t.system("root", [t.component("g", "AdderU", t.adder_connectors(version),
                                                   t.bindings(t.from_file("g.ssv")))]), version)
    folder = t.write(tmp_path / "s", ssd, {"AdderU": fmus[version]["AdderU"]}, {
        "g.ssv": t.parameter_set({"k1": (-981.0, unit)}, version, SSV_UNITS, standalone=True)})
    with pytest.raises(BindingError, match=rf"g\.ssv.*k1 = -981\.0 {unit} cannot be converted.*'m/s2'.*{why}"):
        ipcosim.run(folder, stop_time=0.2)
    assert cli.main(["run", str(folder), "--out", str(tmp_path / "out")]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and f"-981.0 {unit}" in err[0]


# ------------------------------------------------------------------ parameter mapping (SSP 7, ssm)
SSM = ('<?xml version="1.0" encoding="UTF-8"?>\n<ssm:ParameterMapping {ns} version="{v}">'
       '<ssm:MappingEntry source="gain_a" target="k1"><ssc:LinearTransformation factor="2" offset="1"/>'
       '</ssm:MappingEntry></ssm:ParameterMapping>')


@pytest.mark.parametrize("version", VERSIONS)
def test_parameter_mapping_renames_transforms_and_selects(version, fmus, tmp_path):
    """"All parameters of the parameter source which are not referenced in a mapping entry will not be
    applied"; a mapped value is renamed and transformed (factor * x + offset)."""
    gain_a, unmapped_k2 = 3.0, 50.0
    ssd = t.document(t.system("root", [t.component(
        "A", "Adder", t.adder_connectors(version),
        t.bindings(t.from_file("values.ssv", mapping='<ssd:ParameterMapping source="map.ssm"/>')))]), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]}, {
        "values.ssv": t.parameter_set({"gain_a": gain_a, "k2": unmapped_k2}, version, standalone=True),
        "map.ssm": SSM.format(ns=t.NS, v=version)})
    assert run(folder)["A.y"] == pytest.approx((2.0 * gain_a + 1.0) * U1 + K2 * U2, abs=1e-12)


def test_parameter_mapping_integer_and_boolean(fmus, tmp_path):
    """Integer and Boolean mapping transformations in an inline ``ssm:ParameterMapping``: values not in
    the table pass unchanged; PassThrough gives int_out = int_in + offset, bool_out = bool_in xor invert."""
    mapping = ('<ssd:ParameterMapping><ssm:ParameterMapping version="1.0">'
               '<ssm:MappingEntry source="o" target="offset"><ssc:IntegerMappingTransformation>'
               '<ssc:MapEntry source="3" target="10"/></ssc:IntegerMappingTransformation></ssm:MappingEntry>'
               '<ssm:MappingEntry source="inv" target="invert"><ssc:BooleanMappingTransformation>'
               '<ssc:MapEntry source="false" target="true"/></ssc:BooleanMappingTransformation></ssm:MappingEntry>'
               '</ssm:ParameterMapping></ssd:ParameterMapping>')
    conns = ("<ssd:Connectors>" + t.connector("int_out", "output", "1.0", type_="Integer")
             + t.connector("bool_out", "output", "1.0", type_="Boolean") + "</ssd:Connectors>")
    ssd = t.document(t.system("root", [t.component("p", "PassThrough", conns, t.bindings(
        t.inline({"o": 3, "inv": False}, "1.0", mapping=mapping)))]), "1.0")
    folder = t.write(tmp_path / "s", ssd, {"PassThrough": fmus["1.0"]["PassThrough"]})
    values = run(folder)
    assert values["p.int_out"] == 0 + 10  # int_in starts at 0; 3 maps to 10
    assert bool(values["p.bool_out"]) is (False != True)  # bool_in false; false maps to true  # noqa: E712


# ------------------------------------------------------------------ nested systems (5.3)
@pytest.mark.parametrize("version", VERSIONS)
def test_nested_system_is_flattened_with_its_connectors_joined(version, fmus, tmp_path):
    """A sub-system S holding component A: the connections through S's connectors join B.y to S.A.u1 and
    S.A.y to C.u1; S's binding (``A.k1``, hierarchical inside S) wins over A's own, the top level's
    (``S.A.k2``) over both."""
    b_u1, s_k1, top_k2 = 2.0, 3.0, 0.5
    inner = t.system("S", [t.component("A", "Adder", t.adder_connectors(version),
                                       t.bindings(t.inline({"k1": 100.0, "k2": 100.0}, version)))],
                     [t.connection(".u", "A.u1"), t.connection("A.y", ".y")],
                     connectors="<ssd:Connectors>" + t.connector("u", "input", version)
                     + t.connector("y", "output", version) + "</ssd:Connectors>",
                     binding=t.bindings(t.inline({"A.k1": s_k1}, version)))
    ssd = t.document(t.system("root", [
        t.component("B", "Adder", t.adder_connectors(version), t.bindings(t.inline({"u1": b_u1, "k2": 0.0}, version))),
        inner.replace("<ssd:System ", "<ssd:System ", 1),
        t.component("C", "Adder", t.adder_connectors(version), t.bindings(t.inline({"k2": 0.0}, version)))],
        [t.connection("B.y", "S.u"), t.connection("S.y", "C.u1")],
        binding=t.bindings(t.inline({"S.A.k2": top_k2}, version))), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    values = run(folder)
    b_y = K1 * b_u1
    a_y = s_k1 * b_y + top_k2 * U2
    assert values["S.A.y"] == pytest.approx(a_y, abs=1e-12)
    assert values["C.y"] == pytest.approx(K1 * a_y, abs=1e-12)
    result = ipcosim.run(folder, stop_time=0.2, step=0.1, set={"S.A.k2": 0.0})
    assert result["S.A.y"][-1] == pytest.approx(s_k1 * b_y, abs=1e-12)


# ------------------------------------------------------------------ refused, by name
def _refusal(version, system_xml, fmus, tmp_path, capsys, units=""):
    folder = t.write(tmp_path / "s", t.document(system_xml, version, units), {"Adder": fmus[version]["Adder"]})
    with pytest.raises(IpcosimError) as info:
        ipcosim.run(folder, stop_time=0.2)
    assert not isinstance(info.value, KeyError)
    assert cli.main(["run", str(folder), "--out", str(tmp_path / "out")]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "SystemStructure.ssd" in err[0], err
    return str(info.value)


@pytest.mark.parametrize("version", VERSIONS)
def test_signal_dictionary_carries_a_signal_between_its_references(version, fmus, tmp_path):
    """A signal dictionary (SSP 1.0: inline ``ssb:SignalDictionary``; SSP 2.0: an ``.ssb`` file) is one
    signal bus: A.y written into reference ``writer``'s ``speed`` reaches B.u1 through reference ``reader``
    and S.C.u1 through a reference inside sub-system S (the dictionary is looked up outwards, 5.5)."""
    a_u1 = 3.0
    entry = f'<ssb:DictionaryEntry name="speed"><ssc:{t.real(version)}/></ssb:DictionaryEntry>'
    ssb = f'<ssb:SignalDictionary version="{version}">{entry}</ssb:SignalDictionary>'
    if version == "1.0":
        dictionary = f'<ssd:SignalDictionary name="bus">{ssb}</ssd:SignalDictionary>'
        files = {}
    else:
        dictionary = '<ssd:SignalDictionary name="bus" source="resources/bus.ssb"/>'
        standalone = ssb.replace("<ssb:SignalDictionary ", f"<ssb:SignalDictionary {t.NS} ")
        files = {"resources/bus.ssb": f'<?xml version="1.0" encoding="UTF-8"?>\n{standalone}'}

    def ref(name):
        return (f'<ssd:SignalDictionaryReference name="{name}" dictionary="bus"><ssd:Connectors>'
                + t.connector("speed", "inout", version) + "</ssd:Connectors></ssd:SignalDictionaryReference>")

    inner = t.system("S", [t.component("C", "Adder", t.adder_connectors(version)), ref("inner")],
                     [t.connection("inner.speed", "C.u1")])
    root = t.system("root", [t.component("A", "Adder", t.adder_connectors(version),
                                         t.bindings(t.inline({"u1": a_u1, "k2": 0.0}, version))),
                             ref("writer"), ref("reader"), t.component("B", "Adder", t.adder_connectors(version)),
                             inner],
                    [t.connection("A.y", "writer.speed"), t.connection("reader.speed", "B.u1")])
    head, _, tail = root.rpartition("</ssd:System>")  # the top level's end: the dictionary is defined there
    root = f"{head}<ssd:SignalDictionaries>{dictionary}</ssd:SignalDictionaries></ssd:System>{tail}"
    folder = t.write(tmp_path / "s", t.document(root, version), {"Adder": fmus[version]["Adder"]}, files)
    values = run(folder)
    speed = K1 * a_u1
    assert values["B.u1"] == pytest.approx(speed, abs=1e-12)
    assert values["S.C.y"] == pytest.approx(K1 * speed + K2 * U2, abs=1e-12)


@pytest.mark.parametrize("version", VERSIONS)
def test_signal_dictionary_reference_to_no_dictionary_is_refused_by_name(version, fmus, tmp_path, capsys):
    sd = ('<ssd:SignalDictionaryReference name="bus" dictionary="d"><ssd:Connectors>'
          + t.connector("s", "inout", version) + "</ssd:Connectors></ssd:SignalDictionaryReference>")
    msg = _refusal(version, t.system("root", [t.component("A", "Adder", t.adder_connectors(version)), sd]),
                   fmus, tmp_path, capsys)
    assert "ssd:SignalDictionaryReference 'bus'" in msg and "signal dictionary 'd'" in msg


@pytest.mark.parametrize("version", VERSIONS)
def test_ssp_as_component_is_refused_by_name(version, fmus, tmp_path, capsys):
    sub = ('<ssd:Component name="sub" type="application/x-ssp-package" source="resources/Sub.ssp">'
           "</ssd:Component>")
    msg = _refusal(version, t.system("root", [sub]), fmus, tmp_path, capsys)
    assert "component 'sub'" in msg and "an SSP or SSD used as a component is not supported" in msg


@pytest.mark.parametrize("version", VERSIONS)
def test_model_exchange_asked_of_a_co_simulation_fmu_is_refused_by_name(version, fmus, tmp_path, capsys):
    comp = t.component("A", "Adder", t.adder_connectors(version), extra=' implementation="ModelExchange"')
    msg = _refusal(version, t.system("root", [comp]), fmus, tmp_path, capsys)
    assert "component 'A'" in msg and "ModelExchange" in msg and "co-simulation" in msg


@pytest.mark.parametrize("version", VERSIONS)
def test_calculated_parameter_feeds_a_parameter_and_an_input(version, fmus, tmp_path):
    """Element calculatedParameter -> element parameter and -> element input are allowed SSP connections
    (5.3.2.1); A's k_sum = k1 + k2 (computed in initialization) becomes B's k1 through a linear
    transformation, and C's u2 as it is."""
    a_k1, a_k2, factor, offset = 2.0, 3.0, 2.0, 1.0
    k_sum = a_k1 + a_k2
    b_k1 = factor * k_sum + offset
    ssd = t.document(t.system("root", [
        t.component("A", "Adder", t.adder_connectors(version, True),
                    t.bindings(t.inline({"k1": a_k1, "k2": a_k2}, version))),
        t.component("B", "Adder", t.adder_connectors(version, True)),
        t.component("C", "Adder", t.adder_connectors(version, True))],
        [t.connection("A.k_sum", "B.k1", f'<ssc:LinearTransformation factor="{factor}" offset="{offset}"/>'),
         t.connection("C.u2", "A.k_sum")]), version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    values = run(folder)
    assert values["B.y"] == pytest.approx(b_k1 * U1 + K2 * U2, abs=1e-12)
    assert values["C.u2"] == pytest.approx(k_sum, abs=1e-12)
    assert values["C.y"] == pytest.approx(K1 * U1 + K2 * k_sum, abs=1e-12)
    with pytest.raises(BindingError, match="'k1' is connected to A.k_sum"):
        ipcosim.run(folder, stop_time=0.2, set={"B.k1": 9.0})


@pytest.mark.parametrize("version", VERSIONS)
def test_output_into_a_parameter_is_refused_by_name(version, fmus, tmp_path, capsys):
    """Element output -> element parameter is not in SSP's table of allowed connections."""
    msg = _refusal(version, t.system("root", [t.component("A", "Adder", t.adder_connectors(version, True)),
                                              t.component("B", "Adder", t.adder_connectors(version, True))],
                                     [t.connection("A.y", "B.k1")]), fmus, tmp_path, capsys)
    assert "A.y -> B.k1" in msg and "parameter" in msg


# ------------------------------------------------------------------ SSP 2.0 only
def test_ssp2_array_connector_is_refused_by_name(fmus, tmp_path, capsys):
    conns = ('<ssd:Connectors><ssd:Connector name="u1" kind="input"><ssc:Float64/><ssc:Dimension size="2"/>'
             "</ssd:Connector></ssd:Connectors>")
    msg = _refusal("2.0", t.system("root", [t.component("A", "Adder", conns)]), fmus, tmp_path, capsys)
    assert "connector 'u1' is an array" in msg


def test_ssp2_component_without_source_is_refused_by_name(fmus, tmp_path, capsys):
    comp = f'<ssd:Component name="design">{t.adder_connectors("2.0")}</ssd:Component>'
    msg = _refusal("2.0", t.system("root", [comp]), fmus, tmp_path, capsys)
    assert "component 'design' has no source" in msg


def test_ssp2_is_validated_against_the_2_0_schema(fmus, tmp_path, capsys):
    """A 2.0 document is checked by the 2.0 schema: a connector kind 1.0 lacks (``local``) passes it;
    a kind neither has fails it, named with file and line."""
    msg = _refusal("2.0", t.system("root", [t.component("A", "Adder", "<ssd:Connectors>"
                                                        + t.connector("u1", "sideways", "2.0")
                                                        + "</ssd:Connectors>")]), fmus, tmp_path, capsys)
    assert "fails the SSP 2.0 schema" in msg and "sideways" in msg


def test_ssp1_document_with_a_2_0_kind_fails_the_1_0_schema(fmus, tmp_path, capsys):
    msg = _refusal("1.0", t.system("root", [t.component("A", "Adder", "<ssd:Connectors>"
                                                        + t.connector("u1", "local", "1.0")
                                                        + "</ssd:Connectors>")]), fmus, tmp_path, capsys)
    assert "fails the SSP 1.0 schema" in msg


def test_omsimulator_style_ssp2_runs_with_the_standards_values(fmus, tmp_path):
    """As OMSimulator 3 writes an SSP 2.0 file: ``version="2.0"``, a ``parameter`` connector for every
    parameter of every component, empty ``startElement`` for the system's own connectors, the system's
    parameters in a system-level ``.ssv`` (hierarchical names and system connectors), the components'
    own ``.ssv`` files below it, tool annotations. Values worked out from the rules above:
    system level over component level, system parameter connectors feeding their components."""
    v = "2.0"
    sys_conns = ("<ssd:Connectors>" + t.connector("Input_cref", "input", v) + t.connector("Output_cref", "output", v)
                 + t.connector("k_cref", "parameter", v) + "</ssd:Connectors>")
    ann = ('<ssd:Annotations><ssc:Annotation type="org.openmodelica"><oms:Annotations '
           'xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd">'
           '<oms:SimulationInformation><oms:FixedStepMaster description="oms-ma" stepSize="0.1"/>'
           "</oms:SimulationInformation></oms:Annotations></ssc:Annotation></ssd:Annotations>")
    addp = t.component("addP", "Adder", t.adder_connectors(v, True), t.bindings(t.from_file("resources/addP.ssv")))
    addi = t.component("addI", "Adder", t.adder_connectors(v, True), t.bindings(t.from_file("resources/addI.ssv")))
    body = t.system("root", [addp, addi],
                    ['<ssd:Connection startElement="" startConnector="k_cref" endElement="addP" endConnector="k1"/>',
                     '<ssd:Connection startElement="" startConnector="Input_cref" endElement="addP" '
                     'endConnector="u1"/>',
                     '<ssd:Connection startElement="addP" startConnector="y" endElement="addI" endConnector="u1"/>',
                     '<ssd:Connection startElement="addI" startConnector="y" endElement="" '
                     'endConnector="Output_cref"/>'],
                    connectors=sys_conns, binding=t.bindings(t.from_file("resources/root.ssv")))
    body = body.replace("</ssd:System>", ann + "</ssd:System>")
    root_values = {"k_cref": 4.0, "Input_cref": 2.0, "addP.k2": -3.0, "addI.k1": 0.5}
    addp_values = {"k1": 10.0, "k2": 20.0}
    addi_values = {"k1": 30.0, "k2": 40.0}
    folder = t.write(tmp_path / "oms", t.document(body, v), {"Adder": fmus[v]["Adder"]}, {
        "resources/root.ssv": t.parameter_set(root_values, v, standalone=True),
        "resources/addP.ssv": t.parameter_set(addp_values, v, standalone=True),
        "resources/addI.ssv": t.parameter_set(addi_values, v, standalone=True)})
    addp_y = root_values["k_cref"] * root_values["Input_cref"] + root_values["addP.k2"] * U2
    addi_y = root_values["addI.k1"] * addp_y + addi_values["k2"] * U2
    values = run(folder)
    assert values["addP.y"] == pytest.approx(addp_y, abs=1e-12)
    assert values["addI.y"] == pytest.approx(addi_y, abs=1e-12)


# ------------------------------------------------------------------ writing SSP 2.0 (ipcosim build --ssp-version)
def test_packed_archive_declares_the_asked_version_and_runs_the_same(fmus, tmp_path):
    """An archive packed as SSP 2.0 declares it in its SSD and parameter files, passes the 2.0 schema and
    gives the values of the 1.0 folder it was packed from; the default stays 1.0."""
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.ssp_pack import archive_version, pack

    ssd = t.document(t.system("root", [t.component("A", "Adder", t.adder_connectors("1.0", True),
                                                   t.bindings(t.from_file("set.ssv")))]), "1.0")
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus["1.0"]["Adder"]},
                     {"set.ssv": t.parameter_set({"k1": 6.0}, "1.0", standalone=True)})
    v2 = pack(folder, tmp_path, tmp_path / "v2.ssp", ssp_version="2.0")
    v1 = pack(folder, tmp_path, tmp_path / "v1.ssp")
    assert (archive_version(v2), archive_version(v1)) == ("2.0", "1.0")
    assert load_scenario(v2).version == "2.0"
    assert run(v2)["A.y"] == run(folder)["A.y"] == pytest.approx(6.0 * U1 + K2 * U2, abs=1e-12)
    args = cli.build_parser().parse_args(["build", "--ssp-version", "2.0"])
    assert args.ssp_version == "2.0"


def test_ssp2_local_connector_is_checked_and_refused_when_connected(fmus, tmp_path, capsys):
    """SSP 2.0's ``kind="local"``: declared on the FMU's local variable it binds and the run goes through;
    connected (SSP: "the semantics are same as for an output") the master, which carries outputs only,
    refuses in one line naming the connection."""
    v = "2.0"
    conns = t.adder_connectors(v).replace("</ssd:Connectors>", t.connector("twice_y", "local", v) + "</ssd:Connectors>")
    folder = t.write(tmp_path / "ok", t.document(t.system("root", [t.component("A", "Adder", conns)]), v),
                     {"Adder": fmus[v]["Adder"]})
    assert run(folder)["A.y"] == pytest.approx(K1 * U1 + K2 * U2, abs=1e-12)
    msg = _refusal(v, t.system("root", [t.component("A", "Adder", conns), t.component("B", "Adder", conns)],
                               [t.connection("A.twice_y", "B.u1")]), fmus, tmp_path, capsys)
    assert "A.twice_y -> B.u1" in msg and "local" in msg


#: The SSD's declaration of the enumeration type Mode (connectors of type Enumeration name it).
ENUMS = ("<ssd:Enumerations><ssc:Enumeration name=\"Mode\">"
         + "".join(f'<ssc:Item name="{k}" value="{v}"/>' for k, v in adder_fmus.MODE.items())
         + "</ssc:Enumeration></ssd:Enumerations>")


def test_enumeration_value_by_item_name(fmus, tmp_path):
    """An ``ssv:Enumeration`` value is an item name, applied as that item's value in the variable's
    enumeration type ("the actual numeric value ... will depend on the item mapping of the enumeration type
    of the variables being parameterized"); PassThrough gives int_out = int_in + offset."""
    conns = ("<ssd:Connectors>" + t.connector("int_out", "output", "1.0", type_='Enumeration name="Mode"')
             + "</ssd:Connectors>")
    enum = ('<ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0" name="e"><ssv:Parameters>'
            '<ssv:Parameter name="offset"><ssv:Enumeration value="Fast"/></ssv:Parameter></ssv:Parameters>'
            '</ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>')
    folder = t.write(tmp_path / "s", t.document(t.system("root", [t.component("p", "Modes", conns, t.bindings(enum))]),
                                                "1.0", units=ENUMS), {"Modes": fmus["1.0"]["Modes"]})
    assert run(folder)["p.int_out"] == 0 + adder_fmus.MODE["Fast"]
    bad = tmp_path / "bad"
    t.write(bad, (folder / "SystemStructure.ssd").read_text().replace('value="Fast"', 'value="Fastest"'),
            {"Modes": fmus["1.0"]["Modes"]})
    with pytest.raises(BindingError, match="'Fastest' is not an item of offset's enumeration"):
        ipcosim.run(bad, stop_time=0.2)


def test_enumeration_mapping_on_a_mapping_entry_and_a_connection(fmus, tmp_path):
    """``ssc:EnumerationMappingTransformation`` maps item names, in a parameter mapping (Slow -> Fast for
    A's offset) and on a connection (A.int_out Fast -> B.int_in Slow); items it does not name pass."""
    def conns(*names):
        kinds = {"int_in": "input", "int_out": "output"}
        return "<ssd:Connectors>" + "".join(t.connector(n, kinds[n], "1.0", type_='Enumeration name="Mode"')
                                            for n in names) + "</ssd:Connectors>"
    emap = ('<ssc:EnumerationMappingTransformation><ssc:MapEntry source="{a}" target="{b}"/>'
            '</ssc:EnumerationMappingTransformation>')
    mapping = ('<ssd:ParameterMapping><ssm:ParameterMapping version="1.0"><ssm:MappingEntry source="offset" '
               f'target="offset">{emap.format(a="Slow", b="Fast")}</ssm:MappingEntry></ssm:ParameterMapping>'
               '</ssd:ParameterMapping>')
    enum = ('<ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0" name="e"><ssv:Parameters>'
            '<ssv:Parameter name="offset"><ssv:Enumeration value="Slow"/></ssv:Parameter></ssv:Parameters>'
            f'</ssv:ParameterSet></ssd:ParameterValues>{mapping}</ssd:ParameterBinding>')
    ssd = t.document(t.system("root", [t.component("A", "Modes", conns("int_out"), t.bindings(enum)),
                                       t.component("B", "Modes", conns("int_in", "int_out"))],
                              [t.connection("A.int_out", "B.int_in", emap.format(a="Fast", b="Slow"))]), "1.0",
                     units=ENUMS)
    folder = t.write(tmp_path / "s", ssd, {"Modes": fmus["1.0"]["Modes"]})
    values = run(folder)
    mode = adder_fmus.MODE
    assert values["A.int_out"] == 0 + mode["Fast"]           # offset Slow, mapped to Fast
    assert values["B.int_in"] == mode["Slow"]                # Fast on the wire, mapped to Slow
    assert values["B.int_out"] == mode["Slow"] + mode["Off"]  # B's offset keeps its start 0 (Off)


@pytest.mark.parametrize("version", VERSIONS)
def test_prefix_comes_before_the_mapping(version, fmus, tmp_path):
    """"the specified prefix is prepended to all names in the parameter source prior to processing the
    normal name resolution or name mapping rules": a system-level binding with ``prefix="A."`` and a
    mapping maps the prefixed name ``A.gain_a``."""
    gain_a = 3.0
    mapping = ('<ssd:ParameterMapping><ssm:ParameterMapping version="{v}"><ssm:MappingEntry source="A.gain_a" '
               'target="A.k2"/></ssm:ParameterMapping></ssd:ParameterMapping>').format(v=version)
    ssd = t.document(t.system("root", [t.component("A", "Adder", t.adder_connectors(version))],
                              binding=t.bindings(t.inline({"gain_a": gain_a}, version, prefix="A.", mapping=mapping))),
                     version)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[version]["Adder"]})
    assert run(folder)["A.y"] == pytest.approx(K1 * U1 + gain_a * U2, abs=1e-12)


def test_ssp2_unspecified_connectors_take_the_direction_of_the_fmu(fmus, tmp_path):
    """SSP 2.0's ``kind="unspecified"`` "can be connected to any other connector": its direction is the
    FMU variable's, so A.y (an output) feeds B.u1."""
    v = "2.0"
    a = "<ssd:Connectors>" + t.connector("y", "unspecified", v) + "</ssd:Connectors>"
    b = "<ssd:Connectors>" + t.connector("u1", "input", v) + t.connector("y", "output", v) + "</ssd:Connectors>"
    ssd = t.document(t.system("root", [t.component("A", "Adder", a, t.bindings(t.inline({"u1": 4.0}, v))),
                                       t.component("B", "Adder", b)], [t.connection("A.y", "B.u1")]), v)
    folder = t.write(tmp_path / "s", ssd, {"Adder": fmus[v]["Adder"]})
    a_y = K1 * 4.0 + K2 * U2
    assert run(folder)["B.y"] == pytest.approx(K1 * a_y + K2 * U2, abs=1e-12)
