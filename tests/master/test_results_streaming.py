"""Streamed results (``ipcosim.harness.master.results.RowWriter``) and the task metrics computed
from them a chunk at a time (``ipcosim.fmus.metrics``), which must equal those of the whole arrays."""
from __future__ import annotations

import numpy as np
import pytest

from ipcosim.fmus.metrics import compute_metrics, streamed_task_metrics, task_metrics
from ipcosim.harness.master.results import RowWriter

NAMES = ["time", "setpoint.reference", "plant.cart_position", "plant.pendulum_angle", "controller.voltage"]


def _run_like(n: int, seed: int, spike: bool = False, ref_steps: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    data = np.zeros(n, dtype=[(c, "f8") for c in NAMES])
    data["time"] = t
    ref = np.zeros(n)
    for k in range(ref_steps):
        ref[t >= (k + 1) * t[-1] / (ref_steps + 2)] = 0.05 * (k + 1) / ref_steps
    data["setpoint.reference"] = ref
    x = ref[-1] * (1 - np.exp(-t / max(t[-1] / 8, 1e-3))) + 1e-3 * rng.standard_normal(n)
    data["plant.cart_position"] = x
    data["plant.pendulum_angle"] = 0.05 * np.sin(7 * t) + 1e-3 * rng.standard_normal(n)
    data["controller.voltage"] = rng.standard_normal(n)
    if spike:
        data["controller.voltage"][n // 2] = np.nan
    return data


def _chunks(data: np.ndarray, size: int):
    return lambda: (data[i:i + size] for i in range(0, len(data), size))


@pytest.mark.parametrize("n, seed, spike, ref_steps", [(2, 0, False, 1), (1001, 1, False, 1), (5000, 2, False, 3),
                                                      (3000, 3, True, 1), (4000, 4, False, 0)])
@pytest.mark.parametrize("size", [1, 7, 256, 100000])
def test_streamed_metrics_equal_the_whole_array_ones(n, seed, spike, ref_steps, size):
    data = _run_like(n, seed, spike, ref_steps)
    whole = task_metrics(data)  # compute_metrics and upright_metrics on the whole arrays
    streamed = streamed_task_metrics(_chunks(data, size), NAMES)
    assert streamed.keys() == whole.keys()
    for key, value in whole.items():
        if value is None or isinstance(value, bool):
            assert streamed[key] == value, key
        else:
            assert streamed[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def test_settling_entry_on_a_chunk_boundary():
    data = _run_like(1000, 5)
    x = data["plant.cart_position"]
    x[:] = 0.05
    x[:400] = 0.0  # last sample outside the band: row 399, entry at row 400
    whole = compute_metrics(data["time"], x, data["setpoint.reference"], data["plant.pendulum_angle"],
                            data["controller.voltage"])
    for size in (100, 400, 399, 401):
        assert streamed_task_metrics(_chunks(data, size), NAMES)["settling_time_s"] == pytest.approx(
            whole["settling_time_s"])


def test_row_writer_spools_and_streams_csv(tmp_path):
    data = _run_like(3000, 6)
    w = RowWriter(NAMES, tmp_path / "results.csv", ["time", "controller.voltage"], in_memory_limit=1024)
    for i in range(0, len(data), 512):
        w.append(data[i:i + 512])
        lines = (tmp_path / "results.csv").read_text().splitlines()
        assert len(lines) == 1 + min(i + 512, len(data))  # on disk as soon as appended
    back = w.finish()
    assert isinstance(back, np.memmap) and np.array_equal(back, data)  # large: memory-mapped, not in memory
    csv = np.genfromtxt(tmp_path / "results.csv", delimiter=",", names=True, deletechars="")
    assert np.array_equal(csv["controller.voltage"], data["controller.voltage"])  # full precision


@pytest.mark.parametrize("size", [1, 2, 99, 100, 101, 250, 4096])
@pytest.mark.parametrize("ends_down", [False, True])
def test_streamed_tap_and_upright_metrics_on_chunk_boundaries(size, ends_down):
    """A pendulum at rest, tapped at row 100 (0.1 s), back inside the recovery band from row 300;
    a swing-up-like start (angle near pi) until row 50; optionally falling over at the end."""
    data = _run_like(1000, 7)
    t = data["time"]
    th = np.zeros(len(t))
    th[:50] = np.pi - 0.01 * np.arange(50)                # wrapped: far from upright
    th[50:100] = 0.0
    th[100:300] = 0.2 * np.exp(-(t[100:300] - t[100]) * 10)  # the tap, decaying
    th[300:] = 0.001
    if ends_down:
        th[-1] = 1.0
    data["plant.pendulum_angle"] = th
    whole = task_metrics(data, tasks={"tap", "swing-up"})
    # the angle first leaves its initial value at row 1: the "tap" of this run starts there
    assert whole["recovery_time_s"] == (None if ends_down else pytest.approx(t[300] - t[1]))
    assert whole["time_to_upright_s"] == (None if ends_down else pytest.approx(t[50]))
    streamed = streamed_task_metrics(_chunks(data, size), NAMES, tasks={"tap", "swing-up"})
    for key in ("time_to_upright_s", "track_used_m", "peak_angle_after_tap_rad", "recovery_time_s"):
        assert streamed[key] == (pytest.approx(whole[key]) if whole[key] is not None else None), key
