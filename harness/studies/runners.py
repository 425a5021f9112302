"""Run specifications: what one run of a sweep is, built once per worker.

A :class:`RunSpec` is a small picklable description (for a co-simulation: the scenario
and the run settings). The sweep engine sends it to every worker, where ``build()`` is
called once -- for a co-simulation this extracts and loads the FMUs -- and the returned
runner is called once per case with the case's parameter values and seed. A runner returns
a dict of metrics; it may raise, and the engine records the exception as a failed run.

Specs here:

* :class:`CosimSpec` (in ``ipcosim.harness.studies.cosim``): the real FMI co-simulation of a scenario.
* :class:`PurePlantSpec`: the pure-Python single-mass plant under a discrete LQR state
  feedback, no FMUs -- a fast, deterministic stand-in with the same metrics, used to test the
  engine and to check a cluster set-up quickly (scenario name ``pure:single-mass-lqr``).
* :class:`SyntheticSpec`: an analytic function with optional delay and failures (tests, bench).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Mapping

import numpy as np

from ipcosim.errors import IpcosimError

#: A per-worker run function: (parameter values, seed) -> metrics.
Runner = Callable[[Mapping[str, float], int], dict]

#: Statuses a run can end with. ``ok`` is a success; the others are failures.
STATUSES = ("ok", "fell", "unsettled", "hunting", "error")


class RunFailure(IpcosimError, RuntimeError):
    """A run that could not be carried out (recorded as status ``error``)."""


def classify_task(metrics: Mapping[str, Any], params: Mapping[str, Any] | None = None) -> str:
    """Status of a closed-loop run of the thesis's task: :func:`ipcosim.fmus.metrics.success_status` (``ok``,
    ``fell``, ``unsettled``: mean error beyond 1 mm, ``hunting``: residual amplitude beyond its bound) with the
    run's own amplitude bound (``amplitude_bound_m`` of its metrics, computed before it ran); a run without one is
    held to the friction bound of its passive-cart friction and spring (``plant.b2``, ``plant.K`` of ``params``;
    absent: no forced cycle).
    Metrics without the residual oscillation (a spec that does not measure it) fall back on the settling time.
    """
    from ipcosim.fmus.metrics import amplitude_bound, success_status

    if "cart_mean_error_m" not in metrics:
        return "fell" if metrics.get("upright") is not True else (
            "unsettled" if metrics.get("settling_time_s") is None else "ok")
    params = params or {}
    if metrics.get("amplitude_bound_m") is not None:
        return success_status(metrics)
    return success_status(metrics, amplitude_bound(float(params.get("plant.b2") or 0.0),
                                                   float(params.get("plant.K") or 0.0)))


def stable_hash(obj: Any) -> str:
    """SHA-256 (hex, 16 chars) of a JSON-serialisable description."""
    text = json.dumps(obj, sort_keys=True, default=repr, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class RunSpec:
    """Base of run specifications (see the module docstring).

    Subclasses set ``name``, ``parameters`` (``component.variable`` -> nominal value of every
    parameter a sweep may vary) and ``metric_names``, and implement ``build`` and ``identity``.
    """

    name: str = "spec"
    parameters: Mapping[str, float] = {}
    metric_names: tuple[str, ...] = ()
    stop_time: float = 0.0

    def build(self) -> Runner:  # pragma: no cover - abstract
        """Create the per-worker runner (load models once)."""
        raise NotImplementedError

    def identity(self) -> dict[str, Any]:
        """What identifies the spec, JSON-serialisable (recorded in the sweep's metadata, hashed into ``key``)."""
        return {"name": self.name}

    def classify(self, metrics: Mapping[str, Any], params: Mapping[str, Any] | None = None) -> str:
        """Status of a finished run (default: the task's success criterion, :func:`classify_task`), with the
        run's parameter values (``component.variable``; the spec's nominal ones where the case sets none)."""
        return classify_task(metrics, {**self.parameters, **(params or {})})

    @property
    def key(self) -> str:
        """Identity of the spec: runs of specs with equal keys are interchangeable."""
        return stable_hash(self.identity())


# --------------------------------------------------------------------------- synthetic


@dataclass
class SyntheticSpec(RunSpec):
    """An analytic stand-in for a co-simulation (tests and benchmarks).

    ``value = (model.x - 1)^2 + (model.y - 2)^2 + noise * N(0, 1)`` with the normal draw seeded
    by the case's seed. A run raises :class:`RunFailure` when ``model.x > fail_above``, ends its
worker process abruptly (as a crashing FMU would) when ``model.x > crash_above``, takes at
    least ``delay_s`` seconds, and, with ``calls_dir`` set, leaves a file named after its seed
    there (so tests can count how often each case ran).
    """

    delay_s: float = 0.0
    fail_above: float = math.inf
    crash_above: float = math.inf
    noise: float = 0.0
    calls_dir: str | None = None
    name: str = "synthetic"
    parameters: Mapping[str, float] = field(default_factory=lambda: {"model.x": 1.0, "model.y": 2.0})
    metric_names: tuple[str, ...] = ("value", "upright", "settling_time_s")

    def identity(self) -> dict[str, Any]:
        return {"name": self.name, "delay_s": self.delay_s, "fail_above": repr(self.fail_above),
                "crash_above": repr(self.crash_above),
                "noise": self.noise, "parameters": dict(self.parameters)}

    def build(self) -> Runner:
        spec = self

        def run(params: Mapping[str, float], seed: int) -> dict:
            t0 = time.perf_counter()
            values = {**spec.parameters, **params}
            unknown = set(params) - set(spec.parameters)
            if unknown:
                raise RunFailure(f"synthetic model has no parameter {sorted(unknown)[0]!r}")
            x, y = values["model.x"], values["model.y"]
            if spec.calls_dir:
                with open(os.path.join(spec.calls_dir, f"{seed}.{os.getpid()}.{time.monotonic_ns()}"), "w"):
                    pass
            if x > spec.crash_above:
                os._exit(70)
            if x > spec.fail_above:
                raise RunFailure(f"model.x = {x:g} is above {spec.fail_above:g}: the model diverged")
            noise = spec.noise * float(np.random.default_rng(seed).normal()) if spec.noise else 0.0
            value = (x - 1.0) ** 2 + (y - 2.0) ** 2 + noise
            remaining = spec.delay_s - (time.perf_counter() - t0)
            if remaining > 0:
                time.sleep(remaining)
            return {"value": value, "upright": value < 1.0, "settling_time_s": 1.0 if value < 0.5 else None}

        return run


# --------------------------------------------------------------------------- pure plant loop


@dataclass
class PurePlantSpec(RunSpec):
    """The single-mass plant (``ipcosim.fmus.plant.Plant``) under a discrete LQR state feedback.

    The controller samples the true state every ``controller.sample_period`` and holds
    ``u = -K (x - [r, 0, 0, 0])`` (clipped to ``controller.voltage_limit``); ``K`` is the LQR
    gain of the nominal plant's 4-state model for ``Q = diag(q_position, q_velocity, q_angle,
    q_angular_velocity)``, ``R = r_voltage``. The reference steps to ``setpoint.amplitude`` at
    ``setpoint.step_time``. Plant parameters are the ``ipcosim.fmus.params`` names under ``plant.``.
    """

    stop_time: float = 5.0
    step: float = 1e-3
    preset: str = "thesis-ch3"
    with_series: bool = False
    name: str = "pure:single-mass-lqr"
    metric_names: tuple[str, ...] = ()
    parameters: Mapping[str, float] = field(default_factory=dict)

    CONTROLLER_DEFAULTS = {"controller.q_position": 2000.0, "controller.q_velocity": 1.0,
                           "controller.q_angle": 200.0, "controller.q_angular_velocity": 1.0,
                           "controller.r_voltage": 1.0, "controller.sample_period": 2e-3,
                           "controller.voltage_limit": 10.0}
    SETPOINT_DEFAULTS = {"setpoint.amplitude": 0.05, "setpoint.step_time": 0.0}

    def __post_init__(self) -> None:
        from ipcosim.fmus.metrics import METRIC_KEYS
        from ipcosim.fmus.params import preset
        from ipcosim.harness.studies.cost import COST_TERMS

        plant = preset(self.preset)
        params = {f"plant.{f.name}": float(getattr(plant, f.name)) for f in fields(plant)}
        params.update(self.CONTROLLER_DEFAULTS)
        params.update(self.SETPOINT_DEFAULTS)
        self.parameters = params
        self.metric_names = tuple(METRIC_KEYS) + COST_TERMS

    def identity(self) -> dict[str, Any]:
        return {"name": self.name, "stop_time": self.stop_time, "step": self.step, "preset": self.preset,
                "with_series": self.with_series, "parameters": dict(self.parameters)}

    def build(self) -> Runner:
        from ipcosim.controllers.design import lqr_gain
        from ipcosim.controllers.simulate import LoopError, run_loop
        from ipcosim.fmus.linearize import linearize
        from ipcosim.fmus.params import preset, with_values
        from ipcosim.fmus.plant import PlantStepError
        from ipcosim.harness.studies.cost import metrics_and_cost_terms, series

        nominal_plant = preset(self.preset)
        design = linearize(nominal_plant, inductance=False)
        spec = self
        gains: dict[tuple, np.ndarray] = {}

        def gain(q: tuple[float, ...], r: float) -> np.ndarray:
            if (q, r) not in gains:
                gains[(q, r)] = lqr_gain(design.A, design.B, np.diag(q), np.array([[r]])).ravel()
            return gains[(q, r)]

        def run(params: Mapping[str, float], seed: int) -> dict:
            unknown = set(params) - set(spec.parameters)
            if unknown:
                raise RunFailure(f"{spec.name} has no parameter {sorted(unknown)[0]!r}")
            v = {**spec.parameters, **params}
            plant = with_values(nominal_plant, {k[6:]: val for k, val in v.items() if k.startswith("plant.")})
            law = StateFeedback(gain((v["controller.q_position"], v["controller.q_velocity"], v["controller.q_angle"],
                                      v["controller.q_angular_velocity"]), v["controller.r_voltage"]),
                                v["controller.sample_period"], v["controller.voltage_limit"])
            amplitude, step_time = v["setpoint.amplitude"], v["setpoint.step_time"]
            try:
                r = run_loop(law, plant, spec.stop_time, spec.step, lambda t: amplitude if t >= step_time else 0.0,
                             observe="state", hold_beyond=FALLEN_FAR_RAD)
            except LoopError as exc:
                raise RunFailure(f"controller.{exc}") from None
            if r.failure:
                raise PlantStepError(r.failure)
            cols = (r.time, r.states[:, 0], r.reference, r.signal("pendulum_angle"), r.voltage)
            metrics = metrics_and_cost_terms(*cols)
            if spec.with_series:
                metrics["series"] = series(*cols)
            return metrics

        return run


#: Past this pendulum angle [rad] the stand-in stops integrating (fallen far beyond the upright limit) and holds
#: its last sample to the end of the run.
FALLEN_FAR_RAD = 1.5


class StateFeedback:
    """The stand-in's controller: ``u = -K (x - [r, 0, 0, 0])`` on the plant's true state, clipped to
    ``+-voltage_limit`` (``run_loop(observe="state")`` gives it the state at each sample)."""

    def __init__(self, K: np.ndarray, sample_period: float, voltage_limit: float) -> None:
        self.K, self.sample_period, self.voltage_limit = K, sample_period, voltage_limit

    def reset(self) -> None:
        """Nothing to reset: the law has no state."""

    def step(self, x: np.ndarray, r: float) -> float:
        """The voltage for the state ``x`` (``ipcosim.fmus.physics`` order) and the reference ``r`` [m]."""
        from ipcosim.controllers.laws.base import saturate

        return saturate(float(-self.K @ np.array([x[0] - r, x[1], x[2], x[3]])), self.voltage_limit)


# --------------------------------------------------------------------------- several scenarios at once


#: Case parameter that selects the sub-spec of a :class:`MultiSpec`.
SCENARIO_PARAM = "study.scenario"


@dataclass
class MultiSpec(RunSpec):
    """Several run specs as one, so that runs of different scenarios share one sweep (and its
    parallelism). A case picks its scenario with the parameter ``study.scenario`` (its index in
    ``specs``); its other parameters go to that scenario's runner. Each worker builds a
    scenario's runner the first time it runs one of its cases."""

    specs: list = field(default_factory=list)
    name: str = "scenarios"

    def __post_init__(self) -> None:
        names: dict[str, None] = {}
        for s in self.specs:
            for m in s.metric_names:
                names.setdefault(m, None)
        self.metric_names = tuple(names)
        self.parameters = {SCENARIO_PARAM: 0.0}

    def identity(self) -> dict[str, Any]:
        return {"name": self.name, "specs": [s.identity() for s in self.specs]}

    def build(self) -> Runner:
        specs = self.specs
        runners: dict[int, Runner] = {}

        def run(params: Mapping[str, float], seed: int) -> dict:
            i = int(params[SCENARIO_PARAM])
            if i not in runners:
                runners[i] = specs[i].build()
            rest = {k: v for k, v in params.items() if k != SCENARIO_PARAM}
            return runners[i](rest, seed)

        return run
