"""The Bode figure of `ipcosim analyze` shows the -180 deg line and its margins where they are,
checked on the rendered PNG against a loop whose margins are known by hand."""
from __future__ import annotations

import math

import control
import numpy as np
import pytest

pytest.importorskip("matplotlib")

from ipcosim.harness.analysis.analyze import analyze_loop, frequency_grid, loop_from, loop_response  # noqa: E402
from ipcosim.harness.analysis.analyze_plots import _plot_bode  # noqa: E402
from ipcosim.harness.analysis.linear_law import LinearLaw  # noqa: E402

K, T = 50.0, 0.01


def _figure(tmp_path):  # noqa: ANN001, ANN202
    """Integrator plant 1/s under u = -K y sampled at T: L(z) = K T / (z - 1). |L| = 1 where
    2 sin(w T/2) = K T, the phase there -(90 + w T/2 [deg]); the phase reaches -180 deg at the
    Nyquist frequency pi/T, where |L| = K T/2: gain margin 2/(K T)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    law = LinearLaw(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[-K]]), T, ("y",), ())
    loop = loop_from(control.ss([[0.0]], [[1.0]], [[1.0]], [[0.0]]), law)
    w = frequency_grid(T, 3000)
    fig = _plot_bode(plt, w, loop_response(loop, w), "integrator under P", analyze_loop(loop))
    fig.savefig(tmp_path / "bode.png", dpi=110)
    assert (tmp_path / "bode.png").read_bytes()[:4] == b"\x89PNG"
    return fig


def _bars(ax, color: str) -> list[tuple[float, float, float]]:  # noqa: ANN001
    """Vertical two-point lines of ``color``: (x, y from, y to)."""
    import matplotlib.colors as mc

    out = []
    for line in ax.get_lines():
        x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
        if x.size == 2 and x[0] == x[1] and mc.same_color(line.get_color(), color):
            out.append((float(x[0]), float(y[0]), float(y[1])))
    return out


def test_phase_panel_has_the_minus_180_line(tmp_path) -> None:
    mag_ax, phase_ax = _figure(tmp_path).axes
    flat = [line for line in phase_ax.get_lines() if np.all(np.asarray(line.get_ydata(), float) == -180.0)]
    assert flat, "a horizontal line at -180 deg"
    lo, hi = phase_ax.get_ylim()
    assert lo < -180.0 < hi, "and it is in view"


def test_phase_margin_drawn_at_the_gain_crossover(tmp_path) -> None:
    fig = _figure(tmp_path)
    wc = 2 / T * math.asin(K * T / 2)
    pm = 90.0 - math.degrees(wc * T / 2)
    (x, y0, y1), = _bars(fig.axes[1], "tab:purple")
    assert x == pytest.approx(wc, rel=1e-6)
    assert y0 == pytest.approx(-180.0, abs=0.5) and y1 - y0 == pytest.approx(pm, rel=1e-6)
    texts = [t.get_text() for t in fig.axes[1].texts]
    assert any(t.startswith(f"PM {pm:.3g} deg") and f"{wc:.3g} rad/s" in t for t in texts), texts


def test_gain_margin_drawn_at_the_phase_crossover(tmp_path) -> None:
    fig = _figure(tmp_path)
    gm_db = 20 * math.log10(2 / (K * T))
    (x, y0, y1), = _bars(fig.axes[0], "tab:brown")
    assert x == pytest.approx(math.pi / T, rel=1e-6)
    assert y0 == pytest.approx(-gm_db, abs=0.05) and y1 == 0.0, "from |L| up to 0 dB"
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert any(t.startswith(f"GM {gm_db:+.3g} dB") for t in texts), texts


def test_margin_labels_are_inside_the_png(tmp_path) -> None:
    fig = _figure(tmp_path)
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for ax in fig.axes for t in ax.texts]
    assert len(boxes) == 2
    for b in boxes:
        assert b.x0 >= 0 and b.y0 >= 0 and b.x1 <= fig.bbox.width and b.y1 <= fig.bbox.height, b
