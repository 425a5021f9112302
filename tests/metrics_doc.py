"""The metrics docs/metrics.md defines, for the tests that check a run writes only those."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def documented_metrics() -> set[str]:
    """The keys docs/metrics.md defines (first cell of its tables)."""
    text = (ROOT / "docs" / "metrics.md").read_text()
    return {key for row in re.findall(r"^\| (`[^|]+`) \|", text, re.M) for key in re.findall(r"`([^`]+)`", row)}
