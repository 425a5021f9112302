"""Step-response metrics of one closed-loop run, under the name earlier code imports them by.

The definitions belong to the plant kind: :mod:`ipcosim.fmus.task` ("the IP02 task and its
metrics"); this module re-exports them unchanged.
"""
from __future__ import annotations

from ipcosim.fmus.task import (
    METRIC_KEYS,
    RECOVERY_BAND_RAD,
    SETTLING_BAND,
    STEADY_STATE_FRACTION,
    UPRIGHT_LIMIT_RAD,
    MetricsError,
    compute_metrics,
    tap_metrics,
    upright_metrics,
    wrapped,
)

__all__ = ["METRIC_KEYS", "RECOVERY_BAND_RAD", "SETTLING_BAND", "STEADY_STATE_FRACTION", "UPRIGHT_LIMIT_RAD",
           "MetricsError", "compute_metrics", "tap_metrics", "upright_metrics", "wrapped"]
