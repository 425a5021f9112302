"""Loading SSP scenarios (no FMU needed): the project's ten scenarios, folders and archives,
schema validation, parameter sets, and every malformed-file case with its one-line message."""
from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path

import pytest
from lxml import etree
from ssd_helpers import component, connection, connector, ssd, ssv, write_scenario

from devtools.ssp_gen import CONTROLLERS, PLANTS, ssd_text
from ipcosim.harness.scenario.errors import ScenarioError, ScenarioNotFoundError
from ipcosim.harness.scenario.files import NS
from ipcosim.harness.scenario.locations import scenario_names
from ipcosim.harness.scenario.ssp import load_scenario
from ipcosim.harness.scenario.ssp_pack import pack
from ipcosim.harness.scenario.structure import Unit, select_parameter_set
from ipcosim.harness.scenario.units import unit_conversion

ROOT = Path(__file__).resolve().parents[2]
EXPECTED = sorted(f"{p}-{c}" for p in ("single-mass", "double-mass")
                  for c in ("pid", "cascade-pid", "lqr", "lqg", "hsmc", "adaptive-hsmc"))


def test_the_twelve_scenarios_exist_and_follow_the_contract():
    from devtools.ssp_gen import VARIANTS

    assert scenario_names() == sorted(EXPECTED + list(VARIANTS))
    for name in EXPECTED:
        sc = load_scenario(name)  # schema-validated
        assert sc.name == name
        assert [c.name for c in sc.components] == ["setpoint", "controller", "plant"]
        plant, law = name.split("-", 2)[0] + "-mass", name.split("-", 2)[2]
        model = "IP02SingleMass" if plant == "single-mass" else "IP02DoubleMass"
        assert sc.component("plant").source == f"resources/{model}.fmu"
        assert sc.component("controller").source == \
            f"resources/{CONTROLLERS[law][0]}{PLANTS[plant]['suffix']}.fmu"
        assert sc.component("setpoint").source == "resources/Setpoint.fmu"
        assert (sc.experiment.start_time, sc.experiment.stop_time, sc.experiment.step_size) == (0.0, 10.0, 0.001)
        setpoint = {p.name: p.value for b in sc.component("setpoint").bindings for p in b.parameters}
        assert setpoint["amplitude"] == 0.05
        measured = ["cart_position", "pendulum_angle"] if plant == "single-mass" else \
            ["active_cart_position", "passive_cart_position", "pendulum_angle"]
        into_controller = [c.end_connector for c in sc.connections if c.end_element == "controller"]
        assert into_controller == ["reference", *measured]
        assert [(c.start, c.end) for c in sc.connections if c.end_element == "plant"] == \
            [("controller.voltage", "plant.voltage")]
        for c in sc.components:  # every connector typed with a unit (libcosim requires the type)
            assert all(k.type == "Real" and k.unit for k in c.connectors)
        # names of connectors equal the FMU variable names of the contract
        assert {k.name for k in sc.component("controller").connectors} == {"reference", "voltage", *measured}


def test_scenario_files_are_what_the_generator_writes():
    """The committed files equal what ``python -m devtools.ssp_gen`` writes from the controllers'
    catalog (so a changed parameter set cannot silently diverge from the scenarios)."""
    from devtools.ssp_gen import parameter_sets, ssv_text

    for name in EXPECTED:
        plant = name[:11]
        law = name[12:]
        sc = load_scenario(name)
        sets = parameter_sets(plant, law)
        assert sets, name
        default = "tuned" if "tuned" in sets else "thesis"
        assert sc.bound_sets == (default,)
        assert sorted(sc.parameter_sets) == sorted(sets)
        period = float(sets[default].get("sample_period", 1e-3))
        assert (ROOT / "ssp" / name / "SystemStructure.ssd").read_text() == ssd_text(plant, law, default, period)
        for set_name, values in sets.items():
            assert (ROOT / "ssp" / name / f"{set_name}.ssv").read_text() == \
                ssv_text(values, set_name, f"{name}: {set_name} controller parameters")


def test_libcosim_reads_the_literal_prefixes():
    # libcosim's parser matches element names with their prefixes (ssd:, ssc:, ssv:, osp:)
    text = (ROOT / "ssp" / "single-mass-lqr" / "SystemStructure.ssd").read_text()
    for tag in ("<ssd:SystemStructureDescription", "<ssd:Component ", "<ssc:Real ", "<osp:FixedStepAlgorithm",
                '<ssc:Annotation type="com.opensimulationplatform">', "<ssd:Connection "):
        assert tag in text


