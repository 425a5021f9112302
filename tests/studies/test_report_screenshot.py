"""The comparison report as a person sees it: a fallen run shows no settling time and its traces end at
the fall, so its +-10 V chatter after the fall no longer paints over the other laws (a headless-browser
screenshot of report.html)."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ipcosim.harness.studies import report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FALL = 0.4


def _series(fallen: bool) -> dict[str, list[float]]:
    t = np.linspace(0, 5, 2001)
    if fallen:  # upright until 0.4 s, then down, with the saturated controller chattering at +-10 V
        angle = np.where(t < FALL, 0.02 * t, 0.35 + 2.0 * (t - FALL))
        volt = np.where(t < FALL, 4.0 * t, 10.0 * np.sign(np.sin(400 * t)))
        x = np.full_like(t, 0.05)
    else:
        angle, volt, x = 0.05 * np.exp(-t) * np.sin(8 * t), 3 * np.exp(-t), 0.05 * (1 - np.exp(-2 * t))
    return {"time": t.tolist(), "position": x.tolist(), "reference": np.full_like(t, 0.05).tolist(),
            "angle": angle.tolist(), "voltage": volt.tolist()}


def _results(fall_time: float | None) -> dict[str, dict]:
    ok = {"status": "ok", "settling_time_s": 2.0, "upright": True, "fall_time_s": None, "peak_voltage_V": 3.0}
    return {"single-mass-pid": {"status": "fell", "settling_time_s": None, "upright": False, "fall_time_s": fall_time,
                                "peak_voltage_V": 10.0, "series": _series(True)},
            **{f"single-mass-{c}": {**ok, "series": _series(False)} for c in ("lqr", "hsmc", "adaptive-hsmc")}}


def test_a_fallen_run_is_not_settled_in_the_table(tmp_path: Path) -> None:
    md = report.render(_results(FALL), tmp_path)["markdown"].read_text()
    pid = next(line for line in md.splitlines() if line.startswith("| single mass | PID |"))
    assert "| fell | not settled |" in pid


def test_fallen_traces_end_at_the_fall() -> None:
    s = report.until(_series(True), FALL)
    assert max(s["time"]) <= FALL and len(s["time"]) == sum(t <= FALL for t in _series(True)["time"])
    assert report.until(_series(True), None) == _series(True)


def _grey_share(html: Path, shot: Path) -> float:
    """Share of the screenshot's pixels in the fallen PID's colour (matplotlib tab:gray, #7f7f7f)."""
    import matplotlib.image

    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                          f"--screenshot={shot}", "--window-size=1100,2600", html.as_uri()],
                         capture_output=True, text=True, timeout=120)
    assert shot.is_file(), run.stderr[-2000:]
    pixels = matplotlib.image.imread(shot)[..., :3]
    grey = np.all(np.abs(pixels - 0x7F / 255) < 0.04, axis=-1)
    return float(grey.mean())


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt install chromium): no screenshot")
def test_screenshot_shows_the_fallen_run_ending_at_the_fall(tmp_path: Path) -> None:
    fixed = _grey_share(report.render(_results(FALL), tmp_path / "fixed")["html"], tmp_path / "fixed.png")
    whole = _grey_share(report.render(_results(None), tmp_path / "whole")["html"], tmp_path / "whole.png")
    assert whole > 0.01, f"the check sees a grey block where the chatter is drawn to the end ({whole:.4f})"
    assert fixed < 0.2 * whole, (fixed, whole)
