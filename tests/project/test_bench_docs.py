"""The speed and memory figures of the docs are written by ``python -m benchmarks.docs --update`` from
the committed ``benchmarks/last.json`` (that the blocks are current is tests/project/test_docblocks.py's), and
none is typed by hand elsewhere (``benchmarks/docs.py``)."""
from __future__ import annotations

import pytest

from benchmarks.docs import BLOCKS, ROOT, documents, load, render, stray_figures


@pytest.mark.parametrize("doc", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_speed_figure_outside_the_marked_blocks(doc):
    assert stray_figures(doc.read_text()) == []


def test_every_block_is_in_a_doc_and_renders():
    text = "".join(d.read_text() for d in documents())
    data = load()
    for name in BLOCKS:
        assert f"<!-- bench:{name} -->" in text, name
        assert "| measured | figure |" in render(name, data)


def test_the_figure_detector_finds_figures_and_spares_blocks_and_code():
    prose = ("the loop runs at 2356x real time\n", "a cycle costs 4.99 us\n", "0.27 s per run\n",
             "it grows by 57 MB\n", "5x faster than before\n")
    assert all(stray_figures(line) for line in prose)
    spared = ("<!-- bench:native -->\n2356x\n<!-- /bench:native -->\n", "```\n4.99 us\n```\n",
              "the step `0.5 us`\n", "a step of 1 ms and a watchdog of 0.5 s\n")
    assert not any(stray_figures(text) for text in spared)
