"""docs/plant.md's parameter tables match fmus.params (the doc cannot go stale silently)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from fmus.params import PLANT_KINDS, PRESETS, parameter_info, preset

DOC = Path(__file__).resolve().parents[1] / "docs" / "plant.md"


def doc_table(name: str) -> dict[str, tuple[float, str]]:
    text = DOC.read_text()
    start = text.index(f"#### `{name}`")
    end = text.find("####", start + 5)
    rows = {}
    for m in re.finditer(r"^\| `(\w+)` \| ([-+0-9.e]+)(?: \*\*\(preset\)\*\*)? \| ([^|]+) \|", text[start:end], re.M):
        rows[m.group(1)] = (float(m.group(2)), m.group(3).strip())
    return rows


@pytest.mark.parametrize("name", list(PRESETS))
def test_parameter_tables_match_presets(name: str) -> None:
    kind = PRESETS[name][0]
    params = preset(name)
    rows = doc_table(name)
    infos = parameter_info(PLANT_KINDS[kind])
    assert {i["name"] for i in infos} <= set(rows)
    for info in infos:
        value, unit = rows[info["name"]]
        assert value == pytest.approx(getattr(params, info["name"]), rel=1e-5), info["name"]
        assert unit == info["unit"]
