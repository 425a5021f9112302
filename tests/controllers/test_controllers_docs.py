"""docs/controllers.md shows what the code computes: the evidence table and the tuned gains."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from evidence.controllers_table import BEGIN, END, document
from ipcosim.controllers.laws.hsmc import TUNED_HSMC
from ipcosim.controllers.laws.pid import TUNED_CASCADE

DOC = Path(__file__).resolve().parents[2] / "docs" / "controllers.md"


_NUMBER = re.compile(r"-?\d+\.\d+")


def _same_table(shown: str, computed: str) -> bool:
    """Equal text, and numbers equal to the last digit shown (+-1): the figures after a fall
    (a chaotic trajectory) move in their last digit between numpy/scipy builds.

    The second table (measurements rounded to encoder counts) is compared on its rows' law,
    plant and parameter set only: sliding-mode laws chatter on quantized signals, and whether
    such a run is inside the band at 10 s changes with the last bit of a floating-point sum
    (docs/controllers.md says so beside the table)."""
    shown_ideal, _, shown_quantized = shown.partition("rounded to whole encoder counts")
    computed_ideal, _, computed_quantized = computed.partition("rounded to whole encoder counts")
    if [r.split("|")[1:4] for r in shown_quantized.splitlines() if r.startswith("| ")] != \
            [r.split("|")[1:4] for r in computed_quantized.splitlines() if r.startswith("| ")]:
        return False
    shown, computed = shown_ideal, computed_ideal
    if _NUMBER.sub("#", shown) != _NUMBER.sub("#", computed):
        return False
    for a, b in zip(_NUMBER.findall(shown), _NUMBER.findall(computed)):
        last = 10.0 ** -len(a.split(".")[1])
        if abs(float(a) - float(b)) > 1.01 * last:
            return False
    return True


@pytest.mark.slow
def test_evidence_table_in_the_docs_is_current() -> None:
    expected = document().strip()
    for doc in (DOC,):
        text = doc.read_text()
        block = text[text.index(BEGIN) + len(BEGIN):text.index(END)].strip()
        assert _same_table(block, expected), \
            f"run: python -m evidence.controllers_table --update docs/{doc.name}"


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
