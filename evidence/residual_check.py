"""The residual cycle predicted against the simulated one, on the nominal lab bench (``docs/results.md``).

For every law of the comparison (``evidence.comparison``) that stays upright on the lab bench, both plants: the
describing function's cycle of the friction and the counts together
(``ipcosim.harness.analysis.residual_cycle.scenario_prediction``, from the run's plant and law) beside the step
run's residual over its final 5 s (``docs/metrics.md``): each cart's and the pendulum's peak-to-peak and dominant
frequency. The pendulum's simulated peak-to-peak is its encoder's reading (whole counts), so the prediction's is
given as the reading of the predicted swing too. The motor cart's peak-to-peak is the target: within
:data:`TOLERANCE` of the simulated one; where it is not, the row says which way and what the prediction leaves
out there.
"""
from __future__ import annotations

import math
from typing import Any

#: The motor-cart peak-to-peak the prediction should come within, relative to the simulated one.
TOLERANCE = 0.30
#: Signals of each plant kind: (label, measured name, the step run's metric prefix).
SIGNALS = {"single-mass": [("motor cart", "cart_position", "cart")],
           "double-mass": [("motor cart", "active_cart_position", "cart"),
                           ("passive cart", "passive_cart_position", "passive_cart")]}
#: The table's cart columns, by the signals' labels (a kind without such a cart: ``-``).
CART_COLUMNS = ("motor cart", "passive cart")


def check_rows(comparison: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per lab-bench law of ``comparison`` whose step run stayed upright: the prediction and the run."""
    from ipcosim.harness.analysis.residual_cycle import realism_values, scenario_prediction
    from ipcosim.harness.scenario.ssp import load_scenario
    from ipcosim.harness.scenario.structure import select_parameter_set

    rows = []
    for r in comparison:
        step = r["step"]
        if r["bench"] != "lab" or step.get("upright") is not True:
            continue
        sc = select_parameter_set(load_scenario(r["scenario"]), r["set"])
        p = scenario_prediction(sc, realism_values("lab", r["kind"]))
        simulated = {name: {"peak_to_peak": step.get(f"{prefix}_peak_to_peak_m"),
                            "frequency_Hz": step.get(f"{prefix}_frequency_Hz")}
                     for _, name, prefix in SIGNALS[r["kind"]]}
        simulated["pendulum_angle"] = {"peak_to_peak": step.get("angle_peak_to_peak_rad"),
                                       "frequency_Hz": step.get("angle_frequency_Hz")}
        rows.append({"scenario": r["scenario"], "kind": r["kind"], "set": r["set"], "simulated": simulated,
                     "predicted": _compact(p), "dither_V": _dither(sc)})
    return rows


def _compact(p: dict[str, Any]) -> dict[str, Any]:
    """What the table needs of a prediction (JSON: no arrays)."""
    keep = {k: p.get(k) for k in ("found", "reason", "combined", "frequency_Hz", "signals",
                                  "motor_cart_peak_to_peak_m", "law_terms_left_out")}
    for part in ("friction", "counts", "together"):
        q = p.get(part)
        keep[part] = None if q is None else {k: q.get(k) for k in ("found", "reason", "frequency_Hz",
                                                                  "motor_cart_peak_to_peak_m")}
    return keep


def _dither(sc: Any) -> float:
    """The law's dither amplitude [V] (0 for a law without)."""
    from ipcosim.harness.analysis.analyze import binding_values

    return float(binding_values(sc.component("controller")).get("dither_amplitude") or 0.0)


def error(row: dict[str, Any]) -> float | None:
    """(predicted - simulated) / simulated of the motor cart's peak-to-peak; None without a prediction."""
    p, sim = row["predicted"], row["simulated"][SIGNALS[row["kind"]][0][1]]["peak_to_peak"]
    if not p["found"] or not sim:
        return None
    return (p["motor_cart_peak_to_peak_m"] - sim) / sim


def why(row: dict[str, Any]) -> str:
    """Within the tolerance, or which way the prediction misses and what it leaves out there."""
    p = row["predicted"]
    if not p["found"]:
        return f"not predicted: {p['reason']} (the run falls back on the friction bound)"
    e = error(row)
    if e is None:
        return "-"
    if abs(e) <= TOLERANCE:
        return f"within {100 * TOLERANCE:.0f} %"
    notes = []
    sim_f = row["simulated"][SIGNALS[row["kind"]][0][1]]["frequency_Hz"]
    if sim_f and p["frequency_Hz"] and not 1 / 1.3 <= sim_f / p["frequency_Hz"] <= 1.3:
        notes.append(f"the simulated cycle is another one ({sim_f:.2f} Hz against {p['frequency_Hz']:.2f} Hz "
                     "predicted)")
    if not notes:
        notes.append(_same_cycle_missed(p))
    return ("over" if e > 0 else "under") + f"-predicted by {100 * abs(e):.0f} %: " + "; ".join(notes)


def _same_cycle_missed(p: dict[str, Any]) -> str:
    """Why a cycle at the simulated frequency misses its amplitude: a count-sized swing, or friction's dwell."""
    from ipcosim.fmus.instruments import PENDULUM_RAD_PER_COUNT

    pend = ((p.get("signals") or {}).get("pendulum_angle") or {}).get("amplitude")
    counts = (p.get("counts") or {}).get("motor_cart_peak_to_peak_m") or 0.0
    friction = (p.get("friction") or {}).get("motor_cart_peak_to_peak_m") or 0.0
    if counts > friction and pend is not None:
        return (f"the same cycle, its amplitude missed: the counts set it, the pendulum swinging "
                f"{pend / PENDULUM_RAD_PER_COUNT:.2f} counts, where the quantizer's first harmonic is worst "
                "(the reading is a square wave of one or two counts)")
    return ("the same cycle, its amplitude missed: the friction sets it, and the relay's first harmonic "
            "leaves out the carts' sticking at the turns")


def _together(p: dict[str, Any]) -> str:
    """The one balance of every nonlinearity at one frequency: motor-cart mm p-p at Hz, '-' where none."""
    t = p.get("together")
    if not t:
        return "-"
    if not t.get("found"):
        return "no cycle"
    return f"{t['motor_cart_peak_to_peak_m'] * 1e3:.3g} at {t['frequency_Hz']:.2f}"


def _pp(v: float | None, scale: float) -> str:
    return "-" if v is None else f"{v * scale:.3g}"


def _hz(v: float | None) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.2f}"


