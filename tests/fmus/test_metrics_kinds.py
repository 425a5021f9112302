"""Metrics a control engineer can read: a task's metrics only in the runs that do it, no settling for a
fallen pendulum, and every metric a run writes defined in docs/metrics.md."""
from __future__ import annotations

import numpy as np
import pytest
from metrics_doc import documented_metrics

import ipcosim
from ipcosim.fmus.metrics import TASK_METRICS, compute_metrics, tasks_of


def test_tasks_come_from_the_plant_start_values() -> None:
    assert tasks_of({}.get) == frozenset()
    assert tasks_of({"tap_torque_impulse": 0.005}.get) == {"tap"}
    assert tasks_of({"tap_force_impulse": -0.1, "initial_pendulum_angle": np.pi}.get) == {"tap", "swing-up"}
    assert tasks_of({"initial_pendulum_angle": 2 * np.pi + 0.01}.get) == frozenset()  # wrapped: upright


def test_a_fallen_pendulum_has_not_settled() -> None:
    """The cart sits at the reference from 0.2 s, but the pendulum fell at 1 s."""
    t = np.linspace(0, 3, 301)
    x = np.where(t < 0.2, 0.0, 0.05)
    angle = np.where(t < 1.0, 0.0, 1.2)
    m = compute_metrics(t, x, np.full_like(t, 0.05), angle, np.zeros_like(t))
    assert m["upright"] is False and m["settling_time_s"] is None
    upright = compute_metrics(t, x, np.full_like(t, 0.05), np.zeros_like(t), np.zeros_like(t))
    assert upright["settling_time_s"] == pytest.approx(0.2)


@pytest.mark.integration
@pytest.mark.parametrize("scenario,tasks", [("single-mass-lqr", ()), ("single-mass-lqr-tap", ("tap",)),
                                            ("single-mass-swing-up", ("swing-up",))])
def test_task_metrics_only_in_their_scenarios_and_all_documented(scenario: str, tasks: tuple[str, ...]) -> None:
    m = ipcosim.run(scenario, stop_time=2.5).metrics
    for task, keys in TASK_METRICS.items():
        assert all((key in m) == (task in tasks) for key in keys), (task, sorted(m))
    assert set(m) <= documented_metrics(), set(m) - documented_metrics()


@pytest.mark.integration
def test_a_set_tap_makes_any_run_a_tap_run() -> None:
    tapped = ipcosim.run("single-mass-lqr", stop_time=1.0, set={"plant.tap_torque_impulse": 0.002,
                                                                 "plant.tap_time": 0.5}).metrics
    assert "recovery_time_s" in tapped and "time_to_upright_s" not in tapped
