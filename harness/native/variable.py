"""A native model's FMI variable and the plant's tap state: what the model generator (``models``) and its
model-exchange part (``exchange``) both name, below either of them."""
from __future__ import annotations

from dataclasses import dataclass

#: The native plant's state that says whether the taps have acted (0 before, 1 after).
TAPPED = "S:tapped"


@dataclass
class NativeVariable:
    """One FMI scalar variable of a native model (``index`` = its slot in the value array)."""

    name: str
    vr: int
    causality: str
    variability: str
    type: str = "Real"
    start: float | None = None
    initial: str | None = None
    unit: str | None = None
    description: str = ""
    index: int = -1
    depends_on: tuple[str, ...] | None = None
    initial_depends_on: tuple[str, ...] | None = None