def table(rows: list[dict[str, Any]]) -> str:
    """The check as one Markdown table: per signal predicted / simulated peak-to-peak and frequency."""
    head = ["plant", "law (set)", "how the cycles combine", "motor cart mm p-p, Hz (predicted / simulated)",
            "passive cart mm p-p, Hz", "pendulum mrad p-p as read, Hz", "motor cart error",
            "one balance of both: motor cart mm p-p at Hz (error)", "verdict"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        p, sim = r["predicted"], r["simulated"]
        cells = []
        for label in CART_COLUMNS:
            name = next((n for lab, n, _ in SIGNALS[r["kind"]] if lab == label), None)
            if name not in sim:
                cells.append("-")
                continue
            ps = (p.get("signals") or {}).get(name) or {}
            cells.append(f"{_pp(ps.get('peak_to_peak'), 1e3)} / {_pp(sim[name]['peak_to_peak'], 1e3)}, "
                         f"{_hz(p.get('frequency_Hz'))} / {_hz(sim[name]['frequency_Hz'])}")
        pend = (p.get("signals") or {}).get("pendulum_angle") or {}
        cells.append(f"{_pp(pend.get('reading_peak_to_peak'), 1e3)} / {_pp(sim['pendulum_angle']['peak_to_peak'], 1e3)}"
                     f", {_hz(p.get('frequency_Hz'))} / {_hz(sim['pendulum_angle']['frequency_Hz'])}")
        e, t = error(r), _together(p)
        sim_pp = sim[SIGNALS[r["kind"]][0][1]]["peak_to_peak"]
        if (p.get("together") or {}).get("found") and sim_pp:
            t += f" ({100 * (p['together']['motor_cart_peak_to_peak_m'] - sim_pp) / sim_pp:+.0f} %)"
        lines.append("| " + " | ".join([r["kind"], f"{r['scenario'].split('-mass-')[1]} ({r['set']})",
                                        p.get("combined") or "-", *cells,
                                        "-" if e is None else f"{100 * e:+.0f} %", t, why(r)]) + " |")
    return "\n".join(lines)


INTRO = (
    "The nominal lab bench (encoder counts, stick-slip Coulomb friction 0.1047 N, end stops, DAC codes, the 1 ms "
    "computation delay, +-10 V): for every law of the comparison that stays upright there, the residual cycle "
    "the describing functions predict from its plant and law (`ipcosim analyze`, `residual_cycle`; "
    "`ipcosim.harness.analysis.residual_cycle`, docs/studies.md) against the step run's residual over its final "
    f"5 s (one run: the nominal bench is deterministic). Target: the motor cart's peak-to-peak within "
    f"{100 * TOLERANCE:.0f} % of the simulated one. The pendulum's simulated peak-to-peak is its encoder's "
    "reading, whole counts of 1.53 mrad; the predicted one is the reading of the predicted swing. The predicted "
    "frequency is the cycle's (for two cycles side by side, the one with the larger motor-cart swing). *One "
    "balance of both*: every nonlinearity balanced at one frequency, where the friction and the counts each give "
    "a cycle, against the same simulated peak-to-peak: what one cycle would be where the rule adds two (without "
    "the windup). On the double mass the motor cart's predicted peak-to-peak includes its travel while the passive "
    "cart rests at the turns, 2 b2 / K (1.47 mm here). A law's dither is in the friction's describing function "
    "(docs/studies.md).")
