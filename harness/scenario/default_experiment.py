"""The experiment of a run that gives none: the communication step and the stop time from the
SSD's DefaultExperiment, else from the FMUs' (with where each comes from, for messages)."""
from __future__ import annotations

import math

from ipcosim.harness.master.system import System


def default_step(system: System) -> tuple[float | None, str]:
    """The communication step when none is given, and where it comes from.

    The SSD's step (the OSP ``FixedStepAlgorithm`` annotation of its DefaultExperiment; SSP 1.0's
    DefaultExperiment has no step attribute), else the FMUs' common DefaultExperiment stepSize:
    the largest step that divides every FMU's (in whole nanoseconds), so each FMU's own step is a
    whole number of communication steps. ``(None, reason)`` when there is none.
    """
    sc = system.scenario
    if sc.experiment.step_size is not None:
        return sc.experiment.step_size, f"{sc.origin}: DefaultExperiment (osp:FixedStepAlgorithm baseStepSize)"
    steps = {i.name: i.model.default_step for i in system.instances if i.model.default_step is not None}
    if not steps:
        return None, f"{sc.origin}: no step in the SSD and no FMU gives a DefaultExperiment stepSize"
    ns = {k: round(v * 1e9) for k, v in steps.items()}
    if any(n < 1 or abs(n - steps[k] * 1e9) > 1e-6 * steps[k] * 1e9 for k, n in ns.items()):
        if len(set(steps.values())) == 1:
            return next(iter(steps.values())), "the FMUs' DefaultExperiment stepSize"
        return None, (f"{sc.origin}: the FMUs' DefaultExperiment steps ("
                      + ", ".join(f"{k} {v:g} s" for k, v in steps.items()) + ") have no common step")
    g = 0
    for n in ns.values():
        g = math.gcd(g, n)
    return g / 1e9, "the FMUs' DefaultExperiment stepSize (" + ", ".join(f"{k} {v:g} s" for k, v in steps.items()) + ")"


def default_stop_time(system: System) -> tuple[float | None, str]:
    """The stop time when none is given: the SSD's DefaultExperiment stopTime, else the FMUs'
    DefaultExperiment stopTime when those that give one agree; ``(None, reason)`` otherwise."""
    sc = system.scenario
    if sc.experiment.stop_time is not None:
        return sc.experiment.stop_time, f"{sc.origin}: DefaultExperiment stopTime"
    stops = {i.name: i.model.default_stop for i in system.instances if i.model.default_stop is not None}
    if len(set(stops.values())) == 1:
        return next(iter(stops.values())), "the FMUs' DefaultExperiment stopTime"
    if not stops:
        return None, f"{sc.origin}: no DefaultExperiment stopTime in the SSD or the FMUs"
    return None, (f"{sc.origin}: no stopTime in the SSD and the FMUs' differ ("
                  + ", ".join(f"{k} {v:g} s" for k, v in stops.items()) + ")")
