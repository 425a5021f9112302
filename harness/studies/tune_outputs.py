"""What a tuning writes (:mod:`ipcosim.harness.studies.tune`): the tuned parameter set
(:func:`tuned_parameter_set`), the before/after table of its report, every run as CSV, and where
``--install`` puts the set (:func:`install_path`, :func:`install`).
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Mapping, Sequence

from ipcosim.errors import UsageError
from ipcosim.harness.studies.robustness_summary import fmt
from ipcosim.harness.studies.tune_search import TuneResult


def tuned_parameter_set(scenario: str, best: Mapping[str, float],
                        parameter_set: str | None = None) -> tuple[dict[str, Any], str | None]:
    """The complete parameter set to write for a tuned scenario.

    When every tuned parameter belongs to one component that binds a parameter-set file (the
    controller's ``thesis``/``tuned`` set), the result is that set with the tuned values put in,
    names relative to the component -- a drop-in replacement selectable with
    ``--parameter-set autotuned``. Otherwise the tuned values alone, as ``component.variable``.

    Returns
    -------
    (values, component)
        ``component`` is None in the second case.
    """
    components = {n.split(".", 1)[0] for n in best}
    if len(components) == 1:
        component = components.pop()
        try:
            from ipcosim.harness.scenario.ssp import load_scenario
            from ipcosim.harness.scenario.structure import select_parameter_set

            sc = load_scenario(scenario)
            if parameter_set:
                sc = select_parameter_set(sc, parameter_set)
            comp = sc.component(component)
        except Exception:  # noqa: BLE001 -- not a scenario with files (e.g. a pure stand-in)
            comp = None
        if comp is not None:
            file_sets = [b for b in comp.bindings if b.source is not None]
            if file_sets:
                values: dict[str, Any] = {}
                for b in file_sets:
                    values.update({p.name: p.value for p in b.parameters})
                values.update({n.split(".", 1)[1]: float(v) for n, v in best.items()})
                return values, component
    return {n: float(v) for n, v in best.items()}, None


TABLE_METRICS = ("cost", "itae_position", "settling_time_s", "overshoot_m", "steady_state_error_m",
                 "max_abs_angle_rad", "peak_voltage_V", "rms_voltage_V", "upright")


def before_after_markdown(res: TuneResult, label_before: str = "scenario gains") -> str:
    """Before/after table of parameter values and metrics."""
    lines = [f"| | {label_before} | tuned |", "|---|---|---|"]
    for n in res.names:
        lines.append(f"| {n} | {fmt(res.nominal[n], 6)} | {fmt(res.best[n], 6)} |")
    for m in TABLE_METRICS:
        before, after = res.nominal_row.get(m), res.best_row.get(m)
        lines.append(f"| {m} | {fmt(before)} | {fmt(after)} |")
    lines.append(f"| status | {res.nominal_row['status']} | {res.best_row['status']} |")
    return "\n".join(lines) + "\n"


def write_evaluations(path: Path, rows: Sequence[Mapping[str, Any]], names: Sequence[str]) -> None:
    """Every run of the tuning as CSV (parameters, cost, status, metrics)."""
    if not rows:
        return
    keys = ["index", "status", "cost", *names]
    for r in rows:
        keys += [k for k in r if k not in keys and k not in ("seed", "success")]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow(["" if r.get(k) is None else r.get(k) for k in keys])


def _scenario_dir(scenario: str) -> Path | None:
    """The scenario's folder (where its .ssv files live), or None."""
    path = Path(scenario)
    if path.is_dir():
        return path
    if path.suffix == ".ssp" and path.exists():
        return path.parent
    from ipcosim.harness.support.paths import SCENARIO_DIR

    candidate = SCENARIO_DIR / scenario
    return candidate if candidate.is_dir() else None


def install_path(scenario: str) -> Path:
    """Where ``--install`` puts a tuned set: ``autotuned.ssv`` in the scenario's folder (beside its other
    sets); for a scenario shipped in an installed wheel, in the user's copy of it
    (``ipcosim.harness.support.paths.user_scenario_dir``, made by :func:`install`), never in site-packages.

    Raises
    ------
    UsageError
        If the scenario has no folder (an archive, a pure stand-in).
    """
    folder = _scenario_dir(scenario)
    if folder is None or Path(scenario).suffix == ".ssp":
        raise UsageError(f"--install: scenario {scenario!r} has no folder to install a parameter set into")
    from ipcosim.harness.support.paths import SCENARIO_DIR, in_checkout, user_scenario_dir

    if not in_checkout() and folder.resolve().is_relative_to(SCENARIO_DIR.resolve()):
        return user_scenario_dir() / folder.name / "autotuned.ssv"
    return folder / "autotuned.ssv"


def install(scenario: str, path: Path, text: str) -> None:
    """Write the tuned set ``text`` to ``path`` (:func:`install_path`), first copying the shipped
    scenario's SSD and parameter sets into the user's folder when ``path`` is there."""
    import os
    import shutil

    folder = _scenario_dir(scenario)
    if folder is not None and path.parent != folder and not (path.parent / "SystemStructure.ssd").exists():
        shutil.copytree(folder, path.parent, dirs_exist_ok=True, ignore=shutil.ignore_patterns("autotuned.ssv"))
    staged = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    staged.write_text(text)
    os.replace(staged, path)
