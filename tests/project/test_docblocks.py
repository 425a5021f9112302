"""Every generated block of the docs is what its tool writes now (``devtools.docblocks``): the rooms table, the
API table, the bench figures (from the committed benchmarks/last.json), the pure-loop evidence tables and the
results page (from the committed docs/results.json); and the one marker grammar's splicer."""
from __future__ import annotations

import importlib

import pytest

from devtools import docblocks
from devtools.docblocks import ROOT, Block, BlockError, blocks, documents, generator, rendered, splice


def _same(block: Block, now: str) -> bool:
    """The block's text is ``now``: byte for byte, or to the tolerance its tool declares (``same_block``: the
    evidence tables' last digits move between numpy builds)."""
    module = importlib.import_module(docblocks.TOOLS[block.tool].split(":")[0])
    return getattr(module, "same_block", str.__eq__)(block.text, now)


#: Tools whose blocks take tens of seconds to write (the evidence tables run every law on every plant, 10 s each).
SLOW = {"evidence"}


def _every_block() -> list:
    found = []
    for doc in documents():
        origin = str(doc.relative_to(ROOT))
        for block in blocks(doc.read_text(encoding="utf-8"), origin):
            marks = [pytest.mark.slow] if block.tool in SLOW else []
            found.append(pytest.param(origin, block.name, marks=marks, id=f"{origin}:{block.name}"))
    return found


@pytest.mark.parametrize("origin, name", _every_block())
def test_every_generated_block_is_current(origin: str, name: str) -> None:
    (block,) = [b for b in blocks((ROOT / origin).read_text(encoding="utf-8"), origin) if b.name == name]
    assert _same(block, rendered(block, origin)), (f"{origin}: block {name} is not what its tool writes now: "
                                                   f"run `python -m devtools.docblocks --update` and commit {origin}")


def test_every_tool_writes_a_block_of_the_docs() -> None:
    names = {b.tool for doc in documents() for b in blocks(doc.read_text(encoding="utf-8"))}
    assert names == set(docblocks.TOOLS)


def test_a_stale_block_is_rewritten_and_the_rest_kept() -> None:
    rest = "middle\n<!-- rooms:table -->\nx\n<!-- /rooms:table -->\n"
    page = "intro\n<!-- api:run -->\nold table\n<!-- /api:run -->\n" + rest
    new = splice(page, lambda b: "new\n" if b.name == "api:run" else None)
    assert new == "intro\n<!-- api:run -->\nnew\n<!-- /api:run -->\n" + rest
    assert splice(new, lambda b: None) == new
    current = docblocks.current(page, tools=("api",))
    assert current.startswith("intro\n<!-- api:run -->\n| Python | command line | |\n") and "old table" not in current
    assert docblocks.current(current, tools=("api",)) == current


def test_bad_markers_and_names_are_one_clear_error() -> None:
    with pytest.raises(BlockError, match=r"x\.md: block 'api:run' has no closing <!-- /api:run -->"):
        list(blocks("<!-- api:run -->\ntable\n<!-- /api:rn -->\n", "x.md"))
    with pytest.raises(BlockError, match="no tool writes blocks named nosuch:"):
        generator("nosuch")
    with pytest.raises(BlockError, match=r"x\.md: block 'bench:plnt': no bench block 'plnt' \(closest: plant\)"):
        rendered(next(blocks("<!-- bench:plnt -->\n<!-- /bench:plnt -->\n")), "x.md")


def test_write_names_a_missing_block(tmp_path) -> None:
    doc = tmp_path / "page.md"
    doc.write_text("no blocks here\n")
    with pytest.raises(BlockError, match="no <!-- rooms:table --> ... <!-- /rooms:table --> block"):
        docblocks.write(doc, "rooms:table", "x\n")
    doc.write_text("a\n<!-- rooms:table -->\nold\n<!-- /rooms:table -->\nb\n")
    assert docblocks.write(doc, "rooms:table", "new\n") and not docblocks.write(doc, "rooms:table", "new\n")
    assert doc.read_text() == "a\n<!-- rooms:table -->\nnew\n<!-- /rooms:table -->\nb\n"
