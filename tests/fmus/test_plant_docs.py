"""The parameter tables of docs/plant.md match ipcosim.fmus.params (the docs cannot go stale silently)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from ipcosim.fmus.params import PLANT_KINDS, PRESETS, parameter_info, preset

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "plant.md"
README = ROOT / "docs" / "plant.md"  # the table of every preset side by side


def doc_table(name: str) -> dict[str, tuple[float, str]]:
    text = DOC.read_text()
    start = text.index(f"#### `{name}`")
    ends = [i for i in (text.find("####", start + 5), text.find("\n## ", start)) if i >= 0]
    end = min(ends) if ends else len(text)
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


def readme_table() -> tuple[list[str], dict[str, tuple[list[str], str]]]:
    """The side-by-side table: preset columns, then per parameter (cells per preset, unit)."""
    text = README.read_text()
    header = re.search(r"^\| parameter \| (thesis-ch3 \|.+?) \| unit \| meaning \| source \|$", text, re.M)
    assert header, "docs/plant.md: side-by-side parameter table not found"
    presets = [c.strip() for c in header.group(1).split("|")]
    rows = {}
    for m in re.finditer(r"^\| `(\w+)` \| (.+)$", text[header.end():], re.M):
        cells = [c.strip() for c in m.group(2).rstrip("|").split("|")]
        rows[m.group(1)] = (cells[:len(presets)], cells[len(presets)])
    return presets, rows


def test_readme_parameter_table_matches_presets() -> None:
    presets, rows = readme_table()
    assert sorted(presets) == sorted(PRESETS)
    for col, name in enumerate(presets):
        kind = PRESETS[name][0]
        params = preset(name)
        for info in parameter_info(PLANT_KINDS[kind]):
            assert info["name"] in rows, f"docs/plant.md lacks parameter {info['name']}"
            cells, unit = rows[info["name"]]
            assert float(cells[col]) == pytest.approx(getattr(params, info["name"]), rel=1e-5), (name, info["name"])
            assert unit == info["unit"], info["name"]
        names = {i["name"] for i in parameter_info(PLANT_KINDS[kind])}
        for pname, (cells, _) in rows.items():
            if pname not in names:
                assert cells[col] == "-", f"docs/plant.md gives {pname} a value for {name}, which has no such parameter"
