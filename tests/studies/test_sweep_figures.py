"""A sweep's histograms are readable in the PNG: tick labels apart, written in full."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from ipcosim.harness.studies.robustness import histogram, plot_distributions, tick_labels_overlap  # noqa: E402


def _boxes(fig, axis):  # noqa: ANN001, ANN202
    """Extents of the labels drawn: those of the ticks inside the axis's view."""
    renderer = fig.canvas.get_renderer()
    lo, hi = sorted(axis.get_view_interval())
    return [t.label1.get_window_extent(renderer) for t in axis.get_major_ticks()
            if lo <= t.get_loc() <= hi and t.label1.get_text()]


def test_the_overlap_check_sees_labels_that_touch() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2.0, 2.0))
    ax.set_xticks(np.arange(10), [f"{1e6 + i:.1f}" for i in range(10)])  # ten 9-character labels in 2 inches
    assert tick_labels_overlap(fig, ax.xaxis)
    ax.set_xticks([0, 9], ["0", "9"])
    assert not tick_labels_overlap(fig, ax.xaxis)
    plt.close(fig)


@pytest.mark.parametrize("values", [
    np.linspace(1234567.01, 1234567.99, 60),  # long labels: the default six would run into each other
    np.linspace(1.000123, 1.000987, 40),  # a narrow range matplotlib would write as 0.0002 .. and "+1"
    np.geomspace(1e-4, 12.0, 50),
])
def test_histogram_tick_labels_do_not_overlap_in_the_png(tmp_path, values) -> None:  # noqa: ANN001
    import matplotlib.pyplot as plt

    fig = histogram(values[:-3], values[-3:], "settling_time_s", "sweep of plant.Mp")
    fig.savefig(tmp_path / "h.png")
    axis = fig.axes[0].xaxis
    boxes = sorted(_boxes(fig, axis), key=lambda b: b.x0)
    assert len(boxes) >= 2, "the axis keeps at least two numbers"
    for a, b in zip(boxes, boxes[1:]):
        assert not (a.x1 > b.x0 and a.y1 > b.y0 and b.y1 > a.y0), (a, b)
    assert axis.get_offset_text().get_text() == "", "no offset to add in the reader's head"
    lo, hi = fig.axes[0].get_xlim()
    shown = [float(t.label1.get_text().replace("\u2212", "-")) for t in axis.get_major_ticks()
             if lo <= t.get_loc() <= hi]
    for b in boxes:
        assert b.x0 >= 0 and b.x1 <= fig.bbox.width, "every label inside the PNG"
    assert any(abs(v - values.min()) < 0.5 * np.ptp(values) for v in shown), "labels are the values, not offsets"
    plt.close(fig)


def test_plot_distributions_writes_one_png_per_metric(tmp_path) -> None:
    rows = [{"status": "ok", "a": float(x), "b": 2.0} for x in np.linspace(1.0, 2.0, 20)]
    rows.append({"status": "fell", "a": 5.0, "b": 2.0})
    paths = plot_distributions(rows, ["a", "b"], tmp_path)
    assert [p.name for p in paths] == ["a.png", "b.png"]
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in paths)


def test_a_far_outlier_is_counted_not_allowed_to_squash_the_rest(tmp_path) -> None:
    import matplotlib.pyplot as plt

    good = np.linspace(1.0, 10.0, 300)  # settling times of 300 runs, 1 .. 10 s
    fig = histogram(good, np.array([123456.7]), "settling_time_s")
    fig.savefig(tmp_path / "h.png")
    ax = fig.axes[0]
    assert ax.get_xlim()[1] < 20.0, "the axis spans the 300 runs, not the one far out"
    heights = [p.get_height() for p in ax.patches]
    assert sum(heights) == pytest.approx(300), "every run on the axis is in a bar"
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["success (300)", "failure (1)", "1 run(s) off the axis: 1.235e+05"], legend
    plt.close(fig)
