"""``ipcosim analyze``: margins, sensitivity and Bode/Nyquist plots of a scenario's loop."""
from __future__ import annotations

import argparse
import json

from ipcosim.harness.cli import add_parameter_file_option

#: The one line ``ipcosim --help`` shows for this command.
HELP = "linear analysis of a scenario's loop (margins, sensitivity, Bode/Nyquist)"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help=HELP,
                       description="Break the scenario's loop at the plant input and report gain, phase and delay "
                                   "margins, the sensitivity peak, the sampled-data closed-loop poles and the limit "
                                   "that the plant's right-half-plane zero and pole put on a position-only "
                                   "controller, and the limit cycles Coulomb friction would drive (describing "
                                   "function). Writes DIR/bode.png, DIR/nyquist.png and DIR/analysis.json.")
    p.add_argument("scenario", help="scenario name (see `ipcosim list`) or folder")
    p.add_argument("--parameter-set", metavar="NAME", help="bind this parameter set (thesis, tuned...)")
    p.add_argument("--set", action="append", default=[], metavar="COMP.VAR=VALUE",
                   help="override a controller or plant parameter, e.g. --set plant.Mp=0.2 (repeatable)")
    add_parameter_file_option(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--out", metavar="DIR", help="output folder (default: out/analyze/<scenario>)")
    p.set_defaults(func=main)


def _fmt(v: float | None, spec: str, unit: str = "") -> str:
    return "-" if v is None else f"{format(v, spec)}{unit}"


def _cycle_lines(report: dict | None) -> list[str]:
    """The describing function's friction limit cycles, one line each."""
    if report is None:
        return []
    if report["cycles"] is None:
        return ["friction limit cycles: not predicted (the linear loop is unstable)"]
    forces = ", ".join(f"{k} = {v:g} N" for k, v in report["coulomb_forces_N"].items())
    lines = [f"friction limit cycles ({report['method']}; {forces}, {report['forces_from']}):"]
    for c in report["cycles"]:
        amps = ", ".join(f"{k} +-{v * 1e3:.3g} {'mrad' if k.endswith('angle') else 'mm'}"
                         for k, v in c["amplitudes"].items())
        lines.append(f"  {c['parameter']}: {c['frequency_Hz']:.3g} Hz, {amps}")
    if not report["cycles"]:
        lines.append("  none (no crossing of the negative real axis)")
    return lines


def _residual_lines(p: dict | None) -> list[str]:
    """The residual cycle of friction and counts together (``residual_cycle``), one line per signal."""
    if p is None:
        return []
    head = f"residual cycle, friction and counts together ({p['bench']})"
    if not p["found"]:
        return [f"{head}: not predicted: {p['reason']}"]
    if p["frequency_Hz"] is None:
        return [f"{head}: none ({p['combined']})"]
    lines = [f"{head}: {p['frequency_Hz']:.3g} Hz, {p['combined']}"]
    for name, s in p["signals"].items():
        unit, scale = ("mrad", 1e3) if name.endswith("angle") else ("mm", 1e3)
        lines.append(f"  {name}: {s['peak_to_peak'] * scale:.3g} {unit} peak to peak "
                     f"({s['reading_peak_to_peak'] * scale:.3g} {unit} as its encoder reads it)")
    return lines


def _margin_lines(r: dict) -> list[str]:
    """The disk margin at the plant input and each sensor's gain range and delay margin, one line each."""
    dm = r.get("disk_margin")
    if not dm:
        return []
    upper = _fmt(dm["gain_upper"], ".4g")
    lines = [f"disk margin (balanced) {dm['alpha']:.4g}: simultaneous gain x{dm['gain_lower']:.4g} .. x{upper} "
             f"and phase +-{dm['phase_deg']:.3g} deg (at {dm['frequency_rad_s']:.3g} rad/s)",
             "sensor margins (loop at a time: one reading scaled or delayed, the others exact):"]
    for name, m in r["sensor_margins"].items():
        delay = m["delay_margin_s"]
        lines.append(f"  {name}: gain x{m['gain_lower']:.4g} .. x{_fmt(m['gain_upper'], '.4g')}, "
                     f"phase margin {_fmt(m['phase_margin_deg'], '.3g', ' deg')}, "
                     f"delay margin {_fmt(delay and delay * 1e3, '.3g', ' ms')}, "
                     f"disk margin {m['disk_margin']['alpha']:.3g}")
    return lines


def main(args: argparse.Namespace) -> int:
    from ipcosim.harness.analysis.scenario_analysis import analyze
    from ipcosim.harness.api.grammar import parse_set
    from ipcosim.harness.api.options import with_parameter_file
    from ipcosim.harness.master.results import claim_output

    out = claim_output(args.out or f"out/analyze/{args.scenario.rstrip('/').split('/')[-1]}", "analyze")
    values = with_parameter_file(args.parameter_file, parse_set(args.set, numbers=True))
    r = analyze(args.scenario, parameter_set=args.parameter_set, set=values, out=out)
    if args.json:
        print(json.dumps(r))
        return 0
    gm = r["gain_margin"] or {}
    print(f"{r['scenario']} ({r['law']}, {r['parameter_set']}), T = {r['sample_period_s'] * 1e3:g} ms, "
          f"loop broken at the plant input")
    print(f"  closed loop stable: {'yes' if r['closed_loop_stable'] else 'no'} "
          f"(spectral radius {r['closed_loop_spectral_radius']:.6g})")
    print(f"  gain margin: x{_fmt(gm.get('upper'), '.4g')} / x{_fmt(gm.get('lower'), '.4g')}; "
          f"phase margin {_fmt(r['phase_margin_deg'], '.3g', ' deg')}; "
          f"delay margin {_fmt(r['delay_margin_s'] and r['delay_margin_s'] * 1e3, '.3g', ' ms')}")
    print(f"  peak sensitivity {_fmt(r['peak_sensitivity'], '.4g')}")
    for line in _margin_lines(r):
        print(f"  {line}")
    print(f"  {r['statement']}")
    for line in _cycle_lines(r["friction_limit_cycles"]) + _residual_lines(r.get("residual_cycle")):
        print(f"  {line}")
    if r["figures"]:
        print(f"  figures: {', '.join(r['figures'].values())}")
    return 0
