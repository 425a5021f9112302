"""The run figure's title says what was run: scenario, parameter set, every --set value, and
marks a hardware-in-the-loop plant or a real-time run over its overrun budget."""
from __future__ import annotations

import numpy as np
import pytest

from ipcosim.harness.api.plot import figure
from ipcosim.harness.master.results import Result

pytest.importorskip("matplotlib")


def _result(metadata: dict, metrics: dict | None = None) -> Result:
    t = np.linspace(0.0, 2.0, 201)
    names = ["time", "plant.cart_position", "plant.pendulum_angle", "controller.voltage"]
    data = np.zeros(t.size, dtype=[(n, "f8") for n in names])
    data["time"], data["plant.cart_position"] = t, 0.01 * t
    return Result(data=data, metrics=metrics or {}, metadata=metadata)


def _render(result: Result, tmp_path):  # noqa: ANN001, ANN202
    """Render the PNG as `ipcosim run --plot` does; the title's text, its extent and the width [px]."""
    import matplotlib.pyplot as plt

    fig = figure(result, backend="Agg")
    fig.savefig(tmp_path / "plot.png", dpi=110)
    assert (tmp_path / "plot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    extent = fig._suptitle.get_window_extent(fig.canvas.get_renderer())
    text, width = fig._suptitle.get_text(), fig.bbox.width
    plt.close(fig)
    return text, extent, width


def test_title_names_scenario_parameter_set_and_every_set(tmp_path) -> None:
    sets = {f"controller.k{i}": 1.5 + i for i in range(8)} | {"plant.Mp": 0.2, "controller.sample_period": 0.002}
    text, extent, width = _render(_result({"scenario": "pendulum_step", "parameter_set": "thesis",
                                           "set": sets}), tmp_path)
    assert text.splitlines()[0] == "pendulum_step (thesis)"
    flat = " ".join(text.split())
    for name, value in sets.items():
        assert f"{name}={value}" in flat, name
    assert len(text.splitlines()) >= 3, "ten settings do not fit one line: the title is wrapped"
    assert extent.x0 >= 0 and extent.x1 <= width, "the wrapped title stays inside the PNG"


def test_hil_swap_and_degraded_realtime_are_marked(tmp_path) -> None:
    metrics = {"overrun_budget_exceeded": True, "overrun_fraction": 0.05, "overrun_budget": 0.01}
    text, _, _ = _render(_result({"scenario": "pendulum_step", "swaps": {"plant": "hil"}}, metrics), tmp_path)
    assert "[HIL: plant=hil]" in text
    assert "[DEGRADED real time: 5.00 % late steps > budget 1.00 %]" in text


def test_an_ordinary_run_has_no_marks(tmp_path) -> None:
    metrics = {"overrun_budget_exceeded": False, "overrun_fraction": 0.0, "overrun_budget": 0.01}
    text, _, _ = _render(_result({"scenario": "pendulum_step", "swaps": {}}, metrics), tmp_path)
    assert text == "pendulum_step" and "[" not in text


def test_other_swap_is_named_not_called_hil(tmp_path) -> None:
    text, _, _ = _render(_result({"scenario": "s", "swaps": {"controller": "my/Lqr.fmu"}}), tmp_path)
    assert "[swapped: controller=my/Lqr.fmu]" in text and "HIL" not in text


def test_a_run_s_set_values_reach_its_figure(tmp_path) -> None:
    import ipcosim

    result = ipcosim.run("single-mass-lqr", stop_time=0.01, parameter_set="thesis",
                         set={"plant.Mp": 0.2, "controller.sample_period": 0.002})
    text, _, _ = _render(result, tmp_path)
    assert text.splitlines()[0] == "single-mass-lqr (thesis)"
    assert "plant.Mp=0.2" in text and "controller.sample_period=0.002" in text
