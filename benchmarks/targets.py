"""What a bench module records: checked targets and reference figures (see ``benchmarks.bench``).

A bench module's ``run()`` returns the lines it prints and records its figures here:

* :func:`target` -- a figure the project controls, with the limit it must keep (set a safe margin
  from the figure measured when the limit was set, so that a regression of about a third fails);
  a miss is printed after the module's lines and makes ``make bench`` exit 1;
* :func:`figure` -- a figure printed and recorded, never checked: a reference figure (one that
  depends on fmpy, libcosim, pythonfmu or the machine more than on the project) names its
  ``anchor``, the figure of the same run it is to be read against.

Every recorded figure lands in ``benchmarks/last.json`` under its key (``"<module>.<figure>"``),
where ``python -m benchmarks.docs`` reads it. A bench that cannot run its subject raises: the
module fails and ``make bench`` exits 1 (no fallback is measured in its place).
"""
from __future__ import annotations

import math
from typing import Any

#: Figures recorded in this process: ``{key: {"value", "unit", "what", ...}}``, in recording order.
FIGURES: dict[str, dict[str, Any]] = {}
#: :func:`machine_speed` [ms] at which the absolute limits (``target(..., per_speed=True)``) were set:
#: these machines at their fastest measured (22:27 UTC on 2026-12-01, load near 0).
REFERENCE_SPEED_MS = 23.0
#: This process's :func:`machine_speed` [ms], measured by ``benchmarks.bench`` before the module runs;
#: None: not measured, every limit applies as written.
SPEED_MS: float | None = None
#: Whether :func:`speed_factor` measures the speed again when a scaled target is recorded (set by
#: ``benchmarks.bench``): the machine's speed moves within a module, and the figure a target checks was
#: measured just before it is recorded, often long after the module started.
RESAMPLE = False


def _record(key: str, value: float, unit: str, what: str, **extra: Any) -> None:
    if key in FIGURES:
        raise ValueError(f"bench figure {key!r} recorded twice")
    value = float(value)
    FIGURES[key] = {"value": value if math.isfinite(value) else None, "unit": unit, "what": what or key, **extra}


def target(key: str, value: float, limit: float, unit: str = "", *, at_most: bool = True, what: str,
           per_speed: bool = False) -> str:
    """Record a checked figure; return its verdict text for the module's line.

    Parameters
    ----------
    key : str
        ``"<module>.<figure>"``, the figure's name in ``benchmarks/last.json``.
    value, limit : float
        Measurement and target, in ``unit``. A value that is not finite misses its target.
    unit : str
        As printed after the number (``"s"``, ``"us"``, ``"x"``, ``"%"``).
    at_most : bool
        True: the target is ``value <= limit``; False: ``value >= limit``.
    what : str
        What was measured, in words (the docs' tables and the summary of misses show it).
    per_speed : bool
        For an absolute CPU figure (a time, a time per step, a real-time factor) that moves with the
        machine: ``limit`` holds at :data:`REFERENCE_SPEED_MS` and is scaled by :func:`speed_factor`
        on a machine that runs slower now (a ratio of two figures of the same run needs no scaling).
        The limit applied and the factor are recorded (``limit``, ``limit_at_reference``, ``speed_factor``).

    Returns
    -------
    str
        ``"target <= 1.3 s: met"`` or ``"target <= 1.3 s: MISSED"``; a scaled limit is followed by
        its factor (``"target <= 1.56 s (x1.2 for the machine's speed): met"``).
    """
    extra: dict[str, Any] = {}
    shown = f"{limit:g}{_space(unit)}"
    if per_speed:
        factor = speed_factor()
        extra = {"limit_at_reference": float(limit), "speed_factor": factor}
        limit = limit * factor if at_most else limit / factor
        if factor > 1.0:
            shown = f"{fmt(limit)}{_space(unit)} (x{factor:.2f} for the machine's speed)"
    met = math.isfinite(value) and (value <= limit if at_most else value >= limit)
    _record(key, value, unit, what, limit=float(limit), at_most=at_most, met=met, **extra)
    return f"target {'<=' if at_most else '>='} {shown}: {'met' if met else 'MISSED'}"


def speed_factor() -> float:
    """How many times slower this machine runs than at :data:`REFERENCE_SPEED_MS` (never below 1: a faster
    machine does not tighten a limit); 1 when the speed was not measured. With :data:`RESAMPLE`, the slower
    of the speed before the module and the speed now: the figure being checked was measured between them."""
    if SPEED_MS is None or not math.isfinite(SPEED_MS):
        return 1.0
    speed = max(SPEED_MS, machine_speed()) if RESAMPLE else SPEED_MS
    return max(1.0, speed / REFERENCE_SPEED_MS)


def figure(key: str, value: float, unit: str = "", *, anchor: str = "", what: str) -> str:
    """Record a figure that is never checked; return ``value`` formatted with its unit.

    Parameters
    ----------
    key, value, unit, what
        As for :func:`target`.
    anchor : str
        For a reference figure: what it is to be read against (a figure of the same run, or the
        outside cost it depends on), printed beside it and kept in ``last.json``.

    Returns
    -------
    str
        ``"<value> <unit>"`` (:func:`fmt`).
    """
    _record(key, value, unit, what, **({"anchor": anchor} if anchor else {}))
    return f"{fmt(value)}{_space(unit)}"


def fmt(value: float | None) -> str:
    """A figure as printed and written to the docs: three significant digits, no exponent below 10^6."""
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:.0f}" if abs(value) >= 1000 and abs(value) < 1e6 else f"{value:.3g}"


def missed() -> list[str]:
    """One line per target missed in this process: ``what: value unit, target <= limit unit``."""
    out = []
    for key, f in FIGURES.items():
        if "met" in f and not f["met"]:
            op = "<=" if f["at_most"] else ">="
            value = "not measured" if f["value"] is None else f"{fmt(f['value'])}{_space(f['unit'])}"
            out.append(f"{f['what']} ({key}): {value}, target {op} {f['limit']:g}{_space(f['unit'])}")
    return out


def _space(unit: str) -> str:
    return unit if unit in ("", "x") else f" {unit}"


def machine_speed(rounds: int = 15) -> float:
    """Milliseconds of CPU a fixed pure-Python workload (the sum of 2.5 million integers) takes
    now, the least disturbed of ``rounds``: how fast this machine is while a module runs.

    The machines are shared: the same workload took 23 ms at one hour and 32-36 ms an hour later at
    the same load, and every CPU-time figure of the project moved with it. Each module's entry in
    last.json carries this figure so that its others can be read against it.
    """
    import time

    samples = []
    for _ in range(rounds):
        c0 = time.process_time()
        sum(range(2_500_000))
        samples.append((time.process_time() - c0) * 1e3)
    return least_disturbed(samples)


def least_disturbed(samples: list[float], fraction: float = 0.1) -> float:
    """The ``fraction`` quantile of many short timed rounds: the rounds least disturbed by other load
    on a shared machine (a preempted round is slow, never fast), steadier than their median there."""
    ordered = sorted(samples)
    if not ordered:
        raise ValueError("no samples")
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]
