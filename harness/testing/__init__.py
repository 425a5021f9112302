"""Checks of a run that read like a control engineer's test report, and small case lists.

Each ``assert_*`` takes a :class:`~ipcosim.harness.master.results.Result` (``ipcosim.run`` or
the pytest plugin's ``cosim.run``) and raises :class:`CheckFailed` (an ``AssertionError``)
whose message starts with the run (scenario, swaps, settings) and says in physical units what
was expected and what happened, e.g.::

    single-mass-lqr [controller=MyControllerSingleMass.fmu]: the pendulum fell: |angle| reached
    0.35 rad (20.1 deg) at t = 0.412 s (limit 0.35 rad)

They are re-exported at the top: ``ipcosim.assert_upright`` and so on.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ipcosim.errors import IpcosimError, UsageError
from ipcosim.fmus import metrics
from ipcosim.fmus.metrics import ANGLE_COLUMNS, POSITION_COLUMNS, REFERENCE_COLUMNS, UPRIGHT_LIMIT_RAD, first_column
from ipcosim.fmus.params import KINDS

if TYPE_CHECKING:  # pragma: no cover
    from ipcosim.harness.master.results import Result


class CheckFailed(IpcosimError, AssertionError):
    """A run that does not meet a check (the message says how, in physical units)."""


def run_label(result: "Result") -> str:
    """``scenario [swaps, set values]``: which run a message is about."""
    meta = result.metadata
    items = [f"{k}={Path(str(v)).name}" for k, v in (meta.get("swaps") or {}).items()]
    items += [f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in _set_values(meta).items()]
    return f"{meta.get('scenario', 'run')}" + (f" [{', '.join(items)}]" if items else "")


def _set_values(meta: Mapping[str, Any]) -> dict[str, Any]:
    # the run's ``set``, stored under the metadata key "overrides" (a file format others read)
    raw = meta.get("overrides") or {}
    if isinstance(raw, Mapping):
        return {(".".join(k) if isinstance(k, tuple) else str(k)): v for k, v in raw.items()}
    return {}


def _column(result: "Result", candidates: Sequence[str], what: str) -> np.ndarray:
    __tracebackhide__ = True  # pytest shows the test's line, not this helper's
    name = first_column(result.columns, candidates)
    if name is None:
        raise CheckFailed(f"{run_label(result)}: no {what} recorded (looked for {', '.join(candidates)})")
    return np.asarray(result[name], dtype=float)


def _fail(result: "Result", text: str) -> None:
    __tracebackhide__ = True
    where = (result.metadata.get("files") or {}).get("results")
    raise CheckFailed(f"{run_label(result)}: {text}" + (f"\n  results: {where}" if where else ""))


def assert_upright(result: "Result", limit_rad: float = UPRIGHT_LIMIT_RAD) -> None:
    """Check that the pendulum stayed up: ``|angle| < limit_rad`` at every recorded point.

    Examples
    --------
    >>> import ipcosim
    >>> ipcosim.assert_upright(ipcosim.run("single-mass-lqr", stop_time=0.5))
    >>> ipcosim.assert_upright(ipcosim.run("single-mass-lqr", stop_time=0.5), limit_rad=1e-6)
    Traceback (most recent call last):
    ...
    ipcosim.harness.testing.CheckFailed: single-mass-lqr: the pendulum left +-1e-06 rad: ...
    """
    __tracebackhide__ = True
    t, angle = np.asarray(result["time"], float), _column(result, ANGLE_COLUMNS, "pendulum angle")
    bad = ~(np.abs(angle) < limit_rad)
    if result.error:
        _fail(result, f"the run failed at t = {t[-1]:.3f} s: {result.error}")
    if bad.any():
        k = int(np.argmax(bad))
        peak = float(np.nanmax(np.abs(angle))) if np.isfinite(angle).any() else float("nan")
        _fail(result, f"the pendulum left +-{limit_rad:g} rad: |angle| = {abs(angle[k]):.3g} rad "
                      f"({np.degrees(abs(angle[k])):.1f} deg) at t = {t[k]:.3f} s, peak {peak:.3g} rad")


def _step_target(result: "Result") -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    __tracebackhide__ = True
    t = np.asarray(result["time"], float)
    x = _column(result, POSITION_COLUMNS, "cart position")
    r = _column(result, REFERENCE_COLUMNS, "reference")
    return t, x, r, float(r[-1])


def settling_time(result: "Result", band: float = metrics.SETTLING_BAND) -> float | None:
    """Time [s] from the last change of the reference to the cart's last entry into
    ``reference +- band * |step|`` (None: outside the band at the end, or no step):
    :func:`ipcosim.fmus.metrics.settling_time` on the run's columns."""
    t, x, r, _ = _step_target(result)
    return metrics.settling_time(t, x, r, band)