def test_folder_and_packed_archive_load_the_same(tmp_path):
    fmus = tmp_path / "fmus"
    fmus.mkdir()
    for m in ("Setpoint", "LQRSingleMass", "IP02SingleMass"):
        (fmus / f"{m}.fmu").write_bytes(b"placeholder")
    archive = pack(ROOT / "ssp" / "single-mass-lqr", fmus, tmp_path / "single-mass-lqr.ssp")
    with zipfile.ZipFile(archive) as zf:
        assert {"SystemStructure.ssd", "resources/Setpoint.fmu", "resources/LQRSingleMass.fmu",
                "resources/IP02SingleMass.fmu"} <= set(zf.namelist())
    a, b = load_scenario("single-mass-lqr"), load_scenario(archive)
    assert a.components[0].connectors == b.components[0].connectors
    assert a.connections == b.connections and a.experiment == b.experiment and a.units == b.units
    assert b.origin.endswith("single-mass-lqr.ssp:SystemStructure.ssd")
    # the SSD of a folder may also be named directly
    assert load_scenario(ROOT / "ssp" / "single-mass-lqr" / "SystemStructure.ssd").connections == a.connections


def test_missing_fmu_of_a_packed_scenario_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="component 'setpoint': Setpoint.fmu not found"):
        pack(ROOT / "ssp" / "single-mass-lqr", tmp_path, tmp_path / "x.ssp")


# ------------------------------------------------------------------ bad files
def test_unknown_name_or_path(tmp_path):
    with pytest.raises(ScenarioNotFoundError, match="unknown scenario 'single-mass-foo'; did you mean 'single-mass-"):
        load_scenario("single-mass-foo")
    with pytest.raises(ScenarioNotFoundError, match="does not exist"):
        load_scenario(tmp_path / "nowhere.ssp")
    with pytest.raises(ScenarioNotFoundError, match="folder has no SystemStructure.ssd"):
        load_scenario(tmp_path)


def test_ssp_that_is_not_a_zip(tmp_path):
    bad = tmp_path / "broken.ssp"
    bad.write_text("this is not a zip archive")
    with pytest.raises(ScenarioError, match=r"broken.ssp: not an SSP archive \(not a zip file"):
        load_scenario(bad)


def test_ssp_without_system_structure(tmp_path):
    bad = tmp_path / "empty.ssp"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("resources/readme.txt", "no SSD here")
    with pytest.raises(ScenarioError, match="empty.ssp: no SystemStructure.ssd at the top level of the archive"):
        load_scenario(bad)


