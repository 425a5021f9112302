"""A scenario's description states the numbers it runs with: the identification experiments'
"N V peak" is the excitation amplitude their controller's parameter set binds."""
from __future__ import annotations

import re
from pathlib import Path
from xml.etree import ElementTree

import pytest

SSP = Path(__file__).resolve().parents[2] / "ssp"
NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}


@pytest.mark.parametrize("scenario", ["single-mass-identify", "double-mass-identify"])
def test_the_identify_description_states_the_amplitude_it_excites_with(scenario):
    folder = SSP / scenario
    system = ElementTree.parse(folder / "SystemStructure.ssd").getroot().find("ssd:System", NS)
    stated = re.search(r"([\d.]+) V peak", system.get("description"))
    assert stated, system.get("description")
    values = ElementTree.parse(folder / "identify.ssv").getroot()
    bound = next(float(p.find("ssv:Real", NS).get("value")) for p in values.iter(f"{{{NS['ssv']}}}Parameter")
                 if p.get("name") == "amplitude")
    assert float(stated.group(1)) == bound
