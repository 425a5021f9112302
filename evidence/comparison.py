"""The comparison a lab reads: every law on both plants, on the ideal plant and on the lab bench.

For each law (:data:`LAWS`: the parameter set the robustness table uses; the LQG's ``lab`` set on the lab
bench) and each bench (``ipcosim.fmus.instruments.REALISM``), three runs through the native FMUs:

* the **step** (the thesis's task, :data:`STOP_TIME`): settling time, overshoot, the residual oscillation of
  ``docs/metrics.md`` (mean error, peak-to-peak and frequency, limit cycle), RMS voltage, the electrical
  energy ``integral of |v i| dt`` the amplifier delivers to the motor, and the success criterion's status
  (``ipcosim.fmus.metrics.success_status``);
* the **push**: the loop at rest at the reference 0, an impulse :data:`PUSH_IMPULSE` on the cart carrying
  the pendulum at :data:`PUSH_TIME`; and the **tap**: an impulse :data:`TAP_IMPULSE` on the pendulum at the
  same time (the plant's ``tap_*`` parameters). Each gives its peak angle, the motor cart's largest
  excursion, the recovery time (``recovery_time_s``: the angle back inside +-0.01 rad for good) and whether
  the pendulum stayed up;

and, from ``ipcosim analyze``, the margins at the plant input, the describing function's prediction of the
friction cycle (``friction_limit_cycles``, shown beside the measured one) and the disk and worst-sensor
margins where the analysis reports them.
"""
from __future__ import annotations

import math
import sys
from typing import Any, Sequence

import numpy as np

from ipcosim.fmus.params import KINDS

#: (law, parameter set, parameter set on the lab bench) of each row, in the order of docs/controllers.md.
LAWS = {"single-mass": [("pid", "thesis", "thesis"), ("cascade-pid", "tuned", "tuned"), ("lqr", "thesis", "thesis"),
                        ("hsmc", "tuned", "tuned"), ("adaptive-hsmc", "tuned", "tuned"), ("lqg", "tuned", "lab")],
        "double-mass": [("pid", "thesis", "thesis"), ("cascade-pid", "tuned", "tuned"), ("lqr", "thesis", "thesis"),
                        ("hsmc", "tuned", "tuned"), ("adaptive-hsmc", "thesis", "thesis"), ("lqg", "tuned", "lab")]}
BENCHES = ("ideal", "lab")
#: Length of the step run [s] (the robustness table's), and of the push and tap runs.
STOP_TIME = 15.0
PUSH_STOP_TIME = 8.0
#: When the push and the tap act [s], on a loop at rest at 0.
PUSH_TIME = 2.0
#: The push: an impulse on the cart carrying the pendulum [N s] (0.05 m/s on a 1 kg cart).
PUSH_IMPULSE = 0.05
#: The tap: an impulse on the pendulum [N m s] (``single-mass-lqr-tap``'s).
TAP_IMPULSE = 0.005
PUSH, TAP = {"plant.tap_force_impulse": PUSH_IMPULSE}, {"plant.tap_torque_impulse": TAP_IMPULSE}


def _energy(result: Any) -> float | None:
    """``integral of |v i| dt`` [J]: the electrical power the amplifier delivers to the motor, over the run."""
    cols = result.columns
    if "plant.motor_current" not in cols or "plant.voltage" not in cols:
        return None
    t = np.asarray(result["time"], float)
    p = np.abs(np.asarray(result["plant.voltage"], float) * np.asarray(result["plant.motor_current"], float))
    return float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(t))) if np.all(np.isfinite(p)) else None


def _run(scenario: str, pset: str, values: dict[str, float], stop_time: float) -> Any:
    import ipcosim
    from ipcosim.harness.master.results import SimulationError

    try:
        return ipcosim.run(scenario, parameter_set=pset, fmus="native", stop_time=stop_time, set=values)
    except SimulationError as exc:  # a loop that diverged: its rows so far and their metrics are the result
        return exc.result


def step_row(scenario: str, pset: str, bench: str, kind: str) -> dict[str, Any]:
    """The step run's figures (see the module docstring)."""
    from ipcosim.fmus.metrics import success_status
    from ipcosim.harness.analysis.residual_cycle import realism_values

    r = _run(scenario, pset, realism_values(bench, kind), STOP_TIME)
    m = {k: v for k, v in r.metrics.items() if not isinstance(v, (dict, list))}
    return {**m, "energy_J": _energy(r), "amplitude_bound_m": r.metadata.get("amplitude_bound_m"),
            "status": success_status(m, r.metadata.get("amplitude_bound_m")), "error": r.error,
            **_old_verdict(m, realism_values(bench, kind), kind)}


