"""The generated blocks of the docs: one marker grammar, one splicer, one check.

Every generated part of ``README.md`` and ``docs/*.md`` sits between two marker lines::

    <!-- TOOL:PART -->
    (written by the tool)
    <!-- /TOOL:PART -->

``TOOL`` names the tool that writes the block (:data:`TOOLS`: its module and the function that gives a
block's text from ``PART``); everything between the markers is that text, byte for byte. The tools keep
their content generators and their own commands (``python -m devtools.rooms --write``, ...), which write
through :func:`write`; ``python -m devtools.docblocks`` lists the blocks that are not current (exit status
1), ``--update`` rewrites them all, and ``tests/project/test_docblocks.py`` checks every block of the docs.
"""
from __future__ import annotations

import importlib
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

ROOT = Path(__file__).resolve().parents[1]
#: TOOL -> "module:function"; ``function(part)`` is the text of the block ``TOOL:PART``.
TOOLS = {
    "api": "devtools.apidoc:block",
    "bench": "benchmarks.docs:block",
    "evidence": "evidence.controllers_table:block",
    "results": "evidence.results_page:block",
    "rooms": "devtools.rooms:block",
}
OPEN = re.compile(r"^<!-- ([\w-]+):([\w-]+) -->$", re.M)


class BlockError(ValueError):
    """A document's markers are not the grammar's (no closing marker, an unknown tool or part)."""


@dataclass(frozen=True)
class Block:
    """One generated block of a document: ``name`` (``TOOL:PART``), its text and where that text lies."""

    name: str
    start: int
    stop: int
    text: str

    @property
    def tool(self) -> str:
        return self.name.split(":", 1)[0]

    @property
    def part(self) -> str:
        return self.name.split(":", 1)[1]


def blocks(text: str, origin: str = "") -> Iterator[Block]:
    """The marked blocks of ``text`` in order (``BlockError`` for an opening marker without its closing one)."""
    for m in OPEN.finditer(text):
        name = f"{m.group(1)}:{m.group(2)}"
        close = f"<!-- /{name} -->"
        start = m.end() + 1
        stop = text.find(close, m.end())
        if stop < 0 or text[m.end():start] != "\n":
            raise BlockError(f"{origin}: block {name!r} has no closing {close}")
        yield Block(name, start, stop, text[start:stop])


def generator(tool: str) -> Callable[[str], str]:
    """The function that writes the blocks of ``tool`` (``BlockError`` for a tool not in :data:`TOOLS`)."""
    if tool not in TOOLS:
        raise BlockError(f"no tool writes blocks named {tool}:...; known: {', '.join(sorted(TOOLS))}")
    module, function = TOOLS[tool].split(":")
    return getattr(importlib.import_module(module), function)


def splice(text: str, written: Callable[[Block], str | None], origin: str = "") -> str:
    """``text`` with each marked block's text replaced by ``written(block)`` (the block as it is for None)."""
    out, pos = [], 0
    for block in blocks(text, origin):
        new = written(block)
        out += [text[pos:block.start], block.text if new is None else new]
        pos = block.stop
    return "".join(out) + text[pos:]


def rendered(block: Block, origin: str = "") -> str:
    """The text the block's tool writes for it now (``BlockError`` naming the document for an unknown part)."""
    try:
        return generator(block.tool)(block.part)
    except KeyError as exc:
        raise BlockError(f"{origin}: block {block.name!r}: {exc.args[0]}") from None


def current(text: str, tools: Sequence[str] | None = None, origin: str = "") -> str:
    """``text`` with every block (of ``tools``, default all) written as its tool writes it now."""
    return splice(text, lambda b: rendered(b, origin) if tools is None or b.tool in tools else None, origin)


def write(doc: Path, name: str, text: str) -> bool:
    """Write ``text`` as the block ``name`` of ``doc``; True if the file changed (``BlockError`` if it has no
    such block)."""
    page = doc.read_text(encoding="utf-8")
    if name not in {b.name for b in blocks(page, str(doc))}:
        raise BlockError(f"{doc}: no <!-- {name} --> ... <!-- /{name} --> block to write")
    new = splice(page, lambda b: text if b.name == name else None, str(doc))
    if new != page:
        doc.write_text(new, encoding="utf-8")
    return new != page


def documents(root: Path = ROOT) -> list[Path]:
    """The documents that hold blocks: README.md and the pages of docs/."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def update(docs: Sequence[Path], tools: Sequence[str] | None = None, write_back: bool = False) -> list[Path]:
    """The documents of ``docs`` with a block (of ``tools``, default all) that is not current; with
    ``write_back`` they are rewritten."""
    stale = []
    for doc in docs:
        text = doc.read_text(encoding="utf-8")
        new = current(text, tools, str(doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc))
        if new != text:
            stale.append(doc)
            if write_back:
                doc.write_text(new, encoding="utf-8")
    return stale


def main(argv: Sequence[str]) -> int:
    """``--update``: rewrite every stale block; else list the documents with one (exit status 1 if any)."""
    try:
        stale = update(documents(), write_back="--update" in argv)
    except BlockError as exc:
        print(f"docblocks: {exc}", file=sys.stderr)
        return 1
    verb = "rewrote" if "--update" in argv else "stale (run python -m devtools.docblocks --update)"
    for doc in stale:
        print(f"{verb}: {doc.relative_to(ROOT)}")
    return 0 if ("--update" in argv or not stale) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
