"""docs/controllers.md shows what the code computes: the tuned gains (the evidence table, a generated block, is
tests/project/test_docblocks.py's)."""
from __future__ import annotations

import re
from pathlib import Path

from ipcosim.controllers.laws.hsmc import TUNED_HSMC
from ipcosim.controllers.laws.pid import TUNED_CASCADE

DOC = Path(__file__).resolve().parents[2] / "docs" / "controllers.md"


def test_tuned_gains_in_the_docs_match_the_catalog() -> None:
    text = DOC.read_text()
    for name in ("Kp_th", "Kd_th", "Kp_x", "Kd_x", "Ki_x", "Kv_m"):
        row = re.search(rf"^\| {name} \[[^]]*\] \| ([^|]+) \| ([^|]+) \|$", text, re.M)
        assert row, name
        for kind, cell in zip(("single-mass", "double-mass"), row.groups()):
            assert float(cell) == getattr(TUNED_CASCADE[kind], name), (name, kind)
    g = TUNED_HSMC["single-mass"]
    assert f"`c1 = {g.c[0]}`, `c2 = {g.c[1]}`, `k = {g.k}`, `KI = {g.KI:g}`" in text
    assert f"`tau = {g.derivative_time_constant * 1e3:g} ms`" in text
