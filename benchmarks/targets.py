"""How a bench module reports missed targets (see ``benchmarks.bench``)."""
from __future__ import annotations


class TargetMissed(Exception):
    """A bench's figures (``lines``) miss one or more targets (``missed``, one line each)."""

    def __init__(self, lines: list[str], missed: list[str]) -> None:
        super().__init__("; ".join(missed))
        self.lines = lines
        self.missed = missed
