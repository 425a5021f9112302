"""docs/architecture.md's figures are the tree's: the rooms table (its ``rooms:table`` block, which
tests/project/test_docblocks.py checks is what ``python -m devtools.rooms`` computes now) counts every
source file in exactly one room, and the page states no other count of the code outside the table, where
nothing would keep it true."""
from __future__ import annotations

import re
from pathlib import Path

from devtools import rooms
from devtools.docblocks import splice

#: The clone: the folder above this test that holds pyproject.toml (the test may sit in a sub-folder of tests/).
ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
DOC = ROOT / "docs" / "architecture.md"
#: The folders whose files the table counts: the installed package's and the clone's own tooling.
COUNTED = ("fmus", "controllers", "harness", "evidence", "benchmarks", "devtools")


def test_every_source_file_is_in_one_room() -> None:
    files = sorted(p.relative_to(ROOT) for folder in COUNTED for p in (ROOT / folder).rglob("*.py"))
    files += sorted(p.relative_to(ROOT) for p in ROOT.glob("*.py"))
    counted: dict[Path, list[str]] = {f: [] for f in files}
    for room, (folder, deep) in rooms.ROOMS.items():
        for f in rooms.room_files(folder, deep):
            counted.setdefault(f.relative_to(ROOT), []).append(room)
    wrong = {str(f): where for f, where in counted.items() if len(where) != 1}
    assert not wrong, f"files in no room or in several rooms of devtools/rooms.py's ROOMS: {wrong}"


#: A count of the code (``3216 lines``, ``19 modules``, ``0 cycles``) in running text.
COUNT = re.compile(r"\b\d[\d,.]*\s+(?:non-blank\s+)?(?:modules?|lines|functions?|(?:import )?cycles?|rooms?|files?)\b")
#: The one number of that shape the page may state outside the table: the length it asks functions to keep to.
RULE = "about 60 lines"


def counts_outside_the_markers(page: str) -> list[str]:
    outside = splice(page, lambda block: "" if block.name == rooms.BLOCK else None)
    return [m.group(0) for m in COUNT.finditer(outside.replace(RULE, ""))]


def test_no_count_of_the_code_outside_the_table() -> None:
    found = counts_outside_the_markers(DOC.read_text())
    assert not found, (f"docs/architecture.md states counts outside the generated table, which no test keeps true: "
                       f"{found}; move them into devtools/rooms.py's table or remove them")


def test_the_count_check_sees_a_count() -> None:
    page = (f"The master has 16 modules and 3,839 lines, {RULE}.\n<!-- {rooms.BLOCK} -->\n| x | 12 lines |\n"
            f"<!-- /{rooms.BLOCK} -->\nImport cycles: 0 cycles.\n")
    assert counts_outside_the_markers(page) == ["16 modules", "3,839 lines", "0 cycles"]