def _old_verdict(metrics: dict[str, Any], values: dict[str, float], kind: str) -> dict[str, Any]:
    """The verdict of the friction bound 2 mm + 2 b2 / K (the criterion before the predicted cycle), beside, for a
    run of plant ``kind`` with the ``plant.*`` values ``values``."""
    from ipcosim.fmus.metrics import amplitude_bound, success_status
    from ipcosim.fmus.params import DEFAULT_PRESET, preset

    K = values.get("plant.K", getattr(preset(DEFAULT_PRESET[kind]), "K", 0.0))   # the scenarios' spring
    bound = amplitude_bound(float(values.get("plant.b2") or 0.0), float(K or 0.0))
    return {"old_amplitude_bound_m": bound, "old_status": success_status(metrics, bound)}


def rejudge(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` (what :func:`measure` wrote) with each step run judged by its own bound, computed from its plant and
    law by the function the engine calls before a run (``ipcosim.harness.analysis.residual_cycle.run_bound``), and
    by the friction bound beside it; the runs are not repeated (their metrics do not depend on the bound)."""
    from ipcosim.fmus.metrics import success_status
    from ipcosim.harness.analysis.residual_cycle import realism_values, run_bound
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    out = []
    for r in rows:
        values = realism_values(r["bench"], r["kind"])
        bound = run_bound(select_parameter_set(load_scenario(r["scenario"]), r["set"]), values)
        step = {**r["step"], **bound}
        step.update(status=success_status(step, bound["amplitude_bound_m"]), **_old_verdict(step, values, r["kind"]))
        out.append({**r, "step": step})
    return out


def disturbance_row(scenario: str, pset: str, bench: str, kind: str, impulse: dict[str, float]) -> dict[str, Any]:
    """The push or tap run's figures: peak angle, the motor cart's largest excursion, recovery, upright."""
    from ipcosim.fmus import kinds
    from ipcosim.harness.analysis.residual_cycle import realism_values

    values = {**realism_values(bench, kind), "setpoint.amplitude": 0.0, "plant.tap_time": PUSH_TIME, **impulse}
    r = _run(scenario, pset, values, PUSH_STOP_TIME)
    m = r.metrics
    t = np.asarray(r["time"], float)
    col = f"plant.{kinds.get(kind).carts[0].position}"  # the motor cart's
    x = np.asarray(r[col], float)[t >= PUSH_TIME]
    fell_before = not bool(np.all(np.abs(np.asarray(r["plant.pendulum_angle"], float)[t < PUSH_TIME]) < 0.35))
    return {"peak_angle_rad": m.get("peak_angle_after_tap_rad"), "recovery_time_s": m.get("recovery_time_s"),
            "cart_excursion_m": float(np.max(np.abs(x))) if x.size and np.all(np.isfinite(x)) else None,
            "upright": m.get("upright"), "fell_before": fell_before}


def analysis_row(scenario: str, pset: str) -> dict[str, Any]:
    """Margins at the plant input, the predicted friction cycle of the motor cart, and the disk and
    worst-sensor margins where ``ipcosim analyze`` reports them (None where it does not)."""
    from ipcosim.harness.analysis.analyze import analyze_loop, scenario_loop

    a = analyze_loop(scenario_loop(scenario, parameter_set=pset)[0], pid_search=False)
    gm = a.get("gain_margin") or {}
    cycles = ((a.get("friction_limit_cycles") or {}).get("cycles")) or []
    motor = "cart_position" if scenario.startswith("single") else "active_cart_position"
    best = max(cycles, key=lambda c: c["amplitudes"].get(motor, 0.0), default=None)
    return {"stable": a.get("closed_loop_stable"), "gain_up": gm.get("upper"), "gain_down": gm.get("lower"),
            "phase_margin_deg": a.get("phase_margin_deg"), "delay_margin_s": a.get("delay_margin_s"),
            "predicted_cycle": None if best is None else {
                "parameter": best["parameter"], "frequency_Hz": best["frequency_Hz"],
                "cart_amplitude_m": best["amplitudes"].get(motor)},
            "disk_margin": _disk(a.get("disk_margin")), "worst_sensor": _worst_sensor(a.get("sensor_margins"))}


def _disk(disk: dict[str, Any] | None) -> dict[str, float] | None:
    """The balanced disk margin at the plant input: its gain range and phase."""
    if not disk:
        return None
    return {k: float(disk[k]) for k in ("alpha", "gain_lower", "gain_upper", "phase_deg")}


def _worst_sensor(sensors: dict[str, Any] | None) -> dict[str, Any] | None:
    """The measured signal whose loop-at-a-time gain range is narrowest (the smaller of its distances from 1)."""
    if not sensors:
        return None
    name, m = min(sensors.items(), key=lambda kv: min(float(kv[1]["gain_upper"]) - 1, 1 - float(kv[1]["gain_lower"])))
    return {"signal": name, "gain_lower": float(m["gain_lower"]), "gain_upper": float(m["gain_upper"]),
            "delay_margin_s": None if m.get("delay_margin_s") is None else float(m["delay_margin_s"])}


def _disk_text(d: dict[str, float] | None) -> str:
    return "" if d is None else f"x{d['gain_lower']:.3g} .. x{d['gain_upper']:.3g}, +-{d['phase_deg']:.1f} deg"


def _sensor_text(w: dict[str, Any] | None) -> str:
    if w is None:
        return ""
    delay = "" if w["delay_margin_s"] is None else f", {w['delay_margin_s'] * 1e3:.3g} ms"
    return f"{w['signal']}: x{w['gain_lower']:.3g} .. x{w['gain_upper']:.3g}{delay}"


def measure(kinds: Sequence[str] = KINDS) -> list[dict[str, Any]]:
    """Every row of the comparison, as data (``docs/results.json``'s ``comparison``)."""
    rows = []
    for kind in kinds:
        for law, pset, lab_set in LAWS[kind]:
            scenario = f"{kind}-{law}"
            for bench in BENCHES:
                s = lab_set if bench == "lab" else pset
                print(f"comparison: {scenario} ({s}) on the {bench} bench", file=sys.stderr, flush=True)
                rows.append({"scenario": scenario, "law": law, "kind": kind, "set": s, "bench": bench,
                             "step": step_row(scenario, s, bench, kind),
                             "push": disturbance_row(scenario, s, bench, kind, PUSH),
                             "tap": disturbance_row(scenario, s, bench, kind, TAP),
                             "analysis": analysis_row(scenario, pset)})
    return rows


def _f(v: Any, scale: float = 1.0, spec: str = ".3g") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v * scale, spec)


def _disturbance(d: dict[str, Any]) -> str:
    if d["fell_before"]:
        return "fell before"
    if not d["upright"]:
        return "falls"
    rec = ("not recovered" if d["recovery_time_s"] is None else "never beyond 10 mrad" if d["recovery_time_s"] == 0
           else f"recovers in {d['recovery_time_s']:.2f} s")
    return f"{_f(d['peak_angle_rad'], 1e3)} mrad, {_f(d['cart_excursion_m'], 1e3)} mm, {rec}"


def _cycle(step: dict[str, Any]) -> str:
    if step.get("cart_peak_to_peak_m") is None:
        return "-"
    cycle = "cycle" if step.get("limit_cycle") else "at rest"
    return (f"{cycle}: {_f(step['cart_peak_to_peak_m'], 1e3)} mm p-p at {_f(step.get('cart_frequency_Hz'), 1, '.2f')}"
            f" Hz; pendulum {_f(step.get('angle_peak_to_peak_rad'), 1e3)} mrad")


def _predicted(a: dict[str, Any]) -> str:
    c = a.get("predicted_cycle")
    if not a.get("stable"):
        return "unstable loop"
    return "none" if c is None else f"{2 * c['cart_amplitude_m'] * 1e3:.3g} mm p-p at {c['frequency_Hz']:.2f} Hz"


def _margins(a: dict[str, Any]) -> str:
    if not a.get("stable"):
        return "unstable"
    return (f"{_f(a['gain_up'])} / {_f(a['gain_down'])}, {_f(a['phase_margin_deg'], 1, '.1f')} deg, "
            f"{_f(a['delay_margin_s'], 1e3)} ms")


def table(rows: list[dict[str, Any]]) -> str:
    """The comparison as one Markdown table."""
    head = ["plant", "law (set)", "bench", "verdict (bound mm)", "verdict, friction bound", "settling s",
            "overshoot mm", "mean error mm",
            "residual (motor cart, final 5 s)", "predicted friction cycle", "RMS V", "energy J",
            "push 0.05 N s on the cart", "tap 5 mN m s on the pendulum", "input margins (gain up / down, phase, delay)",
            "disk margin", "worst sensor"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        s, a = r["step"], r["analysis"]
        word = {"ok": "**success**", "fell": "falls", "unsettled": "offset", "hunting": "hunts"}
        bound = s.get("amplitude_bound_m")
        fallback = "" if s.get("amplitude_bound_from") in (None, "prediction") else ", friction bound"
        verdict = word[s["status"]] + ("" if bound is None else f" ({bound * 1e3:.2f}{fallback})")
        old = word[s["old_status"]] + f" ({s['old_amplitude_bound_m'] * 1e3:.2f})" if "old_status" in s else "-"
        lines.append("| " + " | ".join([
            r["kind"], f"{r['law']} ({r['set']})", r["bench"], verdict, old,
            "-" if s.get("settling_time_s") is None else f"{s['settling_time_s']:.2f}",
            _f(s.get("overshoot_m"), 1e3), _f(s.get("cart_mean_error_m"), 1e3, ".2f"), _cycle(s), _predicted(a),
            _f(s.get("rms_voltage_V"), 1, ".2f"), _f(s.get("energy_J"), 1, ".3g"),
            _disturbance(r["push"]), _disturbance(r["tap"]), _margins(a),
            _disk_text(a.get("disk_margin")), _sensor_text(a.get("worst_sensor"))]) + " |")
    return "\n".join(lines)


INTRO = (
    "Every law on both plants, through the native FMUs (`evidence.comparison`), on the *ideal* "
    "plant (no friction, exact readings) and on the *lab* bench (encoder counts, stick-slip Coulomb friction "
    "0.1047 N, end stops, DAC codes, the 1 ms computation delay, +-10 V), with the parameter set the robustness "
    f"table uses (the LQG's `lab` set on the lab bench). *Step*: the thesis's task, {STOP_TIME:g} s. *Verdict*: "
    "the success criterion of `docs/metrics.md` (upright, |mean error| <= 1 mm over the final 5 s, the motor "
    "cart's residual peak-to-peak within the run's bound: the residual cycle predicted for its plant and law plus "
    "1 mm, in brackets; *friction bound* where the prediction cannot treat the run, 2 mm + 2 b2 / K); beside it "
    "the verdict of the friction bound alone, the criterion before the predicted cycle (the step runs are judged "
    "again from their recorded metrics, `evidence.comparison.rejudge`); *hunts* = upright but beyond the bound, "
    "*offset* = mean error beyond 1 mm. *Residual*: the motor cart's peak-to-peak and dominant frequency over "
    "the final 5 s, and whether that is a limit cycle; *predicted friction cycle*: the describing function's "
    "(`ipcosim analyze`, `friction_limit_cycles`: the law without its friction compensation, each cart's "
    "friction alone, the largest motor-cart cycle, as peak-to-peak). *Energy*: integral of |v i| over the step "
    f"run. *Push* and *tap*: the loop at rest at 0, an impulse at {PUSH_TIME:g} s ({PUSH_IMPULSE:g} N s on the "
    f"cart carrying the pendulum, or {TAP_IMPULSE:g} N m s on the pendulum), {PUSH_STOP_TIME:g} s: the peak "
    "angle, the motor cart's largest excursion and the recovery time (the angle back inside +-0.01 rad for "
    "good). *Margins* and the prediction: `ipcosim analyze` at the plant input, of the row's ideal-plant set "
    "(the LQG's `lab` set is the `tuned` design plus a friction compensation whose breakaway term is positive "
    "feedback on the frictionless linear plant: see the margins table); the *disk margin* is the balanced one at "
    "the plant input (the gain and phase it tolerates at once), the *worst sensor* the measured signal whose "
    "loop-at-a-time gain range is narrowest, with that range and its delay margin (docs/studies.md, "
    "`ipcosim analyze`).")


if __name__ == "__main__":
    import json

    data = measure()
    json.dump(data, sys.stdout, indent=1)
