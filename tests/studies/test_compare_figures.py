"""The comparison's figure of a plant draws every law its table lists, the LQG included."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from ipcosim.harness.studies import report  # noqa: E402


def _series(k: float) -> dict[str, list[float]]:
    t = np.linspace(0, 5, 201)
    return {"time": t.tolist(), "position": (0.05 * (1 - np.exp(-k * t))).tolist(),
            "reference": np.full_like(t, 0.05).tolist(), "angle": (0.02 * np.exp(-t) * np.sin(k * t)).tolist(),
            "voltage": (3 * np.exp(-k * t)).tolist()}


def _results() -> dict[str, dict]:
    laws = [*report.CONTROLLERS, "lqg"]
    results = {f"single-mass-{c}": {"status": "ok", "series": _series(1.0 + i)} for i, c in enumerate(laws)}
    results["double-mass-lqg"] = {"status": "ok", "series": _series(2.0)}
    results["single-mass-hsmc"] = {"status": "error", "error": "could not load Controller.fmu"}
    return results


def test_every_law_of_the_table_is_in_the_figure(tmp_path, monkeypatch) -> None:
    import matplotlib.pyplot as plt

    closed = []
    monkeypatch.setattr(plt, "close", closed.append)  # keep the figure plot_plant writes and closes
    results = _results()
    path = report.plot_plant("single-mass", results, tmp_path / "single-mass.png")
    assert path.read_bytes()[:4] == b"\x89PNG"
    fig, = closed
    _, rows = report._table(results, None)
    listed = [row[1] for row in rows if row[0] == "single mass"]
    assert len(listed) == 6 and "LQG" in listed, listed
    legend = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    for law in listed:
        assert any(entry == law or entry.startswith(f"{law} (") or entry.startswith(f"{law}:") for entry in legend), \
            (law, legend)
    assert "HSMC: no time series (error)" in legend, "the law that did not run is named, not silently dropped"
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    assert len(lines["LQG"].get_xdata()) == 201, "the LQG's cart position is drawn"
    drawn = [line.get_color() for label, line in lines.items() if label in listed]
    assert len(set(drawn)) == len(drawn), "each law its own colour"
    monkeypatch.undo()
    plt.close(fig)


def test_a_plant_with_only_an_lqg_gets_its_figure(tmp_path) -> None:
    path = report.plot_plant("double-mass", _results(), tmp_path / "double-mass.png")
    assert path is not None and path.read_bytes()[:4] == b"\x89PNG"
