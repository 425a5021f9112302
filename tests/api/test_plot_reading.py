"""The run figure shows what its metrics are judged against: reference, settling band, voltage limits,
every axis in the unit it shows."""
from __future__ import annotations

import numpy as np
import pytest

from ipcosim.harness.api.plot import figure
from ipcosim.harness.master.results import Result

pytest.importorskip("matplotlib")


def _run() -> Result:
    t = np.linspace(0.0, 5.0, 501)
    names = ["time", "setpoint.reference", "plant.cart_position", "plant.pendulum_angle", "controller.voltage"]
    data = np.zeros(t.size, dtype=[(n, "f8") for n in names])
    data["time"], data["setpoint.reference"] = t, 0.05
    data["plant.cart_position"] = 0.05 * (1 - np.exp(-2 * t))
    data["plant.pendulum_angle"] = 0.01 * np.exp(-t) * np.sin(5 * t)
    data["controller.voltage"] = 0.4 * np.exp(-t)
    return Result(data=data, metrics={"settling_time_s": 1.96}, metadata={"voltage_limit_V": 10.0})


def test_figure_draws_band_limits_reference_and_units() -> None:
    fig = figure(_run(), backend="Agg")
    position, angle, voltage = fig.axes[:3]
    assert [ax.get_ylabel() for ax in (position, angle, voltage)] == ["position [m]", "pendulum angle [rad]",
                                                                    "voltage [V]"]
    assert fig.axes[2].get_xlabel() == "time [s]"
    labels = position.get_legend_handles_labels()[1]
    assert labels[0] == "reference" and "settling band +-2 %" in labels and "settled after 1.96 s" in labels
    fig.canvas.draw()
    band = position.patches[0].get_path().get_extents(position.patches[0].get_patch_transform()
                                                      + position.patches[0].get_data_transform()
                                                      + position.transData.inverted())
    assert band.y0 == pytest.approx(0.049) and band.y1 == pytest.approx(0.051)  # 0.05 +- 2 % of the step
    assert voltage.get_ylim()[0] < -10 and voltage.get_ylim()[1] > 10, "the +-10 V limits are in view"
    assert "+-10 V limit" in voltage.get_legend_handles_labels()[1]
    right = [ax for ax in angle.child_axes if ax.get_ylabel() == "pendulum angle [deg]"]
    assert len(right) == 1, "the angle's degrees are on a labelled second axis"