def assert_settles(result: "Result", within_s: float, band: float = metrics.SETTLING_BAND) -> None:
    """Check that the cart settles into ``reference +- band * |step|`` within ``within_s`` seconds
    of the reference step, and stays there to the end of the run.

    Examples
    --------
    >>> import ipcosim
    >>> ipcosim.assert_settles(ipcosim.run("single-mass-lqr", stop_time=6.0), within_s=5.0)
    """
    __tracebackhide__ = True
    if result.error:
        _fail(result, f"the run failed: {result.error}")
    t, x, r, r_final = _step_target(result)
    half = band * abs(r_final - x[0])
    ts = settling_time(result, band)
    where = f"the +-{band * 100:g} % band ({r_final - half:.4g}..{r_final + half:.4g} m)"
    if ts is None:
        _fail(result, f"the cart did not settle within {within_s:g} s: it is outside {where} at the end of "
                      f"the run (x = {x[-1]:.4g} m at t = {t[-1]:.3f} s, target {r_final:.4g} m)")
    elif ts > within_s:
        _fail(result, f"the cart settled after {ts:.3f} s, not within {within_s:g} s (last entry into {where})")


def assert_succeeds(result: "Result") -> None:
    """Check the run meets the task's success criterion (:func:`ipcosim.fmus.metrics.success_status`, the one
    the sweeps and robustness tables count): upright, ``|mean error|`` of the motor cart over the final window
    at most 1 mm, and its residual peak-to-peak within the run's bound (the cycle predicted for its plant and law
    plus 1 mm, else 2 mm plus ``2 b2 / K``; ``docs/metrics.md``).

    Examples
    --------
    >>> import ipcosim
    >>> ipcosim.assert_succeeds(ipcosim.run("single-mass-lqr", stop_time=6.0))
    """
    __tracebackhide__ = True
    if result.error:
        _fail(result, f"the run failed: {result.error}")
    m = result.metrics
    bound = float(result.metadata.get("amplitude_bound_m") or metrics.amplitude_bound())
    status = metrics.success_status(m, bound)
    if status == "fell":
        _fail(result, f"the pendulum fell (|angle| reached {m.get('max_abs_angle_rad') or float('nan'):.3g} rad)")
    window = f"over the final {m.get('residual_window_s') or 0:g} s"
    if status == "unsettled":
        _fail(result, f"mean error {1e3 * float(m['cart_mean_error_m'] or float('nan')):.3g} mm {window} exceeds "
                      f"{1e3 * metrics.MEAN_ERROR_LIMIT_M:g} mm")
    if status == "hunting":
        freq = m.get("cart_frequency_Hz")
        _fail(result, f"the cart hunts {1e3 * float(m['cart_peak_to_peak_m']):.3g} mm peak to peak"
                      f"{f' at {freq:.2f} Hz' if freq else ''} {window}, beyond its bound {1e3 * bound:.3g} mm")


def assert_steady_state(result: "Result", error_m: float, fraction: float = metrics.STEADY_STATE_FRACTION) -> None:
    """Check ``|mean(position - reference)|`` over the last ``fraction`` of the run is at most ``error_m``.

    Examples
    --------
    >>> import ipcosim
    >>> ipcosim.assert_steady_state(ipcosim.run("single-mass-lqr", stop_time=6.0), error_m=0.002)
    """
    __tracebackhide__ = True
    if result.error:
        _fail(result, f"the run failed: {result.error}")
    t, x, r, _ = _step_target(result)
    tail = t >= metrics.steady_state_start(t[0], t[-1], fraction)
    err = metrics.steady_state_error(t, x, r, fraction)
    if not err <= error_m:
        _fail(result, f"steady-state error {err * 1e3:.3g} mm over {t[tail][0]:.2f}..{t[-1]:.2f} s exceeds "
                      f"{error_m * 1e3:.3g} mm (cart at {np.mean(x[tail]):.5g} m, reference {np.mean(r[tail]):.5g} m)")


