"""Plot axes that a single spike cannot squash (``ipcosim.harness.api.plot``)."""
from __future__ import annotations

import numpy as np

from ipcosim.harness.api.plot import axis_limits, plot_result
from ipcosim.harness.master.results import Result


def test_a_single_spike_does_not_set_the_axis():
    t = np.linspace(0.0, 10.0, 10001)
    v = np.sin(t)
    v[5000] = -10.0
    lo, hi = axis_limits([v])
    assert -1.3 < lo < -0.9 and 0.9 < hi < 1.3


def test_an_ordinary_signal_keeps_its_full_range():
    t = np.linspace(0.0, 10.0, 1001)
    v = np.where(t < 5.0, 0.0, 6.0)  # a step is not a spike
    lo, hi = axis_limits([v])
    assert lo < 0.0 and hi > 6.0
    assert axis_limits([np.array([np.nan, np.inf])]) is None
    assert axis_limits([np.full(10, 3.0)]) == (3.0 - 0.24, 3.0 + 0.24)


def test_plot_marks_the_spike(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 1.0, 1001)
    data = np.zeros(t.size, dtype=[("time", "f8"), ("controller.voltage", "f8")])
    data["time"] = t
    data["controller.voltage"] = 0.5 * np.sin(6 * t)
    data["controller.voltage"][300] = -10.0
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig: figures.append(fig))
    path = plot_result(Result(data=data), tmp_path / "plot.png")
    assert path.stat().st_size > 0
    ax = figures[0].axes[0]
    assert ax.get_ylim()[0] > -1.0  # the -10 V spike does not set the axis
    texts = [a.get_text() for a in ax.texts]
    assert texts == ["1 sample(s) beyond the axis (range -10 .. 0.5)"]
    markers = [line for line in ax.lines if line.get_marker() == "v"]
    assert len(markers) == 1 and list(markers[0].get_xdata()) == [t[300]]
