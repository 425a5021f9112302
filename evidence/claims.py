"""The thesis's claims judged on its own terms, and the conditions under which its double-mass LQR falls.

Each claim is run with the **thesis's gain sets** on the thesis's own plant model (``thesis-ch3``,
``thesis-ch4``; the single-mass LQR on the long pendulum it was designed on,
``thesis-appendix-a``), once on the ``ideal`` and once on the ``lab`` plant (``ipcosim.fmus.instruments``:
encoder counts, Coulomb friction, end stops, +-10 V), for ``STOP_TIME`` = 20 s, in the pure loop
(plant step 1 ms, law sampled with zero-order hold). Oscillation is measured by one stated
metric, ``oscillation_rad``: the RMS of the pendulum angle above ``OSCILLATION_CUTOFF_HZ`` = 1 Hz
(4th-order Butterworth high-pass, forward and backward, over the run after the first
second), i.e. the energy of the angle's wobble, not
of the slow lean that moves the cart; a claim about oscillations compares it, and the same measure of the
motor cart's position and of the voltage, on every signal one encoder count resolves (``_fewer``).

``search_lqr_fall`` looks for the smallest departure from the nominal double-mass loop that makes
the thesis's LQR let the pendulum fall (|angle| >= 0.35 rad): a transport delay of the voltage,
encoder quantization, Coulomb friction, a lower voltage limit, a longer sample period, or the
output filters left out -- one at a time, each from small to large.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from ipcosim.controllers.catalog import make_law
from ipcosim.controllers.simulate import run_loop
from ipcosim.fmus.instruments import CART_M_PER_COUNT, PENDULUM_RAD_PER_COUNT, Instruments, realism
from ipcosim.fmus.metrics import UPRIGHT_LIMIT_RAD, compute_metrics
from ipcosim.fmus.params import KINDS, preset
from ipcosim.fmus.physics import MOTOR_CART
from ipcosim.harness.studies.report import CONTROLLER_LABELS, PLANT_LABELS, Results, Verdict
from ipcosim.harness.studies.robustness import fmt

STOP_TIME = 20.0
PLANT_STEP = 1e-3
OSCILLATION_CUTOFF_HZ = 1.0
PRESET = {"single-mass": "thesis-ch3", "double-mass": "thesis-ch4"}


@dataclass
class Run:
    """Metrics of one pure-loop run (``run``)."""

    metrics: dict[str, Any]
    oscillation_rad: float
    itae: float
    fell_at: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: The same measure (RMS above 1 Hz after the first second) of the motor cart's position [m] and the
    #: voltage [V]: what the cart encoder resolves and what the amplifier is asked for.
    cart_oscillation_m: float = 0.0
    voltage_oscillation_V: float = 0.0

    @property
    def done(self) -> bool:
        """Upright and settled (the thesis's task)."""
        return bool(self.metrics["upright"] and self.metrics["settling_time_s"] is not None)


def oscillation(time: np.ndarray, angle: np.ndarray, cutoff_hz: float = OSCILLATION_CUTOFF_HZ) -> float:
    """RMS [rad] of the angle's content above ``cutoff_hz`` after the first second."""
    from scipy.signal import butter, sosfiltfilt

    keep = time >= 1.0
    if np.count_nonzero(keep) < 100:
        return 0.0
    sos = butter(4, cutoff_hz, "highpass", fs=1.0 / float(time[1] - time[0]), output="sos")
    return float(np.sqrt(np.mean(sosfiltfilt(sos, angle[keep]) ** 2)))


def run(law, kind: str, params, instruments: Instruments | None = None, stop_time: float = STOP_TIME,
        amplitude: float = 0.05) -> Run:
    """Step 0 -> ``amplitude`` of the motor cart at t = 0 in the pure loop (``controllers.simulate.run_loop``);
    the law sees the instruments' readings. Metrics are those of the run up to a plant failure (the finite
    part; upright only if it ran to the end), with the last applied voltage held over the end instant."""
    r = run_loop(law, params, stop_time, PLANT_STEP, amplitude, instruments=instruments or Instruments())
    t, x, th = r.time, r.states[:, MOTOR_CART[kind]], r.signal("pendulum_angle")
    v = np.append(r.voltage[:-1], r.voltage[-2])
    ok = np.isfinite(x)
    m = compute_metrics(t[ok], x[ok], r.reference[ok], th[ok], v[ok])
    m["upright"] = bool(m["upright"] and ok.all())
    itae = float(np.trapezoid(t[ok] * np.abs(x[ok] - amplitude), t[ok]))
    beyond = np.flatnonzero(np.abs(th[1:]) >= UPRIGHT_LIMIT_RAD)
    fell = float(t[beyond[0] + 1]) if beyond.size else None
    return Run(m, oscillation(t[ok], th[ok]), itae, fell, cart_oscillation_m=oscillation(t[ok], x[ok]),
               voltage_oscillation_V=oscillation(t[ok], v[ok]))


#: The model each thesis design was made on, where it is not the kind's default preset: the thesis
#: designed its single-mass LQR on the long pendulum (App. A.2).
OWN_MODEL = {("LQR", "single-mass"): "thesis-appendix-a"}
#: The single-mass LQR (designed on its own model) run on the kind's thesis preset, so that a comparison with the
#: other single-mass laws is made on one plant.
LQR_ON_CH3 = ("LQR on thesis-ch3", "single-mass")
#: Differences below these are not differences: one encoder count of the pendulum (an oscillation the rig cannot
#: see) and of the cart (a steady-state error it cannot tell apart) [rad, m].
ANGLE_RESOLUTION = PENDULUM_RAD_PER_COUNT
POSITION_TOLERANCE = CART_M_PER_COUNT


def _on_preset(law: str, kind: str) -> tuple[str, str]:
    """The key in :func:`thesis_runs` of ``law``'s run on ``kind``'s thesis preset (``PRESET``): ``(law, kind)``,
    or, for a law run on a model of its own (``OWN_MODEL``), the run made on the preset beside it (``LQR_ON_CH3``)."""
    return (f"{law} on {PRESET[kind]}", kind) if (law, kind) in OWN_MODEL else (law, kind)


def thesis_runs(realism_name: str, stop_time: float = STOP_TIME) -> dict[tuple[str, str], Run]:
    """Every law with the thesis's gain set, on both plants (CascadePID: no thesis set, left out), each
    on its own model (``OWN_MODEL``: plant and design model; else the kind's thesis preset)."""
    out = {}
    for kind in KINDS:
        for law in ("PID", "LQR", "HSMC", "AdaptiveHSMC"):
            own = OWN_MODEL.get((law, kind))
            inst, phys = realism(realism_name, kind)
            params = preset(own or PRESET[kind], **phys)
            design = {"design_params": preset(own)} if own else {}
            out[(law, kind)] = run(make_law(kind, law, "thesis", **design), kind, params, inst, stop_time)
            if own:
                out[_on_preset(law, kind)] = run(make_law(kind, law, "thesis", **design), kind,
                                                 preset(PRESET[kind], **phys), inst, stop_time)
    return out


# ------------------------------------------------------- the same claims on ``ipcosim compare``'s results
#: The co-simulation comparison's task band: 2 % of the 0.05 m step [m].
BAND = 0.02 * 0.05
THESIS_DOUBLE_HSMC_SSE = 0.005575


def _cosim_row(results: Results, scenario: str) -> Mapping[str, Any] | None:
    row = results.get(scenario)
    if row is None or row.get("status") in (None, "error"):
        return None
    return row


def _cosim_missing(results: Results, *scenarios: str) -> Verdict | None:
    absent = [s for s in scenarios if _cosim_row(results, s) is None]
    if not absent:
        return None
    why = []
    for s in absent:
        row = results.get(s)
        why.append(f"{s}: {row.get('error') or 'failed'}" if row else f"{s}: not run")
    return Verdict("not measured", "; ".join(why))


def _cosim_num(row: Mapping[str, Any], key: str, missing: float = math.inf) -> float:
    v = row.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else missing


def _cosim_desc(row: Mapping[str, Any]) -> str:
    return (f"status {row.get('status')}, settling {fmt(row.get('settling_time_s'))} s, "
            f"max abs angle {fmt(row.get('max_abs_angle_rad'))} rad")


def _cosim_yes(flag: bool) -> str:
    return "confirmed" if flag else "not confirmed"


def _cosim_fails(scn: str) -> Callable[[Results], Verdict]:
    def check(r: Results) -> Verdict:
        miss = _cosim_missing(r, scn)
        if miss:
            return miss
        row = r[scn]
        return Verdict(_cosim_yes(row["status"] != "ok"), f"{scn}: {_cosim_desc(row)}")
    return check


def _cosim_lqr_single(r: Results) -> Verdict:
    a, b = "single-mass-lqr", "single-mass-hsmc"
    miss = _cosim_missing(r, a, b)
    if miss:
        return miss
    la, lb = _cosim_num(r[a], "angle_reversals", -1), _cosim_num(r[b], "angle_reversals", -1)
    ok = r[a]["status"] == "ok" and la > lb
    return Verdict(_cosim_yes(ok), f"LQR: {_cosim_desc(r[a])}, {fmt(la)} angle reversals (HSMC: {fmt(lb)})")


def _cosim_hsmc_integral_single(r: Results) -> Verdict:
    s = "single-mass-hsmc"
    miss = _cosim_missing(r, s)
    if miss:
        return miss
    sse = _cosim_num(r[s], "steady_state_error_m")
    return Verdict(_cosim_yes(r[s]["status"] == "ok" and sse < BAND),
                   f"steady-state error {fmt(sse)} m (band {BAND:g} m), status {r[s]['status']}")


def _cosim_settles_faster(plant: str) -> Callable[[Results], Verdict]:
    def check(r: Results) -> Verdict:
        a, h = f"{plant}-adaptive-hsmc", f"{plant}-hsmc"
        miss = _cosim_missing(r, a, h)
        if miss:
            return miss
        ta, th = _cosim_num(r[a], "settling_time_s"), _cosim_num(r[h], "settling_time_s")
        return Verdict(_cosim_yes(ta < th), f"settling time adaptive {fmt(r[a].get('settling_time_s'))} s vs "
                                      f"HSMC {fmt(r[h].get('settling_time_s'))} s ('-': never inside the band)")
    return check


def _cosim_fewer_oscillations(r: Results) -> Verdict:
    h, lq = "single-mass-hsmc", "single-mass-lqr"
    miss = _cosim_missing(r, h, lq)
    if miss:
        return miss
    nh, nl = _cosim_num(r[h], "angle_reversals", -1), _cosim_num(r[lq], "angle_reversals", -1)
    return Verdict(_cosim_yes(0 <= nh < nl), f"angle reversals HSMC {fmt(nh)} vs LQR {fmt(nl)}")


def _cosim_hsmc_better(r: Results) -> Verdict:
    parts, ok, measured = [], True, False
    for plant in KINDS:
        h = f"{plant}-hsmc"
        if _cosim_row(r, h) is None:
            continue
        for other in ("pid", "lqr"):
            o = f"{plant}-{other}"
            if _cosim_row(r, o) is None:
                continue
            measured = True
            jh, jo = _cosim_num(r[h], "cost"), _cosim_num(r[o], "cost")
            ok &= jh < jo
            parts.append(f"{PLANT_LABELS[plant]}: J(HSMC) {fmt(jh)} vs J({CONTROLLER_LABELS[other]}) {fmt(jo)}")
    if not measured:
        return Verdict("not measured", "HSMC, PID and LQR scenarios not run")
    return Verdict(_cosim_yes(ok), "; ".join(parts))


def _cosim_double_lqr_falls(r: Results) -> Verdict:
    s = "double-mass-lqr"
    miss = _cosim_missing(r, s)
    if miss:
        return miss
    return Verdict(_cosim_yes(r[s].get("upright") is False),
                   f"{_cosim_desc(r[s])}, {fmt(r[s].get('angle_reversals'))} angle reversals, "
                   f"falls at {fmt(r[s].get('fall_time_s'))} s")


def _cosim_double_hsmc(r: Results) -> Verdict:
    s = "double-mass-hsmc"
    miss = _cosim_missing(r, s)
    if miss:
        return miss
    sse = _cosim_num(r[s], "steady_state_error_m")
    ok = r[s].get("upright") is True and sse >= BAND
    return Verdict(_cosim_yes(ok), f"upright {fmt(r[s].get('upright'))}, steady-state error {fmt(sse)} m "
                             f"(thesis {THESIS_DOUBLE_HSMC_SSE} m; band {BAND:g} m)")


def _cosim_double_adaptive(r: Results) -> Verdict:
    a, h = "double-mass-adaptive-hsmc", "double-mass-hsmc"
    miss = _cosim_missing(r, a, h)
    if miss:
        return miss
    ea, eh = _cosim_num(r[a], "steady_state_error_m"), _cosim_num(r[h], "steady_state_error_m")
    ta, th = _cosim_num(r[a], "settling_time_s"), _cosim_num(r[h], "settling_time_s")
    return Verdict(_cosim_yes(ea < eh and ta < th),
                   f"steady-state error {fmt(ea)} vs {fmt(eh)} m; settling {fmt(r[a].get('settling_time_s'))} vs "
                   f"{fmt(r[h].get('settling_time_s'))} s (adaptive vs HSMC)")



# ----------------------------------------------------------------------------- the claims
@dataclass(frozen=True)
class Claim:
    """A claim of the thesis, where it is made, its measurable form and its check.

    ``check`` returns ``(holds, evidence)`` with ``holds`` None when the difference the claim is about is
    below the sensor's resolution (indistinguishable). ``fitted`` names a lab-plant value fitted to this
    very claim: a lab plant that shows it reproduces it by construction, which confirms nothing.
    ``cosim_form`` and ``cosim_check`` judge the same claim on the co-simulation comparison's results
    (scenario -> result row, ``ipcosim.harness.studies.compare``; :func:`on_comparison`).
    """

    text: str
    source: str
    form: str
    check: Callable[[Mapping[tuple[str, str], Run]], tuple[bool | None, str]]
    fitted: str = ""
    cosim_form: str = ""
    cosim_check: Callable[[Results], Verdict] | None = None


def _fmt(r: Run) -> str:
    m = r.metrics
    st = f"settles {m['settling_time_s']:.2f} s" if m["settling_time_s"] is not None else "not settled"
    up = "upright" if m["upright"] else f"falls at {r.fell_at:.2f} s" if r.fell_at else "falls"
    err = m["steady_state_error_m"]
    return f"{up}, {st}, error {err * 1e3:.2f} mm, oscillation {r.oscillation_rad * 1e3:.2f} mrad" \
        if err is not None else f"{up}, {st}"


def _fails(kind: str):
    def check(R):
        r = R[("PID", kind)]
        return (not r.done), _fmt(r)
    return check


#: The signals an oscillation claim is judged on: (label, Run attribute, unit scale, unit, resolution of its
#: instrument: one encoder count; the voltage is always resolved).
OSCILLATION_SIGNALS = (("pendulum", "oscillation_rad", 1e3, "mrad", ANGLE_RESOLUTION),
                       ("cart", "cart_oscillation_m", 1e3, "mm", POSITION_TOLERANCE),
                       ("voltage", "voltage_oscillation_V", 1e3, "mV", 0.0))


def _fewer(more: Run, fewer: Run, factor: float) -> tuple[bool | None, str]:
    """Whether ``fewer`` oscillates less than ``more`` / ``factor`` on every signal its instrument resolves
    (:data:`OSCILLATION_SIGNALS`; a signal below one count in both runs is left out), None when none is."""
    verdicts, parts = [], []
    for label, attr, scale, unit, resolution in OSCILLATION_SIGNALS:
        a, b = getattr(more, attr), getattr(fewer, attr)
        seen = max(a, b) >= resolution
        if seen:
            verdicts.append(b * factor < a)
        parts.append(f"{label} {b * scale:.3g} vs {a * scale:.3g} {unit}" + ("" if seen else " (below one count)"))
    return (all(verdicts) if verdicts else None), ", ".join(parts)


def _lqr_single(R):
    lqr, hsmc = R[LQR_ON_CH3], R[("HSMC", "single-mass")]
    fewer, evidence = _fewer(lqr, hsmc, 2.0)
    return (None if fewer is None else lqr.done and fewer,
            f"both on thesis-ch3: LQR: {_fmt(lqr)}; RMS above 1 Hz, HSMC vs LQR: {evidence}")


def _hsmc_integral(R):
    r = R[("HSMC", "single-mass")]
    err = r.metrics["steady_state_error_m"]
    return bool(err is not None and err < 1e-3 and r.metrics["upright"]), _fmt(r)


def _adaptive_faster(kind: str, error_too: bool):
    def check(R):
        a, h = R[("AdaptiveHSMC", kind)], R[("HSMC", kind)]
        ta, th = a.metrics["settling_time_s"], h.metrics["settling_time_s"]
        faster = ta is not None and (th is None or ta < th)
        if error_too:  # a smaller error: smaller by more than one cart encoder count (else a tie)
            ea, eh = a.metrics["steady_state_error_m"], h.metrics["steady_state_error_m"]
            faster = faster and ea is not None and eh is not None and ea < eh - POSITION_TOLERANCE
        return bool(faster and a.metrics["upright"]), f"adaptive: {_fmt(a)}; HSMC: {_fmt(h)}"
    return check


def _fewer_oscillations(R):
    lqr, hsmc = R[LQR_ON_CH3], R[("HSMC", "single-mass")]
    fewer, evidence = _fewer(lqr, hsmc, 2.0)
    return (None if fewer is None else hsmc.metrics["upright"] and fewer,
            f"both on thesis-ch3, RMS above 1 Hz, HSMC vs LQR: {evidence}")


def _hsmc_better(R):
    parts, ok = [], True
    for kind in KINDS:
        h, lq, p = R[("HSMC", kind)], R[_on_preset("LQR", kind)], R[("PID", kind)]
        better = h.metrics["upright"] and (not lq.metrics["upright"] or h.itae < lq.itae) and \
            (not p.metrics["upright"] or h.itae < p.itae)
        ok = ok and better
        pid = "PID fell" if not p.metrics["upright"] else f"PID {p.itae * 1e3:.2f} mm s^2"
        lqr = f"LQR {lq.itae * 1e3:.2f} mm s^2" + ("" if lq.metrics["upright"] else " (fell)")
        parts.append(f"{kind} ({PRESET[kind]}): ITAE HSMC {h.itae * 1e3:.2f} mm s^2, {lqr}, {pid}")
    return ok, "; ".join(parts)


def _double_lqr_falls(R):
    r = R[("LQR", "double-mass")]
    return (not r.metrics["upright"]), _fmt(r)


def _double_hsmc(R):
    r = R[("HSMC", "double-mass")]
    err = r.metrics["steady_state_error_m"]
    return bool(r.metrics["upright"] and err is not None and err >= 1e-3), _fmt(r) + " (thesis: 5.575 mm)"


CLAIMS: tuple[Claim, ...] = (
    Claim("PID control does not work for this system.", "3.2.1", "thesis PID fails the task (single mass)",
          _fails("single-mass"),
          cosim_form="single-mass-pid fails the task (falls or does not settle in the band)",
          cosim_check=_cosim_fails("single-mass-pid")),
    Claim("It meets the criterion, but has a lot of oscillations.", "3.2.2, Fig. 3.9 (simulation)",
          "single-mass LQR does the task, oscillation > 2x the HSMC's (pendulum, cart, voltage)", _lqr_single,
          cosim_form="single-mass-lqr is upright and settled, with more angle reversals than HSMC",
          cosim_check=_cosim_lqr_single),
    Claim("an integral controller can eliminate the steady-state error", "ch. 5, Fig. 3.11",
          "single-mass HSMC upright with error < 1 mm at 20 s", _hsmc_integral,
          cosim_form="single-mass-hsmc settles with steady-state error below the +-2 % band (0.001 m)",
          cosim_check=_cosim_hsmc_integral_single),
    Claim("the settling time has been reduced", "3.2.4, Fig. 3.12", "single-mass adaptive HSMC settles before HSMC",
          _adaptive_faster("single-mass", False),
          cosim_form="settling time of single-mass-adaptive-hsmc < single-mass-hsmc",
          cosim_check=_cosim_settles_faster("single-mass")),
    Claim("it has decreased oscillations greatly", "3.3, Fig. 3.19 (experiment)",
          "single-mass HSMC oscillation < half the LQR's (pendulum, cart, voltage)", _fewer_oscillations,
          cosim_form="fewer angle reversals with single-mass-hsmc than single-mass-lqr",
          cosim_check=_cosim_fewer_oscillations),
    Claim("HSMC could give a better result than PID and LQR", "ch. 5",
          "HSMC upright with a lower ITAE than LQR and PID, both plants", _hsmc_better,
          cosim_form="cost J of HSMC below PID and LQR on each plant",
          cosim_check=_cosim_hsmc_better),
    Claim("PID control cannot work for this system", "4.2.1, Fig. 4.7", "thesis PID fails the task (double mass)",
          _fails("double-mass"),
          cosim_form="double-mass-pid fails the task",
          cosim_check=_cosim_fails("double-mass-pid")),
    Claim("a lot of oscillations and that would cause the pendulum fall when the carts stop", "4.2.2, Fig. 4.9",
          "double-mass LQR lets the pendulum fall", _double_lqr_falls,
          cosim_form="double-mass-lqr does not stay upright",
          cosim_check=_cosim_double_lqr_falls),
    Claim("it always has a steady-state error of 0.005575m", "4.2.3, Fig. 4.11 (simulation)",
          "double-mass HSMC upright, error >= 1 mm", _double_hsmc,
          fitted="the lab plant's Coulomb friction is fitted to this error (evidence.friction)",
          cosim_form="double-mass-hsmc upright, with a steady-state error at least the +-2 % band",
          cosim_check=_cosim_double_hsmc),
    Claim("the steady-state error and settling time have been decreased", "4.2.4, Fig. 4.12",
          "double-mass adaptive HSMC settles sooner with a smaller error than HSMC",
          _adaptive_faster("double-mass", True),
          cosim_form="double-mass-adaptive-hsmc has smaller steady-state error and settling time than double-mass-hsmc",
          cosim_check=_cosim_double_adaptive),
)


def judge(stop_time: float = STOP_TIME) -> list[dict[str, Any]]:
    """Each claim's verdict and evidence on the ideal and the lab plant."""
    runs = {name: thesis_runs(name, stop_time) for name in ("ideal", "lab")}
    rows = []
    for c in CLAIMS:
        row: dict[str, Any] = {"claim": c.text, "source": c.source, "form": c.form}
        for name, R in runs.items():
            ok, evidence = c.check(R)
            row[name] = {"holds": None if ok is None else bool(ok), "evidence": evidence}
        row["verdict"] = verdict(row["ideal"]["holds"], row["lab"]["holds"], c.fitted)
        rows.append(row)
    return rows


def verdict(ideal: bool | None, lab: bool | None, fitted: str = "") -> str:
    """The verdict of a claim from whether it holds on the ideal and on the lab plant (None: below the sensor's
    resolution). A lab plant fitted to the claim (``fitted``) reproduces it by construction: never a confirmation."""
    if fitted and lab:
        return ("reproduced on the lab plant by construction (" + fitted + "); "
                + ("confirmed" if ideal else "indistinguishable" if ideal is None else "not confirmed")
                + " on the ideal plant")
    if ideal is None and lab is None:
        return "indistinguishable (below one encoder count)"
    if ideal is None or lab is None:
        known, name = (lab, "lab") if ideal is None else (ideal, "ideal")
        other = "ideal" if name == "lab" else "lab"
        return (f"{'confirmed' if known else 'not confirmed'} on the {name} plant; indistinguishable on the "
                f"{other} plant")
    return ("confirmed" if ideal and lab else "not confirmed" if not (ideal or lab)
            else "confirmed on the lab plant only" if lab else "confirmed on the ideal plant only")


# ----------------------------------------------------------------------------- the LQR fall search
def _lqr_case(sample_period: float = 1e-3, voltage_limit: float = 10.0, filters: bool = True,
              stop_time: float = STOP_TIME, **bench: float) -> Run:
    kind = "double-mass"
    phys = {k: bench.pop(k) for k in ("b1", "b2") if k in bench}
    params = preset(PRESET[kind], voltage_limit=10.0, **phys)
    law = make_law(kind, "LQR", "thesis", sample_period=sample_period, voltage_limit=voltage_limit,
                   **({} if filters else {"output_filter_time_constant": 0.0}))
    return run(law, kind, params, Instruments(**bench), stop_time)


#: One condition at a time, from small to large (label, unit, values, keyword for ``_lqr_case``).
FALL_CONDITIONS: tuple[tuple[str, str, tuple[float, ...], Callable[[float], dict[str, Any]]], ...] = (
    ("voltage transport delay", "ms", (1, 2, 3, 4, 5, 6, 7, 8, 10, 12), lambda v: {"input_delay": v * 1e-3}),
    ("encoder quantization (IP02 counts x factor)", "x", (1, 2, 4, 8),
     lambda v: {"cart_resolution": 2.275e-5 * v, "pendulum_resolution": 2 * math.pi / 4096 * v}),
    ("Coulomb friction on both carts", "N", (0.1047, 0.2, 0.4, 0.8), lambda v: {"b1": v, "b2": v}),
    ("voltage limit", "V", (8.0, 6.0, 4.0, 2.0), lambda v: {"voltage_limit": v}),
    ("sample period", "ms", (2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0), lambda v: {"sample_period": v * 1e-3}),
    ("output filters left out", "-", (1.0,), lambda v: {"filters": False}),
)


def search_lqr_fall(stop_time: float = STOP_TIME) -> list[dict[str, Any]]:
    """For each condition: the smallest value that makes the thesis's double-mass LQR fall (or None)."""
    rows = []
    for label, unit, values, kw in FALL_CONDITIONS:
        found, last = None, None
        for value in values:
            r = _lqr_case(stop_time=stop_time, **kw(value))
            last = r
            if not r.metrics["upright"]:
                found = (value, r)
                break
        rows.append({"condition": label, "unit": unit, "tried": list(values),
                     "falls_at": found[0] if found else None,
                     "evidence": _fmt(found[1]) if found else f"largest tried: {_fmt(last)}"})
    return rows


def on_comparison(results: Results) -> list[tuple[str, str, str, Verdict]]:
    """Every claim judged on the co-simulation comparison's results (scenario -> result row): (quote,
    source, how it is checked, verdict), the rows of the report's claims section."""
    return [(c.text, c.source, c.cosim_form, c.cosim_check(results)) for c in CLAIMS if c.cosim_check]


def main(argv: list[str] | None = None) -> int:
    """``python -m evidence.claims [OPTIONS]``: ``ipcosim compare [OPTIONS]`` with the thesis's claims judged
    on its results beside the numbers (the report's claims section)."""
    import sys

    from ipcosim.harness.cli import build_parser
    from ipcosim.harness.cli.compare import main as compare

    args = build_parser().parse_args(["compare", *(sys.argv[1:] if argv is None else argv)])
    return compare(args, claims=on_comparison)


if __name__ == "__main__":
    raise SystemExit(main())
