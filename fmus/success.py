"""The success criterion of a run of the task: what a lab signs as a success (``docs/metrics.md``).

A run succeeds when the pendulum stayed upright, the motor cart's mean error over the final window is within
:data:`MEAN_ERROR_LIMIT_M` and its residual peak-to-peak within the run's own amplitude bound, computed before
the run (:data:`BOUND_KEYS`): the residual cycle predicted for its plant and law plus :data:`AMPLITUDE_MARGIN_M`
(:func:`predicted_amplitude_bound`), or, where the prediction cannot treat the run, the friction bound
(:func:`amplitude_bound`). The metrics it reads are :mod:`ipcosim.fmus.metrics`'.
"""
from __future__ import annotations

from typing import Any, Mapping

#: |mean error| of the motor cart over the final window that a successful run stays within [m] (the +-2 %
#: band of the thesis's 50 mm step).
MEAN_ERROR_LIMIT_M = 1e-3
#: The residual peak-to-peak a successful run's motor cart may swing beyond what the plant forces [m]: the
#: width of the +-1 mm band, so a loop with no forced cycle may hunt within the band and no further.
AMPLITUDE_TOLERANCE_M = 2 * MEAN_ERROR_LIMIT_M
#: What a successful run's motor cart may swing beyond the residual cycle predicted for its own plant and law
#: (``ipcosim.harness.analysis.residual_cycle.run_bound``) [m]: half the +-1 mm band, for what the prediction leaves
#: out (the describing functions' harmonics, the DAC's codes, a count level the signal is not centred on).
AMPLITUDE_MARGIN_M = 1e-3
#: The plant parameters that drive a residual cycle (``ipcosim.harness.analysis.residual_cycle``): each cart's
#: Coulomb friction and each encoder's resolution. With all of them zero the loop is linear: no cycle.
CYCLE_SOURCES = ("b", "b1", "b2", "cart_resolution", "pendulum_resolution")
#: A run's amplitude bound as its metrics.json records it (``ipcosim.harness.api.engine``, before the run): the
#: bound [m], where it comes from (``prediction``, or ``friction bound: <why the prediction could not treat the
#: run>``) and the predicted motor-cart peak-to-peak [m] (None on the fallback).
BOUND_KEYS = ("amplitude_bound_m", "amplitude_bound_from", "predicted_cart_peak_to_peak_m")
#: Outcomes of :func:`success_status`; ``ok`` is a success.
SUCCESS_STATUSES = ("ok", "fell", "unsettled", "hunting")


def amplitude_bound(b2: float = 0.0, K: float = 0.0) -> float:
    """The motor cart's residual peak-to-peak a lab signs as a success [m]: ``AMPLITUDE_TOLERANCE_M`` plus the
    cycle the plant forces on any law, ``2 b2 / K`` where a spring ``K`` [N/m] couples a passive cart with
    Coulomb friction ``b2`` [N] (to reverse that cart the spring swings through twice its friction force,
    moving the motor cart by ``2 b2 / K``); no forced cycle without them (the single mass, the ideal plant)."""
    return AMPLITUDE_TOLERANCE_M + (2.0 * b2 / K if b2 > 0.0 and K > 0.0 else 0.0)


def predicted_amplitude_bound(predicted_peak_to_peak: float) -> float:
    """The amplitude bound of a run whose residual cycle was predicted [m]: the predicted motor-cart peak-to-peak
    plus :data:`AMPLITUDE_MARGIN_M`."""
    return float(predicted_peak_to_peak) + AMPLITUDE_MARGIN_M


def success_status(metrics: Mapping[str, Any], bound: float | None = None) -> str:
    """The one success criterion of a run of the task (sweeps, robustness tables, pytest helpers).

    ``fell`` unless the pendulum stayed upright; ``unsettled`` when ``|cart_mean_error_m|`` over the final
    window exceeds ``MEAN_ERROR_LIMIT_M``; ``hunting`` when the motor cart's ``cart_peak_to_peak_m`` exceeds
    ``bound`` (default: the run's own, ``metrics["amplitude_bound_m"]``, computed before it ran; without one,
    :func:`amplitude_bound` of a plant with no forced cycle); else ``ok``.

    Examples
    --------
    >>> m = {"upright": True, "cart_mean_error_m": 3e-4, "cart_peak_to_peak_m": 3.0e-3}
    >>> success_status(m, amplitude_bound(b2=0.1047, K=142.185)), success_status(m)
    ('ok', 'hunting')
    """
    if bound is None:
        bound = metrics.get("amplitude_bound_m") or amplitude_bound()
    if metrics.get("upright") is not True:
        return "fell"
    mean, p2p = metrics.get("cart_mean_error_m"), metrics.get("cart_peak_to_peak_m")
    if mean is None or not abs(float(mean)) <= MEAN_ERROR_LIMIT_M:
        return "unsettled"
    if p2p is None or not float(p2p) <= bound:
        return "hunting"
    return "ok"
