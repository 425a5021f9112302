"""Writes the project's twelve SSP scenarios (``ssp/<plant>-<controller>/``) from one table, so
that they stay consistent: ``python -m devtools.ssp_gen`` (the files are committed; run it
after changing a component's connectors or a parameter set).

Each scenario: ``SystemStructure.ssd`` (SSP 1.0) with the components ``setpoint``
(``Setpoint``), ``controller`` (``<Law><Plant>``) and ``plant`` (``IP02<Plant>``), referencing
``resources/<Model>.fmu``; connections by variable name; the default experiment 0..10 s at a
1 ms step (``DefaultExperiment`` plus the OSP annotation libcosim reads); the setpoint's step
0 -> 0.05 m at t = 0 as inline parameter values; and the controller's parameter sets as
``.ssv`` files (``thesis``, and ``tuned`` where the controller design has one), the SSD
binding ``tuned`` when it exists, else ``thesis``. The file names of the sets are the set
names; ``ipcosim run --parameter-set thesis`` binds another one.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Mapping
from xml.sax.saxutils import quoteattr

from ipcosim.harness.scenario.files import NS
from ipcosim.harness.scenario.scenarios import (
    AMPLITUDE,
    CONTROLLERS,
    PLANTS,
    STATE_UNITS,
    STEP,
    STEP_TIME,
    STOP_TIME,
    UNITS,
    VARIANTS,
)
from ipcosim.harness.scenario.ssv import ssv_text
from ipcosim.harness.support.paths import SCENARIO_DIR


def plant_signals(plant: str) -> tuple[list[str], list[str]]:
    """(measured outputs, all outputs in FMU order) of a plant kind."""
    from ipcosim.fmus.physics import MEASURED, state_names

    measured = list(MEASURED[plant])
    outputs = measured + [n for n in state_names(plant) if n not in measured]
    return measured, outputs


def parameter_sets(plant: str, controller: str) -> dict[str, dict[str, Any]]:
    """The controller's named parameter sets (``thesis``, ``tuned``): variable -> value.

    Taken from ``ipcosim.controllers.catalog.parameter_sets(kind, law)``.
    """
    from ipcosim.controllers.catalog import parameter_sets as catalog_sets

    return {k: dict(v) for k, v in catalog_sets(plant, CONTROLLERS[controller][0]).items() if v}


def _connector(name: str, kind: str, unit: str) -> str:
    return f'          <ssd:Connector name="{name}" kind="{kind}"><ssc:Real unit="{unit}"/></ssd:Connector>'


def ssd_text(plant: str, controller: str, default_set: str | None, sample_period: float | None,
             variant: str | None = None) -> str:
    """The SystemStructure.ssd of one scenario (``variant``: a name of ``VARIANTS``; then ``controller``
    is ignored): the three components ``setpoint``, ``controller``, ``plant``, their connections,
    the units and the default experiment."""
    p = PLANTS[plant]
    amplitude, stop_time, plant_values = AMPLITUDE, STOP_TIME, {}
    if variant is None:
        law, law_doc = CONTROLLERS[controller]
        name = f"{plant}-{controller}"
        description = f"IP02 {p['description']}: {law_doc}; the motor-driven cart moves 0 -> {AMPLITUDE} m"
    else:
        _, law, law_doc, amplitude, stop_time, plant_values = VARIANTS[variant]
        name, description = variant, f"IP02 {p['description']}: {law_doc}"
    measured, outputs = plant_signals(plant)
    L = ['<?xml version="1.0" encoding="UTF-8"?>',
         f'<ssd:SystemStructureDescription xmlns:ssd="{NS["ssd"]}" xmlns:ssc="{NS["ssc"]}"',
         f'    xmlns:ssv="{NS["ssv"]}" xmlns:osp="{NS["osp"]}"',
         f'    version="1.0" name="{name}" generationTool="ipcosim (devtools.ssp_gen)">',
         f'  <ssd:System name="{name}" description={quoteattr(description)}>',
         "    <ssd:Elements>"]
    L += _setpoint_lines(amplitude)
    L += _controller_lines(f"{law}{p['suffix']}", measured, default_set, sample_period)
    L += _plant_lines(p["model"], outputs, plant_values)
    L += ["    </ssd:Elements>"]
    L += _connection_lines(measured)
    L += ["  </ssd:System>"]
    L += _units_and_experiment_lines(stop_time)
    return "\n".join(L)


def _setpoint_lines(amplitude: float) -> list[str]:
    """The ``setpoint`` component: a step to ``amplitude`` [m] at ``STEP_TIME``."""
    return ['      <ssd:Component name="setpoint" type="application/x-fmu-sharedlibrary" '
            'source="resources/Setpoint.fmu">',
            "        <ssd:Connectors>",
            _connector("reference", "output", "m"),
            "        </ssd:Connectors>",
            "        <ssd:ParameterBindings>",
            "          <ssd:ParameterBinding>",
            "            <ssd:ParameterValues>",
            '              <ssv:ParameterSet version="1.0" name="experiment">',
            "                <ssv:Parameters>",
            f'                  <ssv:Parameter name="amplitude">'
            f'<ssv:Real value="{amplitude!r}" unit="m"/></ssv:Parameter>',
            f'                  <ssv:Parameter name="step_time">'
            f'<ssv:Real value="{STEP_TIME!r}" unit="s"/></ssv:Parameter>',
            "                </ssv:Parameters>",
            "              </ssv:ParameterSet>",
            "            </ssd:ParameterValues>",
            "          </ssd:ParameterBinding>",
            "        </ssd:ParameterBindings>",
            "      </ssd:Component>"]


def _controller_lines(model: str, measured: list[str], default_set: str | None,
                      sample_period: float | None) -> list[str]:
    """The ``controller`` component: reference and measured outputs in, voltage out; bound to
    ``<default_set>.ssv`` and with its sample period as ``osp:StepSizeHint`` when given."""
    L = [f'      <ssd:Component name="controller" type="application/x-fmu-sharedlibrary" '
         f'source="resources/{model}.fmu">',
         "        <ssd:Connectors>",
         _connector("reference", "input", "m")]
    L += [_connector(m, "input", STATE_UNITS[m]) for m in measured]
    L += [_connector("voltage", "output", "V"), "        </ssd:Connectors>"]
    if default_set:
        L += ["        <ssd:ParameterBindings>",
              f'          <ssd:ParameterBinding source="{default_set}.ssv"/>',
              "        </ssd:ParameterBindings>"]
    if sample_period:
        L += ["        <ssd:Annotations>",
              '          <ssc:Annotation type="com.opensimulationplatform">'
              f'<osp:StepSizeHint value="{sample_period!r}"/></ssc:Annotation>',
              "        </ssd:Annotations>"]
    return L + ["      </ssd:Component>"]


def _plant_lines(model: str, outputs: list[str], plant_values: Mapping[str, float]) -> list[str]:
    """The ``plant`` component: voltage in, its outputs out, ``plant_values`` bound inline."""
    L = [f'      <ssd:Component name="plant" type="application/x-fmu-sharedlibrary" '
         f'source="resources/{model}.fmu">',
         "        <ssd:Connectors>",
         _connector("voltage", "input", "V")]
    L += [_connector(o, "output", STATE_UNITS[o]) for o in outputs]
    L += ["        </ssd:Connectors>"]
    if plant_values:
        L += ["        <ssd:ParameterBindings>", "          <ssd:ParameterBinding>",
              "            <ssd:ParameterValues>",
              '              <ssv:ParameterSet version="1.0" name="plant">', "                <ssv:Parameters>"]
        L += [f'                  <ssv:Parameter name="{k}"><ssv:Real value="{float(v)!r}"/></ssv:Parameter>'
              for k, v in plant_values.items()]
        L += ["                </ssv:Parameters>", "              </ssv:ParameterSet>",
              "            </ssd:ParameterValues>",
              "          </ssd:ParameterBinding>", "        </ssd:ParameterBindings>"]
    return L + ["      </ssd:Component>"]


def _connection_lines(measured: list[str]) -> list[str]:
    """The loop: setpoint -> controller, the plant's measured outputs -> controller, controller -> plant."""
    L = ["    <ssd:Connections>",
         '      <ssd:Connection startElement="setpoint" startConnector="reference" '
         'endElement="controller" endConnector="reference"/>']
    L += [f'      <ssd:Connection startElement="plant" startConnector="{m}" '
          f'endElement="controller" endConnector="{m}"/>'
          for m in measured]
    return L + ['      <ssd:Connection startElement="controller" startConnector="voltage" '
                'endElement="plant" endConnector="voltage"/>',
                "    </ssd:Connections>"]


