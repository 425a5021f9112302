"""Writes the clocked example scenarios (``examples/clocked/``) from the generated ones (``ssp/``), so that
they stay their copies: ``python -m devtools.clocked_examples`` (the files are committed; run it after
``python -m devtools.ssp_gen``; ``--check`` fails when a committed file differs).

* ``<plant>-lqr-clocked``: ``<plant>-lqr`` with the controller ``LQR<Plant>Clocked.fmu`` (the law sampled by
  its FMI 3.0 input clock, ``build/fmus-clocked``), the same parameter sets.
* ``single-mass-lqr-multirate``: ``single-mass-lqr-clocked`` with the setpoint ``SetpointClocked.fmu`` (a
  10 ms clock) ramping the cart at :data:`RAMP_RATE`: a 100 Hz reference task beside the 1 kHz law.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "examples" / "clocked"
RAMP_RATE = 0.05  # m/s
_MULTIRATE = ("IP02 single-mass cart, multi-rate: a reference task at 100 Hz (the setpoint ramps the cart 0 -&gt; "
              f"0.05 m at {RAMP_RATE:g} m/s, sampled by its 10 ms clock) feeds the LQR balance loop at 1 kHz (its "
              "1 ms clock)")
_INDENT = "\n" + " " * 18
_RAMP = (f'{_INDENT}<ssv:Parameter name="waveform"><ssv:Integer value="1"/></ssv:Parameter>'
         f'{_INDENT}<ssv:Parameter name="ramp_rate"><ssv:Real value="{RAMP_RATE}" unit="m/s"/></ssv:Parameter>')


def clocked(plant: str) -> dict[str, str]:
    """The files of ``<plant>-lqr-clocked`` (name -> text)."""
    from ipcosim.fmus import kinds

    name, suffix = f"{plant}-lqr", kinds.get(plant).suffix
    src = ROOT / "ssp" / name
    ssd = (src / "SystemStructure.ssd").read_text()
    ssd = ssd.replace(f"resources/LQR{suffix}.fmu", f"resources/LQR{suffix}Clocked.fmu")
    ssd = ssd.replace(f'name="{name}"', f'name="{name}-clocked"')
    ssd = ssd.replace("Luenberger observer;", "Luenberger observer, sampled by its FMI 3.0 input clock (1 kHz);")
    return {"SystemStructure.ssd": ssd, **{p.name: p.read_text() for p in sorted(src.glob("*.ssv"))}}


def multirate() -> dict[str, str]:
    """The files of ``single-mass-lqr-multirate``."""
    files = clocked("single-mass")
    ssd = files["SystemStructure.ssd"].replace("single-mass-lqr-clocked", "single-mass-lqr-multirate")
    ssd = ssd.replace("resources/Setpoint.fmu", "resources/SetpointClocked.fmu")
    ssd = re.sub(r'description="[^"]*"', f'description="{_MULTIRATE}"', ssd, count=1)
    step = '<ssv:Parameter name="step_time"><ssv:Real value="0.0" unit="s"/></ssv:Parameter>'
    if step not in ssd:
        raise ValueError("single-mass-lqr: the setpoint's step_time binding moved; update devtools.clocked_examples")
    return {**files, "SystemStructure.ssd": ssd.replace(step, step + _RAMP, 1)}


def examples() -> dict[str, dict[str, str]]:
    """Every clocked example: folder name -> its files."""
    return {"single-mass-lqr-clocked": clocked("single-mass"), "double-mass-lqr-clocked": clocked("double-mass"),
            "single-mass-lqr-multirate": multirate()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare with the committed files")
    args = parser.parse_args(argv)
    stale = []
    for folder, files in examples().items():
        for name, text in files.items():
            path = OUT / folder / name
            if path.is_file() and path.read_text() == text:
                continue
            stale.append(str(path.relative_to(ROOT)))
            if not args.check:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text)
    if stale:
        print(("differs: " if args.check else "written: ") + ", ".join(stale))
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
