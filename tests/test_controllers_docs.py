"""docs/controllers.md shows what the code computes: the evidence table and the tuned gains."""
from __future__ import annotations

import re
from pathlib import Path

from controllers.catalog import TUNED_CASCADE, TUNED_HSMC
from controllers.evidence import BEGIN, END, document

DOC = Path(__file__).resolve().parents[1] / "docs" / "controllers.md"
README = DOC.parents[1] / "README.md"


def test_evidence_table_in_the_docs_is_current() -> None:
    expected = document().strip()
    for doc in (DOC, README):
        text = doc.read_text()
        block = text[text.index(BEGIN) + len(BEGIN):text.index(END)].strip()
        assert block == expected, f"run: python -m controllers.evidence --update {doc.name}"


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
