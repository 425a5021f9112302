"""Studies reuse each component's FMU instance between runs through fmi2Reset: the same results as
fresh instances, and an instance whose run failed is never reused."""
from __future__ import annotations

import numpy as np
import pytest

from ipcosim.harness.api.engine import Prepared

pytestmark = pytest.mark.integration


def test_a_reset_instance_runs_as_a_fresh_one() -> None:
    with Prepared("single-mass-lqr", warn=False) as fresh:
        reference = fresh.run(stop_time=0.5)
    with Prepared("single-mass-lqr", warn=False, reuse_instances=True) as p:
        changed = p.run(stop_time=0.5, set={"plant.Mp": 0.3, "controller.sample_period": 0.002})
        kept = dict(p._kept)
        assert {s.state for s in kept.values()} == {"parked"}
        again = p.run(stop_time=0.5)
        assert all(p._kept[name] is slave for name, slave in kept.items()), "the instances were reset, not new"
    assert not np.array_equal(changed["plant.pendulum_angle"], reference["plant.pendulum_angle"])
    for column in ("plant.cart_position", "plant.pendulum_angle", "controller.voltage"):
        assert np.array_equal(again[column], reference[column]), column
    assert {s.state for s in kept.values()} == {"freed"}, "close frees the kept instances"


def test_an_instance_whose_run_failed_is_not_reused() -> None:
    with Prepared("single-mass-lqr", warn=False, reuse_instances=True) as p:
        failed = p.run(stop_time=0.2, set={"plant.Mp": -1.0}, raise_on_error=False)
        assert failed.error is not None
        before = dict(p._kept)
        ok = p.run(stop_time=0.2)
        assert ok.ok and p._kept["plant"] is not before["plant"]