def _units_and_experiment_lines(stop_time: float) -> list[str]:
    """The SSD's units (SI base-unit exponents) and its default experiment (``STEP`` as
    ``osp:FixedStepAlgorithm``), and the closing tag."""
    L = ["  <ssd:Units>"]
    for unit, exps in UNITS.items():
        attrs = " ".join(f'{k}="{v}"' for k, v in exps.items())
        L.append(f'    <ssc:Unit name="{unit}"><ssc:BaseUnit {attrs}/></ssc:Unit>')
    return L + ["  </ssd:Units>",
                f'  <ssd:DefaultExperiment startTime="0.0" stopTime="{float(stop_time)!r}">',
                "    <ssd:Annotations>",
                '      <ssc:Annotation type="com.opensimulationplatform">',
                f'        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="{STEP!r}"/></osp:Algorithm>',
                "      </ssc:Annotation>",
                "    </ssd:Annotations>",
                "  </ssd:DefaultExperiment>",
                "</ssd:SystemStructureDescription>", ""]


def write_scenarios(root: Path = SCENARIO_DIR, names: list[str] | None = None) -> list[Path]:
    """Write (or rewrite) the scenario folders; returns the files written."""
    written = []
    for plant in PLANTS:
        for controller in CONTROLLERS:
            name = f"{plant}-{controller}"
            if names and name not in names:
                continue
            folder = root / name
            folder.mkdir(parents=True, exist_ok=True)
            sets = parameter_sets(plant, controller)
            default = "tuned" if "tuned" in sets else ("thesis" if "thesis" in sets else None)
            for set_name, values in sets.items():
                path = folder / f"{set_name}.ssv"
                path.write_text(ssv_text(values, set_name, f"{name}: {set_name} controller parameters"))
                written.append(path)
            period = sets.get(default or "", {}).get("sample_period", STEP)
            path = folder / "SystemStructure.ssd"
            path.write_text(ssd_text(plant, controller, default, float(period)))
            written.append(path)
    for name, (_plant, _law, *_rest) in VARIANTS.items():
        if names and name not in names:
            continue
        folder = root / name
        folder.mkdir(parents=True, exist_ok=True)
        for file, text in variant_files(name).items():
            (folder / file).write_text(text)
            written.append(folder / file)
    return written


def variant_files(name: str) -> dict[str, str]:
    """``{file name: text}`` of a ``VARIANTS`` scenario: its SSD and its controller's parameter sets."""
    from ipcosim.controllers.catalog import default_set
    from ipcosim.controllers.catalog import parameter_sets as catalog_sets

    plant, law = VARIANTS[name][:2]
    sets = {k: dict(v) for k, v in catalog_sets(plant, law).items() if v}
    default = "tuned" if "tuned" in sets else ("thesis" if "thesis" in sets else default_set(plant, law))
    files = {f"{s}.ssv": ssv_text(v, s, f"{name}: {s} controller parameters") for s, v in sets.items()}
    files["SystemStructure.ssd"] = ssd_text(plant, "", default, float(sets[default].get("sample_period", STEP)),
                                            variant=name)
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("names", nargs="*", help="scenarios to write (default: all)")
    args = parser.parse_args(argv)
    for path in write_scenarios(names=args.names or None):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