def test_ssd_failing_the_schema_names_file_and_line(tmp_path):
    text = ssd("s", [component("a", "A", [connector("y", "output")])], [])
    text = text.replace('kind="output"', 'kind="sideways"')
    folder = write_scenario(tmp_path / "s", text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(folder)
    msg = str(info.value)
    assert "SystemStructure.ssd:" in msg and "fails the SSP 1.0 schema" in msg and "sideways" in msg
    line = int(msg.split("SystemStructure.ssd:")[1].split(":")[0])
    assert 'kind="sideways"' in text.splitlines()[line - 1]
    assert "\n" not in msg


def test_ssd_that_is_not_xml(tmp_path):
    folder = write_scenario(tmp_path / "s", "<ssd:SystemStructureDescription")
    with pytest.raises(ScenarioError, match="not well-formed XML"):
        load_scenario(folder)


def test_connection_to_an_undeclared_connector_or_component(tmp_path):
    comps = [component("a", "A", [connector("y", "output")]), component("b", "B", [connector("u", "input")])]
    folder = write_scenario(tmp_path / "s1", ssd("s", comps, [connection("a.y", "b.v")]))
    with pytest.raises(ScenarioError, match=r"connection names b\.v, but component 'b' declares no connector 'v'"):
        load_scenario(folder)
    folder = write_scenario(tmp_path / "s2", ssd("s", comps, [connection("c.y", "b.u")]))
    with pytest.raises(ScenarioError, match="component 'c', which the system does not have"):
        load_scenario(folder)


def test_missing_parameter_file(tmp_path):
    comps = [component("a", "A", [connector("y", "output")], bindings=["gone.ssv"])]
    folder = write_scenario(tmp_path / "s", ssd("s", comps, []))
    with pytest.raises(ScenarioError, match="parameter binding source 'gone.ssv' does not exist"):
        load_scenario(folder)


def test_invalid_parameter_file_names_it(tmp_path):
    comps = [component("a", "A", [connector("y", "output")], bindings=["thesis.ssv"])]
    folder = write_scenario(tmp_path / "s", ssd("s", comps, []), ssvs={"thesis.ssv": "<nope/>"})
    with pytest.raises(ScenarioError, match=r"thesis.ssv:1: fails the SSP 1.0 schema"):
        load_scenario(folder)


# ------------------------------------------------------------------ content
def test_parameter_sets_bindings_transformations_and_units(tmp_path):
    comps = [component("a", "A", [connector("y", "output")], inline={"value": 3.0}),
             component("b", "B", [connector("u", "input", "mm")], bindings=["tuned.ssv"])]
    units = ('<ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>'
             '<ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>')
    folder = write_scenario(tmp_path / "s", ssd("s", comps, [connection("a.y", "b.u", factor=2.0, offset=0.5)],
                                                units=units),
                            ssvs={"tuned.ssv": ssv("tuned", {"k": 1.5}), "thesis.ssv": ssv("thesis", {"k": 7.0})})
    sc = load_scenario(folder)
    assert sc.connections[0].factor == 2.0 and sc.connections[0].offset == 0.5  # ssc:LinearTransformation
    assert [p.value for p in sc.component("a").bindings[0].parameters] == [3.0]
    assert sc.component("b").bindings[0].name == "tuned" and sc.component("b").bindings[0].parameters[0].value == 1.5
    assert sorted(sc.parameter_sets) == ["thesis", "tuned"] and sc.bound_sets == ("tuned",)
    thesis = select_parameter_set(sc, "thesis")
    assert thesis.component("b").bindings[0].parameters[0].value == 7.0
    assert thesis.component("a").bindings == sc.component("a").bindings  # inline values stay
    with pytest.raises(ScenarioError, match=r"has no parameter set 'best'; known: thesis, tuned"):
        select_parameter_set(sc, "best")
    assert sc.units["mm"].factor == 0.001
    assert unit_conversion("m", "mm", sc.units) == (pytest.approx(1000.0), 0.0)
    assert unit_conversion("m", "rad", {**sc.units, "rad": Unit("rad", (0, 0, 0, 0, 0, 0, 0, 1))}) is None


def test_loaded_scenario_is_immutable():
    sc = load_scenario("single-mass-lqr")
    with pytest.raises(dataclasses.FrozenInstanceError):
        sc.components[0].name = "x"  # type: ignore[misc]


def test_schema_rejects_what_fmpy_reads_carelessly(tmp_path):
    # fmpy's read_ssd does not validate an SSD it reads from a folder; ours always does
    folder = write_scenario(tmp_path / "s", ssd("s", [component("a", "A", [connector("y", "output")])], []))
    root = etree.parse(str(folder / "SystemStructure.ssd")).getroot()
    root.attrib.pop("version")
    (folder / "SystemStructure.ssd").write_bytes(etree.tostring(root))
    with pytest.raises(ScenarioError, match="version"):
        load_scenario(folder)
    assert NS["ssd"].endswith("SystemStructureDescription")


def test_list_prints_one_line_per_scenario(capsys):
    from ipcosim.harness import cli

    assert cli.main(["list"]) == 0
    from devtools.ssp_gen import VARIANTS

    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == sorted(EXPECTED + list(VARIANTS))
    assert all("at 0.001 s" in line and "sets:" in line for line in lines)
    assert all("10 s at 0.001 s" in line for line in lines if line.split()[0] in EXPECTED)


def test_variant_scenarios_are_what_the_generator_writes():
    """single-mass-swing-up, single-mass-lqr-tap, double-mass-hsmc-lab: committed files = generator output,
    and their plant start values and experiments load as written."""
    from devtools.ssp_gen import VARIANTS, variant_files

    for name, (plant, law, _, amplitude, stop_time, plant_values) in VARIANTS.items():
        files = variant_files(name)
        assert sorted(p.name for p in (ROOT / "ssp" / name).iterdir()) == sorted(files)
        for file, text in files.items():
            assert (ROOT / "ssp" / name / file).read_text() == text, (name, file)
        sc = load_scenario(name)
        assert sc.component("controller").source == f"resources/{law}{PLANTS[plant]['suffix']}.fmu"
        assert sc.experiment.stop_time == stop_time
        bound = {p.name: p.value for b in sc.component("plant").bindings for p in b.parameters}
        assert bound == plant_values
        assert {p.name: p.value for b in sc.component("setpoint").bindings for p in b.parameters}["amplitude"] == \
            amplitude
