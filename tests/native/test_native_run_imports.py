"""``ipcosim run <scenario> --fmus native`` loads no design code unless a design parameter changed:
the native FMUs carry the design's numbers for the values they were built with
(``design_values`` of ``native.json``, ``ipcosim.harness.native.redesign.unchanged``)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: Modules of the design stack (imported by a redesign only).
DESIGN = ("scipy.signal", "scipy.linalg", "control", "ipcosim.controllers.design")

PROBE = r"""
import json, sys
from ipcosim.harness.cli import main
rc = main(sys.argv[2:])
print(json.dumps({"rc": rc, "loaded": sorted(m for m in json.loads(sys.argv[1]) if m in sys.modules)}))
"""


def _run(native: Path, out: Path, *extra: str) -> dict:
    args = ["run", "single-mass-lqr", "--fmus", "native", "--fmu-dir", str(native), "--out", str(out), "--quiet",
            "--stop-time", "1", *extra]
    proc = subprocess.run([sys.executable, "-c", PROBE, json.dumps(DESIGN), *args], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["rc"] == 0, proc.stderr
    return got


def test_native_run_imports_no_design_stack(native_fmus, tmp_path):
    _, native = native_fmus
    assert _run(native, tmp_path / "out")["loaded"] == []


def test_a_changed_design_parameter_is_redesigned(native_fmus, tmp_path):
    """The positive control of the check above: a new sample period goes through the design."""
    _, native = native_fmus
    got = _run(native, tmp_path / "out", "--set", "controller.sample_period=0.002")
    assert "ipcosim.controllers.design" in got["loaded"]


def test_unchanged_design_runs_the_same_numbers(native_fmus, tmp_path):
    """The run that skips the redesign equals the one that redesigns (a design value set to itself
    through the parameter the redesign reads: the weights are the same, so the numbers are)."""
    from ipcosim.harness.native.redesign import native_info, redesign, unchanged

    _, native = native_fmus
    info = native_info(native / "LQRSingleMass.fmu")
    built = info["design_values"]
    assert unchanged(info, {"R": built["R"]}) and not unchanged(info, {"R": 2 * built["R"]})
    skipped = redesign(info, {"R": built["R"]})
    full = redesign({**info, "design_values": None}, {"R": built["R"]})  # forced through the design
    assert set(skipped) <= set(full)
    defaults = {v: float(x) for v, x in _defaults(native / "LQRSingleMass.fmu").items() if v in full}
    assert {k: full[k] for k in defaults} == pytest.approx(defaults, rel=0, abs=0)


def _defaults(fmu: Path) -> dict[str, str]:
    from fmpy import read_model_description

    return {v.name: v.start for v in read_model_description(str(fmu)).modelVariables
            if v.causality == "parameter" and v.start is not None}