def assert_close_to(result: "Result", reference_csv: str | os.PathLike[str], columns: Sequence[str] | None = None,
                    tol: float | Mapping[str, float] = 1e-3) -> None:
    """Check a run against a baseline CSV (``ipcosim run ... --save-baseline FILE``), column by column.

    Parameters
    ----------
    result : Result
    reference_csv : path
        The baseline (or any results.csv); the run is evaluated at its times.
    columns : sequence of str, optional
        Columns to compare (default: every column of the baseline).
    tol : float or mapping
        Largest allowed ``|run - baseline|`` per column, in the column's unit; one number for all.

    On failure, a figure of the difference (``baseline-diff.png``) is written beside the run's
    results (or into a temporary folder) and named in the message.

    Examples
    --------
    >>> import ipcosim, pathlib, tempfile
    >>> base = pathlib.Path(tempfile.mkdtemp()) / "lqr.csv"
    >>> r = ipcosim.run("single-mass-lqr", stop_time=1.0, save_baseline=base,
    ...                 record=["plant.cart_position", "plant.pendulum_angle"])
    >>> ipcosim.assert_close_to(r, base, tol={"plant.cart_position": 1e-6, "plant.pendulum_angle": 1e-6})
    """
    __tracebackhide__ = True
    from ipcosim.harness.testing.baseline import BaselineError, compare, load_baseline, plot_difference

    baseline = load_baseline(reference_csv)
    try:
        diffs, traces = compare(result, baseline, columns, tol)
    except BaselineError as exc:
        _fail(result, f"cannot compare with baseline {reference_csv}: {exc}")
    bad = [d for d in diffs if not d.ok]
    if not bad:
        return
    where = (result.metadata.get("files") or {}).get("results")
    folder = Path(where).parent if where else Path(tempfile.mkdtemp(prefix="ipcosim-diff-"))
    figure = plot_difference(baseline, traces, diffs, folder / "baseline-diff.png")
    lines = [f"{d.column}: max |run - baseline| = {d.max_abs:.3g} at t = {d.at_time:.3f} s "
             f"({'ok' if d.ok else 'exceeds'} tol {d.tol:.3g})" for d in diffs]
    _fail(result, f"differs from baseline {reference_csv} in {len(bad)} of {len(diffs)} columns:\n    "
          + "\n    ".join(lines) + f"\n  difference plot: {figure}")


# --------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Case:
    """One robustness case: a plant and the start values to set (``set`` accepts ``X*nominal``).

    ``scenario(controller)`` is the scenario name, e.g. ``case.scenario("lqr")`` ->
    ``single-mass-lqr``.
    """

    plant: str
    set: dict[str, Any] = field(default_factory=dict)

    @property
    def id(self) -> str:
        return "-".join([self.plant, *(f"{k}={v}" for k, v in self.set.items())])

    def scenario(self, controller: str) -> str:
        return f"{self.plant}-{controller}"


def cases(plants: Sequence[str] = KINDS, vary: Mapping[str, str | Sequence[float]] | None = None) -> list[Any]:
    """Parametrization over plants and parameter values, for ``pytest.mark.parametrize``.

    Parameters
    ----------
    plants : sequence of str
        ``single-mass`` and/or ``double-mass``.
    vary : mapping, optional
        ``component.variable`` -> a list of values, or a deterministic ``--vary`` form:
        ``"[0.9, 1.1]*nominal"``, ``"grid(0.8, 1.2, 3)*nominal"``, ``"[0.2, 0.25]"``.
        Every combination of the values is one case per plant (keep it small).

    Returns
    -------
    list
        ``pytest.param(Case, id=...)`` when pytest is importable, else the :class:`Case` s.

    Examples
    --------
    >>> import ipcosim
    >>> [p.id for p in ipcosim.cases(plants=["single-mass"], vary={"plant.Mp": "[0.9,1.1]*nominal"})]
    ['single-mass-plant.Mp=0.9*nominal', 'single-mass-plant.Mp=1.1*nominal']
    """
    import itertools

    from ipcosim.harness.api.grammar import parse_vary

    for p in plants:
        if p not in KINDS:
            raise UsageError(f"cases: unknown plant {p!r} (expected {', '.join(KINDS)})")
    axes: list[list[tuple[str, Any]]] = []
    for name, form in (vary or {}).items():
        text = form if isinstance(form, str) else "[" + ",".join(repr(float(v)) for v in form) + "]"
        v = parse_vary(f"{name}={text}")
        if v.is_random:
            raise UsageError(f"cases: {name}={text}: random forms make tests flaky; give a list or grid(...)")
        axes.append([(name, f"{p:g}*nominal" if v.relative else p) for p in v.points(1.0)])
    out = [Case(plant, dict(combo)) for plant in plants for combo in itertools.product(*axes)]
    try:
        import pytest
    except ImportError:  # pragma: no cover -- pytest is how cases are used
        return out
    return [pytest.param(c, id=c.id) for c in out]
