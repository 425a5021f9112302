"""Closed-loop evidence without the master: every law x plant x parameter set in the pure loop.

``python -m evidence.controllers_table`` prints the metrics table (markdown) that docs/controllers.md
show beside the thesis's claims; ``--update docs/controllers.md`` rewrites its ``evidence:controllers``
block (``devtools.docblocks``, whose test checks the document holds what this module computes, to the
tolerance of :func:`same_block`).

Experiment (the thesis's task): plant at its default preset (``thesis-ch3`` single mass,
``thesis-ch4`` double mass; one extra row: the long-pendulum ``thesis-appendix-a`` plant with
its own LQR design), upright at rest at 0, reference step 0 -> 0.05 m at t = 0, 10 s, plant
step 1 ms, law sampled at 1 ms with zero-order hold, +-10 V. Metrics: ``ipcosim.fmus.metrics``.
"""
from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ipcosim.controllers.catalog import LAWS, PARAMETER_SETS, default_preset, make_law
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.params import KINDS, preset

#: The thesis's qualitative result per law and plant (reference/thesis-data.md section 2).
THESIS_CLAIMS = {
    ("PID", "single-mass"): "does not work (tuner gains too large to realize)",
    ("PID", "double-mass"): "does not work",
    ("CascadePID", "single-mass"): "(not in the thesis)",
    ("CascadePID", "double-mass"): "(not in the thesis)",
    ("LQR", "single-mass"): "meets the goal with heavy oscillation",
    ("LQR", "double-mass"): "heavy oscillation; pendulum falls when the carts stop",
    ("HSMC", "single-mass"): "meets the goal; integral term removes the error",
    ("HSMC", "double-mass"): "meets the goal, steady-state error 5.575 mm",
    ("AdaptiveHSMC", "single-mass"): "reaches the position faster than HSMC",
    ("AdaptiveHSMC", "double-mass"): "smaller steady-state error and settling time than HSMC",
    ("LQG", "single-mass"): "(not in the thesis)",
    ("LQG", "double-mass"): "(not in the thesis)",
}

#: The block of docs/controllers.md that holds the tables (``devtools.docblocks``).
BLOCK = "evidence:controllers"


@dataclass(frozen=True)
class Row:
    """One closed-loop run of the table."""

    law: str
    kind: str
    parameter_set: str
    plant_preset: str
    metrics: dict


def runs(quantize: bool = False) -> list[Row]:
    """Every law x plant kind x parameter set, plus LQR on the long pendulum with its own design.

    With ``quantize`` the measurements are rounded to whole encoder counts (default sets only).
    """
    rows = []
    for law in LAWS:
        for kind in KINDS:
            for ps in PARAMETER_SETS[law][kind][:1] if quantize else PARAMETER_SETS[law][kind]:
                name = default_preset(kind)
                r = run_loop(make_law(kind, law, ps), preset(name), quantize=quantize)
                rows.append(Row(law, kind, ps, name, r.metrics))
    if not quantize:
        long = preset("thesis-appendix-a")
        r = run_loop(make_law("single-mass", "LQR", "thesis", design_params=long), long)
        rows.append(Row("LQR", "single-mass", "thesis", "thesis-appendix-a", r.metrics))
    return rows


def _fmt(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def verdict(m: dict) -> str:
    """Does the run do the task? ``yes`` / what fails."""
    if not m["upright"]:
        return "no: pendulum falls"
    if m["settling_time_s"] is None:
        return "no: cart not settled in 10 s"
    return "yes"


def table(rows: Sequence[Row], claims: bool = True) -> str:
    """The markdown table."""
    out = ["| law | plant (preset) | set | task done | settling s | overshoot mm | ss error mm | max angle rad "
           "| peak V | rms V |" + (" thesis says |" if claims else ""),
           "|---|---|---|---|---|---|---|---|---|---|" + ("---|" if claims else "")]
    for r in rows:
        m = r.metrics
        angle = "-" if m["max_abs_angle_rad"] is None else (f"{m['max_abs_angle_rad']:.3f}"
                                                             if m["max_abs_angle_rad"] < 1 else
                                                             f"{m['max_abs_angle_rad']:.1f} (fell)")
        out.append(f"| {r.law} | {r.kind} ({r.plant_preset}) | {r.parameter_set} | {verdict(m)} "
                   f"| {_fmt(m['settling_time_s'])} | {_fmt(m['overshoot_m'], 1e3)} "
                   f"| {_fmt(m['steady_state_error_m'], 1e3, 3)} | {angle} | {_fmt(m['peak_voltage_V'], 1, 1)} "
                   f"| {_fmt(m['rms_voltage_V'])} |" + (f" {THESIS_CLAIMS[(r.law, r.kind)]} |" if claims else ""))
    return "\n".join(out) + "\n"


def document() -> str:
    """Both tables as they appear in docs/controllers.md."""
    return (table(runs()) + "\nThe same runs (default sets) with the measurements rounded to whole encoder counts "
            "(cart 2.275e-5 m, pendulum 1.534e-3 rad per count):\n\n" + table(runs(quantize=True), claims=False))


def block(part: str) -> str:
    """The text of the block ``evidence:<part>`` (``devtools.docblocks``): ``controllers``, both tables."""
    if part != "controllers":
        raise KeyError(f"no evidence block {part!r} (the one block is {BLOCK})")
    return document()


_NUMBER = re.compile(r"-?\d+\.\d+")


def same_block(shown: str, computed: str) -> bool:
    """Whether the block ``shown`` in the docs is ``computed``: equal text, and numbers equal to the last
    digit shown (+-1): the figures after a fall (a chaotic trajectory) move in their last digit between
    numpy/scipy builds.

    The second table (measurements rounded to encoder counts) is compared on its rows' law,
    plant and parameter set only: sliding-mode laws chatter on quantized signals, and whether
    such a run is inside the band at 10 s changes with the last bit of a floating-point sum
    (docs/controllers.md says so beside the table)."""
    shown_ideal, _, shown_quantized = shown.strip().partition("rounded to whole encoder counts")
    computed_ideal, _, computed_quantized = computed.strip().partition("rounded to whole encoder counts")
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


def update(path: Path, text: str) -> bool:
    """Write ``text`` as the block of ``path``; True if the file changed."""
    from devtools.docblocks import write

    return write(path, BLOCK, text)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m evidence.controllers_table",
                                     description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--update", type=Path, help="rewrite the table block in this markdown file")
    args = parser.parse_args(argv)
    text = document()
    if args.update:
        changed = update(args.update, text)
        print(f"{args.update}: {'updated' if changed else 'unchanged'}")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
